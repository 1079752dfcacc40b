// The one launch helper of the cuda backend: zero-size guard, grid from the
// item count and block size, the backend's stream, and an error check after
// every launch (cudaGetLastError: launch-configuration errors, no sync). With
// TISSUE_CUDA_SYNC_CHECK defined, it also synchronises the stream and checks
// for faults raised inside the kernel (debugging aid; slow). nvcc only.
#pragma once

#include <cuda_runtime.h>

#include <atomic>
#include <cstdint>
#include <cstdlib>

#include "core/hd.hpp"
#include "cuda/check.hpp"
#include "cuda/dealt.hpp"

namespace tissue::gpu {

/// Threads per block of the per-item kernels.
inline constexpr int kBlock = 256;

/// An attribute of the current device (cudaDeviceGetAttribute).
inline int current_device_attribute(cudaDeviceAttr attr) {
  int dev = 0, v = 0;
  CUDA_CHECK(cudaGetDevice(&dev));
  CUDA_CHECK(cudaDeviceGetAttribute(&v, attr, dev));
  return v;
}

/// Blocks of `block` threads of `kernel` that the current device holds at
/// once (its occupancy times its multiprocessors): one wave of them.
template <class Kernel>
index_t resident_blocks(Kernel kernel, int block) {
  int per_sm = 0;
  CUDA_CHECK(cudaOccupancyMaxActiveBlocksPerMultiprocessor(&per_sm, kernel, block, 0));
  return index_t(per_sm) * current_device_attribute(cudaDevAttrMultiProcessorCount);
}

/// Half the current device's L2 in bytes: arrays larger than this stream
/// from memory from pass to pass (pass 4's slot drop, pass 3's streaming
/// kernel).
inline std::size_t half_l2_bytes() {
  return std::size_t(current_device_attribute(cudaDevAttrL2CacheSize)) / 2;
}

/// Blocks needed for n items at `block` threads each.
inline int grid_for(index_t n, int block = kBlock) { return static_cast<int>((n + block - 1) / block); }

/// Scenes the launches of the calling thread cover (gridDim.y): 1, or a
/// group's slots while a ScenesInLaunches is alive on it (the capture of a
/// group's tick, cuda/scene_group.hpp; the kernels then move their
/// per-scene arrays to block row y's scene, cuda/views.hpp SceneSlots).
inline thread_local int launch_scenes = 1;

/// Sets launch_scenes for its lifetime.
class ScenesInLaunches {
 public:
  explicit ScenesInLaunches(int scenes) : saved_(launch_scenes) { launch_scenes = scenes; }
  ScenesInLaunches(const ScenesInLaunches&) = delete;
  ScenesInLaunches& operator=(const ScenesInLaunches&) = delete;
  ~ScenesInLaunches() { launch_scenes = saved_; }

