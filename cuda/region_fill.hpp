// The deformation region on the device (docs/design.md section 3; the host
// reference is core/region.cpp, whose lists these match element for
// element): rings of node -> element -> node expansion from the seeds, the
// computed elements and the halo, then ascending compacted node and element
// lists (cub::DeviceSelect::Flagged keeps the order). Only the four counts
// come back to the host.
#pragma once

#include <cuda_runtime.h>

#include <cstdint>
#include <span>

#include "core/region.hpp"
#include "cuda/device_array.hpp"
#include "cuda/reduce.hpp"
#include "cuda/views.hpp"

namespace tissue::gpu {

/// Mesh adjacency the flood fill walks (device pointers, model layouts).
struct Topology {
  index_t n_nodes = 0, n_elems = 0;
  const index_t* elem_nodes = nullptr;       ///< (4 x n_elems)
  const index_t* node_elem_start = nullptr;  ///< (n_nodes + 1)
  const index_t* node_elem = nullptr;        ///< element * 4 + corner
  const index_t* pack_first = nullptr;       ///< the whole mesh's windows (ModelView::pack_first)
  index_t n_windows = 0, pack_span = 0;
};

template <class T>
Topology topology(const ModelView<T>& m) {
  return {m.n_nodes, m.n_elems, m.elem_nodes, m.node_elem_start, m.node_elem, m.pack_first, m.n_windows, m.pack_span};
}

class RegionFill {
 public:
  /// Allocates the lists, flags and CUB scratch for a mesh of this size
  /// (n_windows: ModelView::n_windows).
  void allocate(index_t n_nodes, index_t n_elems, index_t n_windows, cudaStream_t stream);

  /// Whole mesh: every node inner, identity lists (no copies).
  RegionSizes whole(const Topology& t, std::uint8_t* role, cudaStream_t stream);

  /// Flood fill from `seeds` (validated on the host: ids in range) for
  /// depth >= 0 rings; writes NodeRole into role (n_nodes), the lists and
  /// the fused passes' windows (RegionView::pack_first, packs). One upload
  /// (the seeds) and one download (the five counts).
  RegionSizes build(const Topology& t, std::span<const index_t> seeds, int depth, std::uint8_t* role,
                    Transfers& log, cudaStream_t stream);

  /// The active lists for kernels (null lists for the whole mesh).
  RegionView view() const { return view_; }
  /// The front ring: nodes reached by the last ring (none for the whole mesh).
  FrontView front() const { return view_.nodes ? FrontView{ring_.data(), sizes_.depth} : FrontView{}; }
  const RegionSizes& sizes() const { return sizes_; }

  /// Installs the region built last into the state (the cpu backend's
  /// holding rule, cpu/constraints.hpp, per component): halo nodes are
  /// stopped (u_prev = u_next = u) and hold every component (0 where fixed,
  /// the tool's target where driven, else the current u); other nodes hold
  /// their driven and fixed components (fixed at 0); nodes outside are
  /// frozen (u_prev = u_next = u, f = 0) so buffer rotation keeps them;
  /// elements outside get zero forces.
  template <class T>
  void apply(const ModelView<T>& m, const StateView<T>& s, StepBuffers<T> b, cudaStream_t stream) const;

  /// Downloads role, lists and the front ring into a host Region (tests
  /// and output).
  Region download(const Topology& t, const std::uint8_t* role, std::span<const index_t> seeds, Transfers& log,
                  cudaStream_t stream) const;

 private:
  DeviceArray<index_t> nodes_, elems_, seeds_;
  DeviceArray<index_t> pack_first_, packs_;  ///< the region's windows (RegionView; n_windows + 1 and n_windows)
  DeviceArray<std::uint8_t> pack_used_;     ///< 1 for a window holding one of the region's nodes
  DeviceArray<int> ring_;                 ///< ring at which a node was reached, -1 none (n_nodes)
  DeviceArray<std::uint8_t> node_sel_, elem_sel_, halo_;
  DeviceArray<int> counts_;               ///< n_inner, n_halo, n_nodes, n_elems, n_packs
  DeviceArray<unsigned char> cub_temp_;
  PinnedArray<int> counts_host_;
  RegionView view_;
  RegionSizes sizes_;
};

}  // namespace tissue::gpu
