#include "cuda/stepper.hpp"

#include <algorithm>
#include <limits>
#include <stdexcept>
#include <type_traits>

#include "cuda/tled.cuh"

namespace tissue::gpu {
namespace {

template <class T, bool kLaw, bool kRecomputed>
int largest_cluster() {
  const auto kernel = persistent_cluster_kernel<T, kLaw, kRecomputed>;
  if (current_device_attribute(cudaDevAttrComputeCapabilityMajor) < 9) return 0;
  if (cudaFuncSetAttribute(kernel, cudaFuncAttributeNonPortableClusterSizeAllowed, 1) != cudaSuccess) {
    cudaGetLastError();  // clear: clusters are then limited to the portable size
  }
  for (int size : {16, 8, 4, 2}) {
    cudaLaunchConfig_t cfg = {};
    cfg.gridDim = dim3(size);
    cfg.blockDim = dim3(kClusterBlock<T>);
    cudaLaunchAttribute attr;
    attr.id = cudaLaunchAttributeClusterDimension;
    attr.val.clusterDim.x = size;
    attr.val.clusterDim.y = 1;
    attr.val.clusterDim.z = 1;
    cfg.attrs = &attr;
    cfg.numAttrs = 1;
    int clusters = 0;
    if (cudaOccupancyMaxActiveClusters(&clusters, kernel, &cfg) != cudaSuccess) {
      cudaGetLastError();
      continue;
    }
    if (clusters >= 1) return size;
  }
  return 0;
}

/// Co-resident blocks per SM of the grid kernel (its kRecomputed variants
/// alike: the smaller).
template <class T, bool kLaw>
int grid_blocks_per_sm() {
  int stored = 0, recomputed = 0;
  CUDA_CHECK(
      cudaOccupancyMaxActiveBlocksPerMultiprocessor(&stored, persistent_grid_kernel<T, kLaw, false>, kGridBlock, 0));
  CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&recomputed, persistent_grid_kernel<T, kLaw, true>,
                                                           kGridBlock, 0));
  return std::min(stored, recomputed);
}

/// Blocks of the fused force kernel the device holds at once (its
/// instantiations alike: the fewest).
template <class T>
index_t fused_force_blocks() {
  index_t fewest = std::numeric_limits<index_t>::max();
  for (auto kernel : {packed_forces_kernel<T, false, false, true>, packed_forces_kernel<T, false, true, true>,
                      packed_forces_kernel<T, true, false, true>, packed_forces_kernel<T, true, true, true>,
                      packed_forces_kernel<T, false, false, false>, packed_forces_kernel<T, false, true, false>,
                      packed_forces_kernel<T, true, false, false>, packed_forces_kernel<T, true, true, false>}) {
    fewest = std::min(fewest, resident_blocks(kernel, kPackedBlock));
  }
  return fewest;
}

/// Surface nodes one wave of the merge's blocks of kBlock holds.
template <class T>
index_t merge_wave_nodes() {
  return resident_blocks(gather_contacts_kernel<T>, kBlock) * kBlock;
}

}  // namespace

template <class T>
void Stepper<T>::init() {
  graphs_.clear();
  limits_ = {};
  limits_.block = kClusterBlock<T>;
  if (current_device_attribute(cudaDevAttrCooperativeLaunch)) {
    const int sms = current_device_attribute(cudaDevAttrMultiProcessorCount);
    limits_.grid_blocks = grid_blocks_per_sm<T, false>() * sms;
    limits_.law_grid_blocks = grid_blocks_per_sm<T, true>() * sms;
  }
  limits_.cluster_size = std::min(largest_cluster<T, false, false>(), largest_cluster<T, false, true>());
  limits_.law_cluster_size = std::min(largest_cluster<T, true, false>(), largest_cluster<T, true, true>());
  limits_.fused_force_blocks = fused_force_blocks<T>();
  limits_.merge_wave_nodes = merge_wave_nodes<T>();
  if constexpr (kStreamingForceBlocks<T> > 0)  // four slots an element
    limits_.streaming_elems = index_t(half_l2_bytes() / (4 * sizeof(Packed3<T>)));
}

template <class T>
int Stepper<T>::merge_block(index_t n_surf) const {
  return n_surf <= limits_.merge_wave_nodes ? kBlock : kSmallMergeBlock;
}

