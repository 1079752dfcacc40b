// Backend::reduce on the host: one deterministic parallel reduction over the
// region's nodes (tbb::parallel_deterministic_reduce with a fixed grain, so
// the chunking and the summation order do not depend on the thread count:
// results are bit-reproducible). Every sum is accumulated in double.
#pragma once

#include <span>

#include "core/backend.hpp"
#include "core/state.hpp"

namespace tissue::cpu {

/// Chunk size of the reduction (nodes).
inline constexpr std::size_t kReduceGrain = 1024;

/// Reductions over `nodes` (the region's inner and halo nodes) from
/// state.f, u, u_prev, driven, held and region.role:
///   reaction     sum f_a over driven nodes
///   internal     sum f_a over inner nodes
///   free_force2  sum |f_a|^2 over inner nodes that are not held
///   held_force2  sum |f_a|^2 over inner nodes that are held (fixed or driven)
///   kinetic      0.5 sum m_a |(u_a - u_prev_a) / dt|^2 over all `nodes`
///   max_disp     max |u_a| over all `nodes`
///   finite       false if any f_a or u_a visited is not finite
/// bad_elem / bad_J are left at "none"; the caller fills them.
template <class T>
Reductions reduce_region(const TissueModel<T>& m, const TissueState<T>& s, std::span<const index_t> nodes);

}  // namespace tissue::cpu
