// Which nodes the cpu backend integrates and which it holds: the region
// change of Backend::build_region and the tool-driven set of
// Backend::set_driven / clear_driven. Host functions of (const model&,
// state&), called once per contact or tick, never inside the step loop.
//
// The holding rule is core/node_rules.hpp's. Nodes outside the region are
// "frozen": u == u_prev == u_next, so the vector rotation after pass 4
// leaves them where they are.
#pragma once

#include <span>

#include "core/state.hpp"

namespace tissue::cpu {

/// Installs `region` (a flood_fill result) into the state: nodes outside it
/// are frozen (u_prev = u_next = u, f = 0); halo nodes are held at their
/// current u (and stopped: u_prev = u_next = u); fixed and driven components
/// stay held; every other component of a region node is released. Elements outside the region
/// get zero forces in f_slot, so a halo node's f sums only computed elements. The
/// caller recomputes pass 1 over all elements afterwards.
template <class T>
void install_region(const TissueModel<T>& m, TissueState<T>& s, Region region);

/// Makes `nodes` driven with targets u (3 per node, xyz interleaved, m) on
/// the components of axes (one mask 1..7 per node), releasing the
/// previously driven nodes in `driven_list` first (see release_driven);
/// driven_list then holds `nodes`. The arguments were checked by Backend
/// (nodes unique, in range and in the region, masks 1..7, targets finite).
template <class T>
void drive_nodes(const TissueModel<T>& m, TissueState<T>& s, std::vector<index_t>& driven_list,
                 std::span<const index_t> nodes, std::span<const double> u, std::span<const std::uint8_t> axes);

/// Releases every node in driven_list (then empties it): a released node
/// stays held only where it is fixed (at 0) or halo (at its current u).
template <class T>
void release_driven(const TissueModel<T>& m, TissueState<T>& s, std::vector<index_t>& driven_list);

}  // namespace tissue::cpu