template <class T>
void Stepper<T>::set_mode(CudaStepMode mode) {
  if (mode == CudaStepMode::Grid && limits_.grid_blocks == 0)
    throw std::invalid_argument("cuda step mode 'grid': this device does not support cooperative launches");
  if ((mode == CudaStepMode::Grid || mode == CudaStepMode::Cluster) && body_.rows > 0)
    throw std::invalid_argument("cuda step mode 'grid' or 'cluster' has no contact between bodies; use auto, graph "
                                "or launch");
  if (mode == CudaStepMode::Cluster && limits_.cluster_size == 0)
    throw std::invalid_argument("cuda step mode 'cluster': this device has no thread-block clusters (needs sm_90+)");
  mode_ = mode;
}

template <class T>
CudaStepMode Stepper<T>::choose(const RegionView& r) const {
  (void)r;  // every region size: see the measurements in docs/cuda.md
  return mode_ == CudaStepMode::Auto ? CudaStepMode::Graph : mode_;
}

template <class T>
void Stepper<T>::element_pressure(const ModelView<T>& m, const StateView<T>& s, const RegionView& r,
                                  const Packed3<T>* u, cudaStream_t stream, const RegionView* gradients_of) {
  with_gradients(m, gradients_of ? *gradients_of : r, [&](auto recomputed) {
    enqueue_element_pressures<T, decltype(recomputed)::value>(m, s, r, u, stream);
  });
}

template <class T>
void Stepper<T>::nodal_pressure(const ModelView<T>& m, const StateView<T>& s, const RegionView& r,
                                cudaStream_t stream) {
  enqueue_nodal_pressures(m, s, r, stream);
}

template <class T>
void Stepper<T>::element_forces(const ModelView<T>& m, const StateView<T>& s, const RegionView& r,
                                const Packed3<T>* u, cudaStream_t stream, bool beside_check) {
  with_gradients(m, r, [&](auto recomputed) {
    constexpr bool kRecomputed = decltype(recomputed)::value;
    if (beside_check && law_.neo_hookean())  // (a law kernel's Prony state must not move before the check)
      launch_chained(r.n_elems, stream, element_forces_beside_check_kernel<T, kRecomputed>, m, s, r, u);
    else if (law_.neo_hookean() && streams_slots(r)) {
      // (compiled under launch bounds of kBlock: never in smaller blocks)
      launch_element_pass<element_forces_streaming_kernel<T, kRecomputed>, kBlock, true>(false, r.n_elems, stream, m, s,
                                                                                         r, u);
      streaming_force_launches.fetch_add(1, std::memory_order_relaxed);
    } else if (law_.neo_hookean()) {
      constexpr bool kLate = kLateLoads<T>;
      launch_element_pass<element_forces_kernel<T, kRecomputed>, kPass3WaveBlock, kLate>(false, r.n_elems, stream, m, s,
                                                                                         r, u);
    } else {
      launch_element_pass<law_element_forces_kernel<T, kRecomputed>, kPass3WaveBlock, true>(false, r.n_elems, stream, m,
                                                                                            s, r, u, law_);
    }
  });
}

template <class T>
void Stepper<T>::node_update(const ModelView<T>& m, const StateView<T>& s, const RegionView& r, StepBuffers<T> b,
                             cudaStream_t stream) {
  with_flag(s.load != nullptr, [&](auto load) { enqueue_node_update<T, decltype(load)::value>(m, s, r, b, stream); });
}

template <class T>
void Stepper<T>::forces_and_update(const ModelView<T>& m, const StateView<T>& s, const RegionView& r,
                                   StepBuffers<T> b, cudaStream_t stream, bool early) {
  with_gradients(m, r, [&](auto recomputed) {
    with_flag(s.load != nullptr, [&](auto load) {
      with_flag(early, [&](auto is_early) {
        launch_chained_in(kPackedBlock, index_t(kPackedBlock) * r.n_packs, stream,
                          packed_forces_kernel<T, decltype(recomputed)::value, decltype(load)::value,
                                               decltype(is_early)::value>,
                          m, s, r, b);
      });
    });
  });
}

