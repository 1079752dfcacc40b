// Backend::reduce on the host, on the backend's thread team
// (cpu/thread_team.hpp): each member sums fixed chunks of kReduceGrain nodes
// or elements, then the chunks' sums are added in chunk order, so the
// chunking and the summation order do not depend on the team's size:
// results are bit-reproducible. Every sum is accumulated in double.
#pragma once

#include <span>
#include <vector>

#include "core/backend.hpp"
#include "core/state.hpp"
#include "cpu/partition.hpp"
#include "cpu/thread_team.hpp"

namespace tissue::cpu {

/// Chunk size of the reduction (nodes or elements; a multiple of kLanes).
inline constexpr std::size_t kReduceGrain = 1024;
static_assert(kReduceGrain % 16 == 0, "a reduction chunk holds whole lane batches (element_lanes.hpp kLanes)");

/// One chunk's sums of core node_terms (all double).
struct NodeSums {
  double reaction[3] = {0, 0, 0};
  double internal[3] = {0, 0, 0};
  double free2 = 0, held2 = 0, kinetic = 0, max_disp = 0;
  bool finite = true;
};

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
};

/// What the region's elements hold at the current u (J; W for the power).
struct ElementEnergies {
  double strain = 0;  ///< sum_e V_e W(Fbar_e) (core/energy.hpp)
  PronyEnergy prony;  ///< the Prony terms' power and stored energy (core/energy.hpp element_prony_energy; 0 without)
};

/// Per-chunk sums, kept between reduces (no allocation per tick).
struct ReduceScratch {
  std::vector<NodeSums> nodes;
  std::vector<ElementEnergies> elems;
};

/// Backend::reduce's sums over the region, on `slices.parts` members of
/// `team` (slices: the region's, cpu/partition.hpp):
/// - over the region's nodes (inner and halo), core node_terms
///   (core/node_rules.hpp) from state.f, u, u_prev, driven, held,
///   region.role and the contact records;
/// - over its elements, the strain energy and the Prony terms' energy at the
///   current u: passes 1 and 2 run into `energy` (the state's own pass
///   arrays are left as the last step wrote them, so download() is
///   unchanged), then per batch of lanes the energy and, for a viscoelastic
///   model, the Prony power and stored energy from the state's Prony history
///   (in T). Leaves energy.fresh set.
/// node_divisor is pass 2's divisor (n_nodes, m^3/Pa). bad_elem / bad_J are
/// left at "none", front_disp at "not computed", the per-tool contact
/// results empty; the caller fills them.
template <class T>
Reductions reduce_region(const TissueModel<T>& m, const TissueState<T>& s, const std::vector<T>& node_divisor,
                         EnergyScratch<T>& energy, ReduceScratch& sums, ThreadTeam& team, const Slices& slices);

/// If scratch is fresh, swaps its passes 1-2 into the state (the values the
/// next step's passes 1 and 2 would compute) and returns true; the caller
/// then skips those passes. Clears fresh either way.
template <class T>
bool take_passes(EnergyScratch<T>& scratch, TissueState<T>& s);

}  // namespace tissue::cpu
