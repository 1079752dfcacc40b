#include "cuda/region_fill.hpp"

#include "core/node_rules.hpp"

#include <cub/device/device_select.cuh>
#include <thrust/iterator/counting_iterator.h>

#include <algorithm>
#include <numeric>
#include <vector>

#include "cuda/launch.cuh"

namespace tissue::gpu {
namespace {

__global__ void seed_kernel(index_t n_seeds, const index_t* seeds, int* ring) {
  const index_t i = thread_index();
  if (i < n_seeds) ring[seeds[i]] = 0;
}

/// One ring: every node reached at ring r claims its unreached neighbours for r + 1.
__global__ void expand_kernel(Topology t, int r, int* ring) {
  const index_t a = thread_index();
  if (a >= t.n_nodes || ring[a] != r) return;
  for (index_t k = t.node_elem_start[a]; k < t.node_elem_start[a + 1]; ++k) {
    const index_t e = incident_element(t.node_elem[k]);
    for (int c = 0; c < 4; ++c) {
      const index_t b = t.elem_nodes[c * t.n_elems + e];
      if (ring[b] < 0) atomicCAS(&ring[b], -1, r + 1);
    }
  }
}

/// Elements with an inner corner are computed; their other corners are halo.
__global__ void mark_elems_kernel(Topology t, const int* ring, std::uint8_t* elem_sel, std::uint8_t* halo) {
  const index_t e = thread_index();
  if (e >= t.n_elems) return;
  index_t c[4];
  bool on = false;
  for (int a = 0; a < 4; ++a) {
    c[a] = t.elem_nodes[a * t.n_elems + e];
    on = on || ring[c[a]] >= 0;
  }
  elem_sel[e] = on;
  if (on)
    for (int a = 0; a < 4; ++a)
      if (ring[c[a]] < 0) halo[c[a]] = 1;  // every writer writes 1
}

__global__ void roles_kernel(index_t n, const int* ring, const std::uint8_t* halo, std::uint8_t* role,
                             std::uint8_t* node_sel, int* counts) {
  const index_t a = thread_index();
  if (a >= n) return;
  const std::uint8_t r = ring[a] >= 0 ? kInner : (halo[a] ? kHalo : kOutside);
  role[a] = r;
  node_sel[a] = r != kOutside;
  if (r == kInner) atomicAdd(&counts[0], 1);
  if (r == kHalo) atomicAdd(&counts[1], 1);
}

template <class T>
__global__ void apply_region_kernel(index_t n, const std::uint8_t* flags, StateView<T> s, StepBuffers<T> b) {
  const index_t a = thread_index();
  if (a >= n) return;
  const std::uint8_t role = s.role[a], fixed = fixed_axes(flags[a]), driven = s.driven[a];
  if (role == kOutside || role == kHalo) {  // frozen, or held in place: stopped
    const Packed3<T> u = b.u[a];
    b.u_prev[a] = u;
    b.u_next[a] = u;
    if (role == kOutside) s.f[a] = {T(0), T(0), T(0), T(0)};
    if (role == kHalo) {
      s.u_held[a] = Packed3<T>::of(halo_target(fixed, driven, u.vec(), s.u_held[a].vec()));
      s.held[a] = kAllAxes;
      return;
    }
  }
  // driven components keep their targets in u_held; fixed ones are at 0
  Packed3<T> held_at = s.u_held[a];
  if (fixed & 1) held_at.x = T(0);
  if (fixed & 2) held_at.y = T(0);
  if (fixed & 4) held_at.z = T(0);
  s.u_held[a] = held_at;
  s.held[a] = driven | fixed;
}

/// Elements outside the region get zero forces, so a halo node's f sums
/// computed elements only.
template <class T>
__global__ void clear_outside_forces_kernel(index_t ne, const std::uint8_t* elem_sel, const index_t* slot_of,
                                            Packed3<T>* f_slot) {
  const index_t e = thread_index();
  if (e >= ne || elem_sel[e]) return;
  for (int a = 0; a < 4; ++a) f_slot[slot_of[a * ne + e]] = {T(0), T(0), T(0), T(0)};
}

/// The region's windows (RegionView::pack_first, packs): node i of the
/// region (ascending ids, so ascending first slots) is the first of every
/// window after node i - 1's up to its own, and the last node's successor
/// (n) the first of every window after its own; node i's window is used.
__global__ void windows_kernel(Topology t, const index_t* nodes, const int* counts, index_t* first,
                               std::uint8_t* used) {
  const index_t i = thread_index(), n = counts[2];
  if (i >= n) return;
  const index_t w = t.node_elem_start[nodes[i]] / t.pack_span;
  const index_t from = i > 0 ? t.node_elem_start[nodes[i - 1]] / t.pack_span + 1 : 0;
  for (index_t v = from; v <= w; ++v) first[v] = i;
  used[w] = 1;
  if (i == n - 1)
    for (index_t v = w + 1; v <= t.n_windows; ++v) first[v] = n;
}

size_t select_temp_bytes(index_t n) {
  size_t bytes = 0;
  // the same argument types as the calls in build(), so the same instantiation
  CUDA_CHECK(cub::DeviceSelect::Flagged(nullptr, bytes, thrust::counting_iterator<index_t>(0),
                                        static_cast<std::uint8_t*>(nullptr), static_cast<index_t*>(nullptr),
                                        static_cast<int*>(nullptr), n));
  return bytes;
}

}  // namespace

void RegionFill::allocate(index_t n_nodes, index_t n_elems, index_t n_windows, cudaStream_t) {
  nodes_.allocate(n_nodes);
  elems_.allocate(n_elems);
  pack_first_.allocate(n_windows + 1);
  packs_.allocate(std::max<index_t>(n_windows, 1));
  pack_used_.allocate(std::max<index_t>(n_windows, 1));
  seeds_.allocate(std::max<index_t>(n_nodes, 3));
  ring_.allocate(n_nodes);
  node_sel_.allocate(n_nodes);
  elem_sel_.allocate(n_elems);
  halo_.allocate(n_nodes);
  counts_.allocate(5);
  counts_host_.allocate(5);
  cub_temp_.allocate(std::max(
      {select_temp_bytes(n_nodes), select_temp_bytes(n_elems), select_temp_bytes(n_windows), size_t(1)}));
  view_ = {};
  sizes_ = {};
}

RegionSizes RegionFill::whole(const Topology& t, std::uint8_t* role, cudaStream_t stream) {
  CUDA_CHECK(cudaMemsetAsync(role, kInner, t.n_nodes, stream));
  view_ = {nullptr, nullptr, t.n_nodes, t.n_elems, nullptr, t.pack_first, nullptr, t.n_windows};
  sizes_ = {kDepthAll, t.n_nodes, 0, t.n_elems};
  return sizes_;
}

RegionSizes RegionFill::build(const Topology& t, std::span<const index_t> seeds, int depth, std::uint8_t* role,
                              Transfers& log, cudaStream_t stream) {
  if (seeds.size() > seeds_.size()) seeds_.allocate(seeds.size());  // only for duplicate-laden seed lists
  ring_.fill_bytes(0xff, stream);  // -1: not reached
  halo_.fill_bytes(0, stream);
  counts_.fill_bytes(0, stream);
  const auto n_seeds = static_cast<index_t>(seeds.size());
  log.to_device_now(seeds_.data(), seeds.data(), seeds.size_bytes(), stream);
  launch(n_seeds, stream, seed_kernel, n_seeds, seeds_.data(), ring_.data());
  for (int r = 0; r < depth; ++r) launch(t.n_nodes, stream, expand_kernel, t, r, ring_.data());
  launch(t.n_elems, stream, mark_elems_kernel, t, ring_.data(), elem_sel_.data(), halo_.data());
  launch(t.n_nodes, stream, roles_kernel, t.n_nodes, ring_.data(), halo_.data(), role, node_sel_.data(),
         counts_.data());
  size_t bytes = cub_temp_.bytes();
  CUDA_CHECK(cub::DeviceSelect::Flagged(cub_temp_.data(), bytes, thrust::counting_iterator<index_t>(0),
                                        node_sel_.data(), nodes_.data(), counts_.data() + 2, t.n_nodes, stream));
  bytes = cub_temp_.bytes();
  CUDA_CHECK(cub::DeviceSelect::Flagged(cub_temp_.data(), bytes, thrust::counting_iterator<index_t>(0),
                                        elem_sel_.data(), elems_.data(), counts_.data() + 3, t.n_elems, stream));
  if (t.n_windows > 0) {
    pack_used_.fill_bytes(0, stream);
    launch(t.n_nodes, stream, windows_kernel, t, nodes_.data(), counts_.data(), pack_first_.data(), pack_used_.data());
    bytes = cub_temp_.bytes();
    CUDA_CHECK(cub::DeviceSelect::Flagged(cub_temp_.data(), bytes, thrust::counting_iterator<index_t>(0),
                                          pack_used_.data(), packs_.data(), counts_.data() + 4, t.n_windows,
                                          stream));
  }
  log.to_host(counts_host_.data(), counts_.data(), 5 * sizeof(int), stream);
  sizes_ = {depth, counts_host_[0], counts_host_[1], counts_host_[3]};
  view_ = {nodes_.data(), elems_.data(), counts_host_[2], counts_host_[3], elem_sel_.data(),
           pack_first_.data(), packs_.data(), counts_host_[4]};
  return sizes_;
}

Region RegionFill::download(const Topology& t, const std::uint8_t* role, std::span<const index_t> seeds,
                            Transfers& log, cudaStream_t stream) const {
  Region r;
  r.depth = sizes_.depth;
  r.seeds.assign(seeds.begin(), seeds.end());
  r.n_inner = sizes_.n_inner;
  r.n_halo = sizes_.n_halo;
  r.role.resize(t.n_nodes);
  log.to_host(r.role.data(), role, r.role.size(), stream);
  r.nodes.resize(view_.n_nodes);
  r.elems.resize(view_.n_elems);
  if (view_.nodes) {
    log.to_host(r.nodes.data(), view_.nodes, r.nodes.size() * sizeof(index_t), stream);
    log.to_host(r.elems.data(), view_.elems, r.elems.size() * sizeof(index_t), stream);
    std::vector<int> ring(t.n_nodes);
    log.to_host(ring.data(), ring_.data(), ring.size() * sizeof(int), stream);
    for (index_t a = 0; a < t.n_nodes; ++a)
      if (ring[a] == sizes_.depth) r.front.push_back(a);  // ascending; empty if the fill ran out
  } else {
    std::iota(r.nodes.begin(), r.nodes.end(), 0);
    std::iota(r.elems.begin(), r.elems.end(), 0);
  }
  return r;
}

template <class T>
void RegionFill::apply(const ModelView<T>& m, const StateView<T>& s, StepBuffers<T> b, cudaStream_t stream) const {
  launch(m.n_nodes, stream, apply_region_kernel<T>, m.n_nodes, m.node_flags, s, b);
  if (view_.elems)
    launch(m.n_elems, stream, clear_outside_forces_kernel<T>, m.n_elems, elem_sel_.data(), m.slot_of, s.f_slot);
}

template void RegionFill::apply(const ModelView<float>&, const StateView<float>&, StepBuffers<float>,
                                cudaStream_t) const;
template void RegionFill::apply(const ModelView<double>&, const StateView<double>&, StepBuffers<double>,
                                cudaStream_t) const;

}  // namespace tissue::gpu