 private:
  int saved_;
};

/// Launches kernel<<<(blocks, launch_scenes), block, 0, stream>>>(args...) when blocks > 0.
template <class Kernel, class... Args>
void launch_blocks(int blocks, int block, cudaStream_t stream, Kernel kernel, Args... args) {
  if (blocks <= 0) return;
  kernel<<<dim3(blocks, launch_scenes), block, 0, stream>>>(args...);
  CUDA_CHECK(cudaGetLastError());
#ifdef TISSUE_CUDA_SYNC_CHECK
  CUDA_CHECK(cudaStreamSynchronize(stream));  // not during graph capture
#endif
}

/// Launches one thread per item (n items, kBlock threads per block) when n > 0.
template <class Kernel, class... Args>
void launch(index_t n, cudaStream_t stream, Kernel kernel, Args... args) {
  launch_blocks(n > 0 ? grid_for(n) : 0, kBlock, stream, kernel, args...);
}

/// Programmatic dependent launch is on unless the environment sets
/// TISSUE_CUDA_NO_PDL (a debugging switch: chained kernels then launch
/// plainly; results are identical either way).
inline bool pdl_enabled() {
  static const bool on = std::getenv("TISSUE_CUDA_NO_PDL") == nullptr;
  return on;
}

/// launch_chained() below, in blocks of `block` threads.
template <class... Params, class... Args>
void launch_chained_in(int block, index_t n, cudaStream_t stream, void (*kernel)(Params...), Args... args) {
  if (n <= 0) return;
  cudaLaunchConfig_t cfg = {};
  cfg.gridDim = dim3(grid_for(n, block), launch_scenes);
  cfg.blockDim = dim3(block);
  cfg.stream = stream;
  cudaLaunchAttribute attr;
  attr.id = cudaLaunchAttributeProgrammaticStreamSerialization;
  attr.val.programmaticStreamSerializationAllowed = 1;
  cfg.attrs = &attr;
  cfg.numAttrs = pdl_enabled() ? 1 : 0;
  CUDA_CHECK(cudaLaunchKernelEx(&cfg, kernel, args...));
#ifdef TISSUE_CUDA_SYNC_CHECK
  CUDA_CHECK(cudaStreamSynchronize(stream));
#endif
}

/// Like launch(), with programmatic dependent launch: the grid may be
/// scheduled while the previous kernel in the stream still runs; the kernel
/// must wait (cudaGridDependencySynchronize) before touching anything that
/// kernel writes. Captured into graphs as programmatic edges. The pass
/// kernels (cuda/tled.cuh) are launched this way, through launch_chained_in
/// where their blocks are not kBlock (passes 1, 3 and 4).
template <class... Params, class... Args>
void launch_chained(index_t n, cudaStream_t stream, void (*kernel)(Params...), Args... args) {
  launch_chained_in(kBlock, n, stream, kernel, args...);
}

/// Programmatic dependent launch, inside a chained kernel: let the next
/// kernel in the stream be scheduled now; wait until the previous one has
/// completed (and its writes are visible). Both are no-ops for a plain launch.
__device__ __forceinline__ void let_next_pass_launch() { cudaTriggerProgrammaticLaunchCompletion(); }
__device__ __forceinline__ void wait_for_previous_pass() { cudaGridDependencySynchronize(); }

/// Grid-stride index of the calling thread and the stride.
__device__ __forceinline__ index_t thread_index() { return static_cast<index_t>(blockIdx.x * blockDim.x + threadIdx.x); }
__device__ __forceinline__ index_t thread_stride() { return static_cast<index_t>(gridDim.x * blockDim.x); }

/// This thread's item when the launch's items are dealt to its warps in
/// runs of kRun (cuda/dealt.hpp dealt_item; blocks of whole warps). For the
/// contact stage's merge, whose few expensive items (the nodes a tool
/// pushes) are neighbours along the meshes' Morton numbering: in one warp
/// their different paths run one after the other. Runs keep loads of
/// neighbouring items coalesced.
template <int kRun>
__device__ __forceinline__ index_t dealt_index() {
  static_assert(32 % kRun == 0);
  return dealt_item(thread_index(), thread_stride(), kRun);
}

/// The chained node passes' launches this process has queued (pass 2:
/// pressures, pass 4: updates; eight threads a node, or two lanes a thread:
/// lanes), counted on the host as they are launched or captured into a
/// graph (a region of no nodes launches nothing and counts nothing): the
/// tests' evidence of which kernels a region ran (cuda_node_pass_launches,
/// cuda/cuda_backend.hpp).
struct NodePassLaunches {
  std::atomic<std::int64_t> pressures{0}, pressures_lanes{0}, updates{0}, updates_lanes{0};
  void count(bool pressure_pass, bool lanes) {
    auto& c = pressure_pass ? (lanes ? pressures_lanes : pressures) : (lanes ? updates_lanes : updates);
    c.fetch_add(1, std::memory_order_relaxed);
  }
};
inline NodePassLaunches node_pass_launches;

/// Launches of element_forces_streaming_kernel this process has queued,
/// counted on the host as they are launched or captured into a graph
/// (cuda_streaming_force_launches: the tests' evidence that it ran).
inline std::atomic<std::int64_t> streaming_force_launches{0};

/// Tests: at most this many blocks of an element pass's launch load before
/// their wait (set_cuda_element_first_wave; 0: none); negative: the
/// device's first wave (launch_element_pass, cuda/tled.cuh). Read when a
/// launch is queued or a graph captured.
inline std::atomic<index_t> element_first_wave_cap{-1};

/// Tests: every launch of passes 1 and 3 in the blocks of a launch of
/// several waves (set_cuda_small_element_blocks; launch_element_pass,
/// cuda/tled.cuh), but pass 3's streaming kernel and the pass 3 beside a
/// region check, which always run in blocks of kBlock. Read when a launch
/// is queued or a graph captured.
inline std::atomic<bool> small_element_blocks_forced{false};

/// Launches of pass 1 (pressures) and of pass 3 or the law kernel (forces)
/// in those smaller blocks this process has queued, counted on the host as
/// they are launched or captured into a graph
/// (cuda_small_element_block_launches: the tests' evidence).
struct SmallElementBlockLaunches {
  std::atomic<std::int64_t> pressures{0}, forces{0};
};
inline SmallElementBlockLaunches small_element_block_launches;

}  // namespace tissue::gpu