template <class T>
void Stepper<T>::launch_steps(const ModelView<T>& m, const StateView<T>& s, const RegionView& r, StepBuffers<T> b,
                              int steps, const ContactTools<T>* tools, StepStart start, cudaStream_t stream) {
  for (int k = 0; k < steps; ++k) {
    if (k > 0 || start == StepStart::kPass1) {
      enqueue_pressures(m, s, r, b.u, stream);
    }
    const bool beside_check = k == 0 && start == StepStart::kPass3BesideCheck;
    if (!beside_check && fuses_forces(r)) {
      forces_and_update(m, s, r, b, stream, /*early=*/!tools && body_.rows == 0);
    } else {
      element_forces(m, s, r, b.u, stream, beside_check);
      node_update(m, s, r, b, stream);
    }
    if (body_.rows > 0) enqueue_body_step(m, s, body_, b, stream);  // bodies first: a rigid tool has the last word
    if (tools) {  // the contact stage over the surface (cuda/contact.cuh)
      launch_chained(m.n_tris, stream, sweep_triangles_kernel<T>, m, s, tools, k,
                     static_cast<const Packed3<T>*>(b.u_next));
      launch_chained_in(merge_block(m.n_surf), m.n_surf, stream, gather_contacts_kernel<T>, m, s, tools, k, b.u,
                        b.u_next);
    }
    b = b.rotated();
  }
  if (body_.rows > 0 && steps > 0) enqueue_body_check(m, s, body_, b.u, stream);  // the lists' reach, at the new u
}

template <class T>
cudaGraphExec_t Stepper<T>::cached_graph(const GraphKey& key, const std::function<void(cudaStream_t)>& enqueue,
                                         cudaStream_t stream) {
  if (auto it = graphs_.find(key); it != graphs_.end()) return it->second.get();
  ++captures_;
  GraphKey shape = key;
  shape.pressures = 0;
  GraphExec reuse;
  if (auto it = kept_.find(shape); it != kept_.end()) {
    reuse = std::move(it->second);
    kept_.erase(it);
  }
  bool updated = false;
  GraphExec exec = capture_graph(stream, enqueue, std::move(reuse), &updated);
  updates_ += updated;
  return graphs_.emplace(key, std::move(exec)).first->second.get();
}

template <class T>
void Stepper<T>::invalidate() {
  if (kept_.size() + graphs_.size() > kMaxKept) kept_.clear();
  for (auto& [key, exec] : graphs_) {
    GraphKey shape = key;
    shape.pressures = 0;
    kept_.emplace(shape, std::move(exec));
  }
  graphs_.clear();
}

template <class T>
void Stepper<T>::adopt_graphs(Stepper& other) {
  other.invalidate();
  invalidate();
  if (kept_.size() + other.kept_.size() > kMaxKept) kept_.clear();
  kept_.merge(other.kept_);
  other.kept_.clear();
}

GraphExec capture_graph(cudaStream_t stream, const std::function<void(cudaStream_t)>& enqueue, GraphExec reuse,
                        bool* updated) {
  cudaGraph_t g = nullptr;
  CUDA_CHECK(cudaStreamBeginCapture(stream, cudaStreamCaptureModeThreadLocal));
  try {
    enqueue(stream);
  } catch (...) {
    cudaStreamEndCapture(stream, &g);
    if (g) cudaGraphDestroy(g);
    throw;
  }
  CUDA_CHECK(cudaStreamEndCapture(stream, &g));
  if (reuse.get()) {
    cudaGraphExecUpdateResultInfo info{};
    const cudaError_t update = cudaGraphExecUpdate(reuse.get(), g, &info);
    if (update == cudaSuccess) {
      cudaGraphDestroy(g);
      if (updated) *updated = true;
      return reuse;
    }
    if (update != cudaErrorGraphExecUpdateFailure) {  // not a topology that differs: a real error
      cudaGraphDestroy(g);
      CUDA_CHECK(update);
    }
    (void)cudaGetLastError();  // a topology that differs: instantiated below
  }
  cudaGraphExec_t exec = nullptr;
  const cudaError_t err = cudaGraphInstantiate(&exec, g, 0);
  cudaGraphDestroy(g);
  CUDA_CHECK(err);
  return GraphExec(exec);
}

