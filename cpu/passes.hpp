// The four IANP passes of docs/design.md section 2 on the host, as TBB loops over
// the region's index lists, or serially over one slice of them (the backend's
// thread team, cpu/thread_team.hpp). Each pass is a function of (const model&,
// state&): it only loops; the per-element and per-node math is core/tet.hpp.
// The element passes run in batches of kLanes elements through the
// vectorised lane kernels of element_lanes.hpp.
// Every pass writes each output slot from exactly one loop iteration (pass 4
// gathers rather than scatters), so results do not depend on the thread
// count or the schedule.
#pragma once

#include <tbb/partitioner.h>

#include <span>
#include <vector>

#include "core/state.hpp"
#include "cpu/bad_element.hpp"

namespace tissue::cpu {

/// Minimum loop chunks (iterations per task). Chosen so a chunk costs a few
/// microseconds: small enough to spread an 8k-element kidney over 8 to 16
/// threads, large enough that task overhead stays negligible at 1M elements.
/// Element grains are multiples of kLanes, so that only a chunk's last batch
/// can be partial.
inline constexpr std::size_t kElemGrain = 512;   ///< pass 1 (about 40 flops per element)
inline constexpr std::size_t kForceGrain = 256;  ///< pass 3 (about 400 flops and two cube roots)
inline constexpr std::size_t kNodeGrain = 512;   ///< passes 2 and 4 (one node->element list each)

/// Per-pass partitioners kept across steps, so that each pass hands the same
/// chunks to the same threads every step (their data stays in that core's cache).
struct PassPartitioners {
  tbb::affinity_partitioner element_pressure, nodal_pressure, element_forces, node_update;
};

/// Pass 1 over `elems`: F_e (elem_F), J_e = det F and elem_dv[e] =
/// (J_e - 1) V_e from the current displacements state.u.
template <class T>
void element_pressure(const TissueModel<T>& m, TissueState<T>& s, std::span<const index_t> elems,
                      tbb::affinity_partitioner& part);

/// Pass 1 from displacements u (3 x n_nodes, m) into J_out[e] (n_elems),
/// dv_out[e] = p_e V_e (n_elems, N m) and the deformation gradient F_out
/// (9 x n_elems), which pass 3 reads; on the calling thread (the
/// reduction's team member, cpu/reduce.cpp).
template <class T>
void element_pressure(const TissueModel<T>& m, const T* u, std::span<const index_t> elems, T* J_out, T* dv_out,
                      T* F_out);

/// Pass 2 over `nodes`: node_p[a] = sum_e (J_e - 1) V_e / node_divisor[a]
/// over the node's node_elem list, in stored order: p_a = K_a theta_a.
/// node_divisor (n_nodes, m^3/Pa) is V_a / K_a (core nodal_pressure_divisors()).
template <class T>
void nodal_pressure(const TissueModel<T>& m, TissueState<T>& s, const std::vector<T>& node_divisor,
                    std::span<const index_t> nodes, tbb::affinity_partitioner& part);

/// Pass 2 from dv (n_elems, m^3) into p_out (n_nodes, Pa), on the calling thread.
template <class T>
void nodal_pressure(const TissueModel<T>& m, const T* dv, const std::vector<T>& node_divisor,
                    std::span<const index_t> nodes, T* p_out);

/// Pass 3 over `elems`, from pass 1's elem_F (u has not moved since): pbar =
/// (1/4) sum of the element's four nodal pressures, then ianp_element_forces (or plain_element_forces when
/// model.ianp is false) into f_slot (an element's four corner forces at
/// slots 4 e + corner: one contiguous store per element, into the cache
/// lines of the thread that owns the element). An element whose returned J
/// is <= 0 or not finite is recorded in `bad` (its forces are zero).
template <class T>
void element_forces(const TissueModel<T>& m, TissueState<T>& s, std::span<const index_t> elems, BadElementFlag& bad,
                    tbb::affinity_partitioner& part);

/// Pass 4 over `nodes`: f_a = sum of the node's f_slot entries (slot 4 e +
/// corner for each entry of its node_elem list, in stored order: the same
/// sum as the cuda backend's node-order slots; no atomics), stored in state.f,
/// and u_next by core node_next (held components at u_held, the others the
/// central difference with R = 0). The contact stage may then correct
/// u_next before rotate().
template <class T>
void node_update(const TissueModel<T>& m, TissueState<T>& s, std::span<const index_t> nodes,
                 tbb::affinity_partitioner& part);

/// The same four passes on the calling thread alone, over `elems` / `nodes`
/// (a team member's slice, cpu/partition.hpp): the same per-element and
/// per-node arithmetic, so a slice computes exactly what the TBB loops do.
template <class T>
void element_pressure(const TissueModel<T>& m, TissueState<T>& s, std::span<const index_t> elems);
template <class T>
void nodal_pressure(const TissueModel<T>& m, TissueState<T>& s, const std::vector<T>& node_divisor,
                    std::span<const index_t> nodes);
template <class T>
void element_forces(const TissueModel<T>& m, TissueState<T>& s, std::span<const index_t> elems, BadElementFlag& bad);
template <class T>
void node_update(const TissueModel<T>& m, TissueState<T>& s, std::span<const index_t> nodes);

/// Rotates u_prev <- u <- u_next by swapping the vectors (nodes outside the
/// region must have u == u_prev == u_next, which build_region guarantees).
template <class T>
void rotate(TissueState<T>& s);

}  // namespace tissue::cpu
