// The cuda backend. This header has no CUDA includes: the registry and the
// apps see only the Backend interface and the few CUDA-free extras below.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "core/backend.hpp"
#include "cuda/gradients.hpp"

namespace tissue {

std::unique_ptr<Backend> make_cuda_backend(Precision precision);

/// Scenes of one model stepped as one on the GPU (BackendGroup; docs/batch.md,
/// "One launch per pass"): `slots` scenes of at most `slot_bytes` of device
/// memory each (a scene's bytes, measured, with room for the arrays'
/// alignment), in one allocation. At most kMaxCudaGroupScenes scenes (a
/// launch's gridDim.y).
inline constexpr int kMaxCudaGroupScenes = 65535;
std::shared_ptr<BackendGroup> make_cuda_scene_group(Precision precision, int slots, std::size_t slot_bytes);

/// Makes `backend` (a cuda backend of the group's precision) scene `slot` of
/// `group`, before its upload: its arrays then lie in the slot.
void join_cuda_scene_group(Backend& backend, const std::shared_ptr<BackendGroup>& group, int slot);

/// A per-node field where it lies in a cuda backend's device memory
/// (registry.hpp DeviceField): which 0 displacement (the current buffer),
/// 1 internal force less the load.
struct CudaNodeField {
  const void* data = nullptr;
  std::int64_t nodes = 0, node_stride = 0;
  int scalar_bytes = 0, device = -1;
};
CudaNodeField cuda_node_field(Backend& backend, int which);

/// cudaMemcpy from device memory to the host (throws naming the pointer
/// where src is not device memory).
void cuda_copy_to_host(const void* src, void* dst, std::size_t bytes);

/// True when a CUDA device can be used; otherwise *why says why not.
/// On success *why holds the device name.
bool cuda_available(std::string* why);

/// Caps the device memory the cuda backends of this process may hold
/// together (bytes; 0 = only the GPU's own limit): a host that shares the GPU
/// with its renderer sets it. Beyond it, and when the GPU itself is full,
/// upload() throws naming the bytes asked for, held and free (a
/// std::runtime_error).
void set_cuda_memory_limit(std::size_t bytes);

/// Device-to-device copy bandwidth of the current GPU (bytes/s, bytes read
/// plus bytes written), timed with CUDA events over a 2 x 512 MiB copy
/// (median of several repeats). Throws std::runtime_error without a GPU.
double cuda_copy_bandwidth();

/// Whether this build's kernels divide and take square roots in float with
/// nvcc's approximate forms and flush float denormals to zero (CMake option
/// TISSUE_CUDA_FAST_FLOAT_MATH, on by default: -prec-div=false
/// -prec-sqrt=false -ftz=true) rather than IEEE round-to-nearest with
/// denormals. Double precision is IEEE either way (docs/cuda.md, "Float
/// division and square root").
bool cuda_fast_float_math();

/// The float division and square root of this build's kernels, measured on
/// the device against the host's IEEE operations over `samples` fixed
/// pseudo-random operands (mantissas at random, exponents in [-20, 20]):
/// how many results differ and by how many ulps at most; and whether a
/// product below the smallest normal float comes out as 0. Throws
/// std::runtime_error without a GPU.
struct CudaFloatMathProbe {
  index_t samples = 0;
  long div_differ = 0, sqrt_differ = 0;
  long div_ulps_max = 0, sqrt_ulps_max = 0;
  bool flushes_denormals = false;
};
CudaFloatMathProbe cuda_probe_float_math(index_t samples = index_t(1) << 20);

/// The contact stage's arithmetic chains alone on one warp of the current
/// device (cuda/contact_chains.cu; docs/cuda.md, "The contact stage's own
/// chains"): cycles per call, each part run `iters` times with every call's
/// input depending on the last one's result, for a 2 mm probe 0.5 mm into a
/// plane -- the test of a triangle, the sweep of a 1.5 mm triangle whose
/// corners are inside the tip (node contact, then face contact) and of an
/// 8 mm one (face contact alone) by a lane group, and the merge of 3, 6 and
/// 8 proposals. clock_mhz is the device's peak clock (cycles / clock_mhz =
/// microseconds at that clock). The sweeps' largest correction, how far
/// the device's proposals and merges lie from core's on the host (m), and
/// whether both triangles pass the test, say that a real contact was timed.
/// chain_per_step_us: test + sweep with corners inside + merge of six. Throws std::runtime_error without a GPU.
struct CudaContactChains {
  double clock_mhz = 0;
  double test_cycles = 0, sweep_pushed_cycles = 0, sweep_face_cycles = 0;
  int merge_counts[3] = {};
  double merge_cycles[3] = {};
  double merged_dx[3] = {};  ///< |dx| of each merge (m)
  double merged_apart = 0;   ///< the largest |dx| between a device merge and the host's of the same proposals (m)
  double pushed_dx = 0, face_dx = 0, pushed_apart = 0, face_apart = 0;
  bool touching = false;
  double chain_per_step_us = 0;
};
CudaContactChains cuda_contact_chains(Precision precision, int iters = 2000);

/// How the cuda backend runs advance(n); every mode gives the same results
/// (see cuda/stepper.hpp). Auto = Graph (captured, chained per-pass
/// kernels), the fastest measured at every size.
enum class CudaStepMode { Auto, Launch, Graph, Grid, Cluster };

const char* to_string(CudaStepMode mode);

/// Selects the step mode of a backend made by make_cuda_backend. Throws
/// std::invalid_argument when `backend` is not a cuda backend or the device
/// cannot run the mode (no cooperative launch, no clusters).
void set_cuda_step_mode(Backend& backend, CudaStepMode mode);

/// The mode advance() uses for the backend's current region (Auto resolved).
CudaStepMode cuda_step_mode(Backend& backend);

/// Whether the chained steps (Launch and Graph modes) over the backend's
/// current region run passes 3 and 4 as one kernel: a model without law
/// terms and a region of at most cuda_fused_force_blocks() windows of
/// nodes, the most blocks of the fused kernel the device holds at once
/// (docs/cuda.md, "Passes 3 and 4 as one kernel").
bool cuda_fuses_forces(Backend& backend);
index_t cuda_fused_force_blocks(Backend& backend);
/// Overrides that limit (tests: 0 runs passes 3 and 4 apart on every
/// region, the same bits).
void set_cuda_fused_force_blocks(Backend& backend, index_t blocks);

/// The fewest nodes of a region whose chained node passes (2 and 4) take
/// two of a node's eight lanes a thread (docs/cuda.md, "Node passes with
/// two lanes a thread"): two waves of the device's resident threads at
/// eight threads a node (67,584 nodes on an H100); 0 before an upload.
index_t cuda_lanes_node_min(Backend& backend);
/// Overrides it until the next upload (tests: 0 runs every region's node
/// passes two lanes a thread, the same bits).
void set_cuda_lanes_node_min(Backend& backend, index_t nodes);

/// Whether pass 4's chained kernel over the whole mesh drops the force
/// slots' lines it has read from the L2 (PTX `discard.global.L2`: a dirty
/// line read for the last time is not written back to memory): set at
/// upload where the slots exceed half the device's L2 (docs/cuda.md, "Pass
/// 4 drops the slots it has read"); false before an upload.
bool cuda_discards_slots(Backend& backend);
/// Overrides it until the next upload (tests: the same bits either way).
void set_cuda_discards_slots(Backend& backend, bool discard);

/// Launches of the chained node passes' kernels this process has queued
/// (pass 2: pressures, pass 4: updates), eight threads a node or two lanes
/// a thread (lanes), counted on the host as they are launched or captured
/// into a graph (a graph's replays add nothing): the tests' evidence of
/// which kernels a region ran, and that a graph is captured again after
/// set_cuda_lanes_node_min. The fused kernels, which run passes 1-2 or 3-4
/// in one, are not counted.
struct CudaNodePassLaunches {
  std::int64_t pressures = 0, pressures_lanes = 0, updates = 0, updates_lanes = 0;
};
CudaNodePassLaunches cuda_node_pass_launches();

/// The most surface nodes the contact stage's merge takes in blocks of 256
/// threads (one wave of them on the device); a larger surface is merged in
/// blocks of 64 (docs/cuda.md, "The merge in smaller blocks").
index_t cuda_merge_wave_nodes(Backend& backend);
/// Overrides it (tests: 0 merges every surface in blocks of 64, the same bits).
void set_cuda_merge_wave_nodes(Backend& backend, index_t nodes);

/// Pass 3 runs its streaming kernel (three blocks an SM in double) over a
/// region of more elements than this: where their force slots exceed half
/// the L2. 0 in float, which has no such kernel (docs/cuda.md, "Later
/// waves load after their wait").
index_t cuda_streaming_elems(Backend& backend);
/// Overrides it for this backend (tests: 1 runs the streaming kernel on
/// every region in either precision, 0 never; the same bits).
void set_cuda_streaming_elems(Backend& backend, index_t elems);

/// Launches of pass 3's streaming kernel this process has queued (counted
/// as they are launched or captured into a graph; replays add nothing).
std::int64_t cuda_streaming_force_launches();

/// Tests: at most `blocks` blocks of each launch of passes 1 and 3 (float;
/// in double pass 3's streaming and law kernels) load their model data before
/// waiting for the previous pass; the later ones wait first, as blocks past
/// the device's first wave do (docs/cuda.md,
/// "Later waves load after their wait"); 0: every block waits first.
/// Process-wide, read when a launch is queued or a graph captured (a graph
/// captured before keeps its blocks' choice); a negative value restores the
/// device's first wave.
void set_cuda_element_first_wave(index_t blocks);

/// Tests: true runs every launch of passes 1 and 3 in the smaller blocks
/// that the backend gives a launch of several waves (docs/cuda.md, "Element
/// passes of several waves in smaller blocks"), but pass 3's streaming
/// kernel and the pass 3 beside a region check, which keep blocks of 256;
/// false restores the choice by waves. Process-wide, read when a launch is
/// queued or a graph captured.
void set_cuda_small_element_blocks(bool always);

/// Launches in those smaller blocks this process has queued, of pass 1
/// (pressures) and of pass 3 or the law kernel (forces), counted as they
/// are launched or captured into a graph (replays add nothing).
struct CudaSmallElementBlockLaunches {
  std::int64_t pressures = 0, forces = 0;
};
CudaSmallElementBlockLaunches cuda_small_element_block_launches();

/// CudaGradients (cuda/gradients.hpp) by name: "auto", "stored", "recomputed".
const char* to_string(CudaGradients g);

/// Selects where the backend's next upload() puts the gradients. Throws
/// std::invalid_argument when `backend` is not a cuda backend; upload()
/// then throws std::invalid_argument under Recomputed when an element's
/// recomputation strays beyond kGradientTolerance (naming it).
void set_cuda_gradients(Backend& backend, CudaGradients g);

/// What the element passes over the backend's current region use (Stored
/// or Recomputed; the selection before any upload).
CudaGradients cuda_gradients(Backend& backend);

}  // namespace tissue