template <class T>
cudaGraphExec_t Stepper<T>::graph(const ModelView<T>& m, const StateView<T>& s, const RegionView& r,
                                  BufferRing<T>& ring, int steps, const ContactTools<T>* tools, StepStart start,
                                  cudaStream_t stream) {
  return cached_graph(
      {ring.phase, steps, tools != nullptr, GraphKey::kSteps, 0, pressures_of(s), static_cast<int>(start)},
      [&](cudaStream_t st) { launch_steps(m, s, r, ring.current(), steps, tools, start, st); }, stream);
}

template <class T>
void Stepper<T>::advance(const ModelView<T>& m, const StateView<T>& s, const RegionView& r, BufferRing<T>& ring,
                         int steps, const ContactTools<T>* tools, StepStart start, cudaStream_t stream) {
  if (steps <= 0) return;
  if (r.n_elems == 0 && r.n_nodes == 0 && !tools) {  // nothing moves; every buffer holds the same (frozen) values
    ring.advance(steps);
    return;
  }
  switch (choose(r)) {
    case CudaStepMode::Auto:  // resolved by choose()
    case CudaStepMode::Launch:
      launch_steps(m, s, r, ring.current(), steps, tools, start, stream);
      ring.advance(steps);
      break;
    case CudaStepMode::Graph:
      while (steps > 0) {
        const int k = std::min(steps, kMaxGraphSteps);
        CUDA_CHECK(cudaGraphLaunch(graph(m, s, r, ring, k, tools, start, stream), stream));
        ring.advance(k);
        steps -= k;
        start = StepStart::kPass1;
      }
      break;
    case CudaStepMode::Grid: {
      const index_t items = std::max({r.n_elems, kNodeLanes * r.n_nodes, tools ? m.n_tris : 0});
      const bool law = !law_.neo_hookean();
      const int blocks = std::clamp(grid_for(items, kGridBlock), 1,
                                    std::max(1, law ? limits_.law_grid_blocks : limits_.grid_blocks));
      ModelView<T> ma = m;
      StateView<T> sa = s;
      RegionView ra = r;
      StepBuffers<T> b = ring.current();
      const ContactTools<T>* ta = tools;
      LawView<T> wa = law_;
      int from_pass3 = start != StepStart::kPass1;
      void* args[] = {&ma, &sa, &ra, &b, &steps, &ta, &wa, &from_pass3};
      const void* kernel = with_gradients(m, r, [&](auto recomputed) {
        constexpr bool kRecomputed = decltype(recomputed)::value;
        return law ? reinterpret_cast<const void*>(persistent_grid_kernel<T, true, kRecomputed>)
                   : reinterpret_cast<const void*>(persistent_grid_kernel<T, false, kRecomputed>);
      });
      CUDA_CHECK(cudaLaunchCooperativeKernel(kernel, dim3(blocks), dim3(kGridBlock), args, 0, stream));
      ring.advance(steps);
      break;
    }
    case CudaStepMode::Cluster: {
      const index_t items = std::max({r.n_elems, kNodeLanes * r.n_nodes, tools ? m.n_tris : 0});
      const bool law = !law_.neo_hookean();
      const int blocks = std::clamp(grid_for(items, kClusterBlock<T>), 1,
                                    std::max(1, law ? limits_.law_cluster_size : limits_.cluster_size));
      cudaLaunchConfig_t cfg = {};
      cfg.gridDim = dim3(blocks);
      cfg.blockDim = dim3(kClusterBlock<T>);
      cfg.stream = stream;
      cudaLaunchAttribute attr;
      attr.id = cudaLaunchAttributeClusterDimension;
      attr.val.clusterDim.x = blocks;
      attr.val.clusterDim.y = 1;
      attr.val.clusterDim.z = 1;
      cfg.attrs = &attr;
      cfg.numAttrs = 1;
      with_gradients(m, r, [&](auto recomputed) {
        constexpr bool kRecomputed = decltype(recomputed)::value;
        const auto kernel =
            law ? persistent_cluster_kernel<T, true, kRecomputed> : persistent_cluster_kernel<T, false, kRecomputed>;
        CUDA_CHECK(cudaLaunchKernelEx(&cfg, kernel, m, s, r, ring.current(), steps, tools, law_,
                                      int(start != StepStart::kPass1)));
      });
      ring.advance(steps);
      break;
    }
  }
}

template class Stepper<float>;
template class Stepper<double>;

}  // namespace tissue::gpu
