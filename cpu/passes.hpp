// The four IANP passes of DESIGN.md section 2 on the host, as TBB loops over
// the region's index lists. Each pass is a function of (const model&,
// state&): it only loops; the per-element and per-node math is core/tet.hpp.
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
inline constexpr std::size_t kElemGrain = 512;   ///< pass 1 (about 40 flops per element)
inline constexpr std::size_t kForceGrain = 128;  ///< pass 3 (about 400 flops, cbrt and pow)
inline constexpr std::size_t kNodeGrain = 512;   ///< passes 2 and 4 (one node->element list each)

/// Per-pass partitioners kept across steps, so that each pass hands the same
/// chunks to the same threads every step (their data stays in that core's cache).
struct PassPartitioners {
  tbb::affinity_partitioner element_pressure, nodal_pressure, element_forces, node_update;
};

/// Pass 1 over `elems`: J_e = det F and elem_pv[e] = volumetric_pressure(J_e, K_e) V_e
/// from the current displacements state.u.
template <class T>
void element_pressure(const TissueModel<T>& m, TissueState<T>& s, std::span<const index_t> elems,
                      tbb::affinity_partitioner& part);

/// Pass 2 over `nodes`: node_p[a] = sum_e p_e V_e / node_volume[a] over the
/// node's node_elem list, in stored order. node_volume (n_nodes, m^3) is
/// sum_e V_e over the same list (core node_volume_sums()).
template <class T>
void nodal_pressure(const TissueModel<T>& m, TissueState<T>& s, const std::vector<T>& node_volume,
                    std::span<const index_t> nodes, tbb::affinity_partitioner& part);

/// Pass 3 over `elems`: pbar = (1/4) sum of the element's four nodal
/// pressures, then ianp_element_forces (or plain_element_forces when
/// model.ianp is false) into elem_f. An element whose returned J is <= 0 or
/// not finite is recorded in `bad` (its forces are zero).
template <class T>
void element_forces(const TissueModel<T>& m, TissueState<T>& s, std::span<const index_t> elems, BadElementFlag& bad,
                    tbb::affinity_partitioner& part);

/// Pass 4 over `nodes`: f_a = sum of elem_f over the node's (element, corner)
/// list in stored order (no atomics), stored in state.f; held components
/// (state.held's axis mask) get u_next = u_held, the others the central
/// difference with R = 0. Then
/// rotates u_prev <- u <- u_next by swapping the vectors (nodes outside the
/// region must have u == u_prev == u_next, which build_region guarantees).
template <class T>
void node_update(const TissueModel<T>& m, TissueState<T>& s, std::span<const index_t> nodes,
                 tbb::affinity_partitioner& part);

}  // namespace tissue::cpu
