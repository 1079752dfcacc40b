// The deformation region (docs/design.md section 3): a flood fill from seed nodes
// over node -> element -> node adjacency for `depth` rings. Nodes reached
// (ring <= depth) are inner (their every element is computed); elements
// touching an inner node are computed; the other corners of those elements
// form the halo, held at their current displacement.
#pragma once

#include <span>
#include <vector>

#include "core/hd.hpp"

namespace tissue {

template <class T> struct TissueModel;

/// Region depth meaning "the whole mesh".
inline constexpr int kDepthAll = -1;

/// Region depth meaning "adaptive": the Scheduler grows the depth while the
/// displacement on the region's front ring is too large (scheduler.hpp).
/// Never passed to flood_fill or a backend: the Scheduler turns it into a
/// number of rings.
inline constexpr int kDepthAuto = -2;

/// Role of a node in the region (one byte per node).
enum NodeRole : std::uint8_t { kOutside = 0, kInner = 1, kHalo = 2 };

/// Sizes of a region (what a device backend reports back per rebuild).
struct RegionSizes {
  int depth = kDepthAll;
  index_t n_inner = 0, n_halo = 0;  ///< inner and halo nodes
  index_t n_elems = 0;              ///< computed elements
  index_t nodes() const { return n_inner + n_halo; }
  bool whole() const { return depth == kDepthAll; }
};

struct Region {
  int depth = kDepthAll;
  std::vector<index_t> seeds;           ///< flood-fill seeds (the contact triangle's nodes)
  std::vector<std::uint8_t> role;       ///< NodeRole (n_nodes)
  std::vector<index_t> nodes;           ///< inner and halo nodes, ascending
  std::vector<index_t> elems;           ///< computed elements, ascending
  std::vector<index_t> front;           ///< front ring: inner nodes first reached by the last ring (ring ==
                                        ///< depth; the seeds when depth is 0), ascending; empty for the whole
                                        ///< mesh or when the fill ran out of nodes before depth rings
  index_t n_inner = 0, n_halo = 0;

  bool whole() const { return depth == kDepthAll; }
  RegionSizes sizes() const { return {depth, n_inner, n_halo, static_cast<index_t>(elems.size())}; }
};

/// Reference flood fill on the host (ascending lists, so every backend can be
/// compared with it element for element). depth = kDepthAll selects every node
/// and element and ignores the seeds; otherwise depth >= 0.
template <class T>
Region flood_fill(const TissueModel<T>& m, std::span<const index_t> seeds, int depth);

}  // namespace tissue
