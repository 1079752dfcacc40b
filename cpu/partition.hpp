// Static slices of a region for the cpu backend's thread team
// (cpu/thread_team.hpp): member r always gets the same contiguous run of the
// region's (ascending) element and node lists, so the arrays it touches stay
// in its core's cache from step to step, and the results do not depend on
// the slicing (every pass writes each slot from one iteration).
#pragma once

#include <cassert>
#include <cstddef>
#include <span>
#include <vector>

#include "core/region.hpp"

namespace tissue::cpu {

/// The fewest elements a team member is given: below this the barrier
/// between passes (about a microsecond) costs more than the member's share of
/// a pass saves, so a small region keeps fewer members busy.
inline constexpr std::size_t kMinMemberElems = 256;

struct Slices {
  int parts = 0;                       ///< members; 0 = not computed for the current region
  std::vector<std::size_t> elem_cut;   ///< member r's elements are region.elems[elem_cut[r] .. elem_cut[r + 1])
  std::vector<std::size_t> node_cut;   ///< and its nodes region.nodes[node_cut[r] .. node_cut[r + 1])

  /// Member r's part of the region's element / node list (the list the
  /// slices were cut from: its size is the last cut).
  std::span<const index_t> elems(std::span<const index_t> all, int r) const {
    assert(all.size() == elem_cut.back());
    return all.subspan(elem_cut[r], elem_cut[r + 1] - elem_cut[r]);
  }
  std::span<const index_t> nodes(std::span<const index_t> all, int r) const {
    assert(all.size() == node_cut.back());
    return all.subspan(node_cut[r], node_cut[r + 1] - node_cut[r]);
  }
};

/// How many of a team's `team_size` members a region of n_elems elements
/// keeps busy (at least kMinMemberElems each, at least one member).
int busy_members(std::size_t n_elems, int team_size);

/// Slices `region` for `parts` members: elements in equal counts cut at
/// multiples of `align` (the lane batch, so only a slice's last batch is
/// partial); nodes in equal shares of their cost, 1 + the length of their
/// node->element list (node_elem_start, n_nodes + 1), which passes 2 and 4 walk.
/// Fills `out` (reusing its vectors: no allocation once they have grown).
void slice_region(const Region& region, const index_t* node_elem_start, int parts, std::size_t align, Slices& out);

}  // namespace tissue::cpu
