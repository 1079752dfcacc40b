// Backend::reduce on the host: one deterministic parallel reduction over the
// region's nodes (tbb::parallel_deterministic_reduce with a fixed grain, so
// the chunking and the summation order do not depend on the thread count:
// results are bit-reproducible). Every sum is accumulated in double.
#pragma once

#include <tbb/partitioner.h>

#include <span>
#include <vector>

#include "core/backend.hpp"
#include "core/state.hpp"

namespace tissue::cpu {

/// Chunk size of the reduction (nodes).
inline constexpr std::size_t kReduceGrain = 1024;

/// Reductions over `nodes` (the region's inner and halo nodes): the sum of
/// core node_terms (core/node_rules.hpp) from state.f, u, u_prev, driven,
/// held, region.role and the contact records. bad_elem / bad_J are left at
/// "none", strain_energy and front_disp at "not computed", the per-tool
/// contact results empty; the caller fills them.
template <class T>
Reductions reduce_region(const TissueModel<T>& m, const TissueState<T>& s, std::span<const index_t> nodes);

/// max |u_a| over the region's front ring (state.region.front), m; 0 when it is empty.
template <class T>
double front_displacement(const TissueModel<T>& m, const TissueState<T>& s);

/// Passes 1 and 2 at the current u, as element_energies computes them (sized
/// on first use, then reused: no allocation per tick). The next TLED step
/// would compute exactly these numbers from the same u (a tick's driving
/// changes targets, not u), so the backend swaps them into its state
/// instead of recomputing them (take_passes). Every element and node
/// outside the region keeps the state's value.
template <class T>
struct EnergyScratch {
  std::vector<T> elem_dv;  ///< (J_e - 1) V_e (n_elems) m^3
  std::vector<T> elem_J;   ///< det F (n_elems)
  std::vector<T> elem_F;   ///< F (9 x n_elems; the region's elements only)
  std::vector<T> node_p;   ///< nodal pressure (n_nodes) Pa
  bool fresh = false;      ///< holds passes 1-2 of the state's current u and region
  /// elem_dv, elem_J and node_p equal the state's outside the region (the
  /// passes rewrite the region's entries, so only a full copy makes them
  /// equal; clear it whenever the state's arrays change beyond the region:
  /// upload, new displacements, a new region)
  bool synced = false;
  tbb::affinity_partitioner pressure_part, nodal_part;  ///< for its passes 1 and 2
};

/// What the region's elements hold at the current u (J; W for the power).
struct ElementEnergies {
  double strain = 0;  ///< sum_e V_e W(Fbar_e) (core/energy.hpp)
  PronyEnergy prony;  ///< the Prony terms' power and stored energy (core/energy.hpp element_prony_energy; 0 without)
};

/// The strain energy and the Prony terms' energy over the region's elements
/// at the current u, from one traversal: passes 1 and 2 run into `scratch`
/// (the state's own pass arrays are left as the last step wrote them, so
/// download() is unchanged), then per batch of lanes the energy and, for a
/// viscoelastic model, the Prony power and stored energy from the state's
/// Prony history (in T); summed in double by a deterministic reduction.
/// node_divisor is pass 2's divisor (n_nodes, m^3/Pa). Leaves scratch.fresh set.
template <class T>
ElementEnergies element_energies(const TissueModel<T>& m, const TissueState<T>& s, const std::vector<T>& node_divisor,
                                 EnergyScratch<T>& scratch);

/// If scratch is fresh, swaps its passes 1-2 into the state (the values the
/// next step's passes 1 and 2 would compute) and returns true; the caller
/// then skips those passes. Clears fresh either way.
template <class T>
bool take_passes(EnergyScratch<T>& scratch, TissueState<T>& s);

}  // namespace tissue::cpu
