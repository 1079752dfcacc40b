// Runs the four IANP passes on the device, one pass at a time (the
// Backend's per-pass calls) or n whole steps (advance), in one of four ways
// that give identical results:
//   Launch   four kernel launches per step;
//   Graph    the launches of up to kMaxGraphSteps steps captured once into a
//            CUDA graph per (starting buffer phase, step count) and replayed;
//            captured lazily, dropped when the region changes;
//   Grid     one persistent cooperative kernel over all co-resident blocks,
//            grid.sync() between passes (cudaLaunchCooperativeKernel);
//   Cluster  one persistent kernel on a single thread-block cluster (up to
//            16 blocks on Hopper), cluster.sync() between passes: the
//            cheapest barrier, for regions a cluster can cover.
// Auto is Graph: on an H200 it was the fastest or within 7% of the fastest
// at every size measured, 8.6k to 4M elements, float and double
// (docs/cuda.md). Grid and Cluster stay selectable for measurement: the
// grid-wide barrier costs more than a graph's chained launch, and one
// cluster has at most 16 SMs, too few for pass 3.
#pragma once

#include <cuda_runtime.h>

#include <compare>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <utility>

#include "cuda/body_contact.hpp"
#include "cuda/cuda_backend.hpp"
#include "core/contact.hpp"
#include "cuda/device_store.hpp"
#include "cuda/launch.cuh"

namespace tissue::gpu {

/// Owns an instantiated CUDA graph; move-only.
class GraphExec {
 public:
  GraphExec() = default;
  explicit GraphExec(cudaGraphExec_t e) : e_(e) {}
  GraphExec(GraphExec&& o) noexcept : e_(std::exchange(o.e_, nullptr)) {}
  GraphExec& operator=(GraphExec&& o) noexcept {
    std::swap(e_, o.e_);
    return *this;
  }
  GraphExec(const GraphExec&) = delete;
  GraphExec& operator=(const GraphExec&) = delete;
  ~GraphExec() {
    if (e_) cudaGraphExecDestroy(e_);
  }
  cudaGraphExec_t get() const { return e_; }

 private:
  cudaGraphExec_t e_ = nullptr;
};

/// Where the first of n steps starts: at pass 1, or at pass 3 when passes
/// 1-2 at the current u are already in the state's pass arrays (the
/// reduction's, taken over by DeviceStore::swap_pressures). In a checked
/// tick (the region's reach check queued just before the steps), pass 3
/// may then run beside the check (kPass3BesideCheck: a model without law
/// terms computes its forces while the check runs; cuda/tled.cuh
/// element_forces_beside_check_kernel).
/// The work `enqueue` queues on `stream`, captured as one graph and
/// instantiated (a failure leaves no capture open). With `reuse`, an
/// instantiated graph of the same topology, that one is updated in place
/// instead (cudaGraphExecUpdate: new kernel arguments and launch sizes, at a
/// fraction of an instantiation's cost) and returned; `updated` says whether
/// it was (a topology that differs instantiates anew).
GraphExec capture_graph(cudaStream_t stream, const std::function<void(cudaStream_t)>& enqueue, GraphExec reuse = {},
                        bool* updated = nullptr);

enum class StepStart { kPass1, kPass3, kPass3BesideCheck };

/// What a cached graph holds: `steps` steps from buffer phase `phase`, with
/// or without the contact stage, alone or as a haptic tick (the backend's
/// tick graph: the tools' upload of `upload_bytes` first, the reductions and
/// their download after, led by the region check when `checked`).
struct GraphKey {
  enum Frame { kSteps, kTick, kCheckedTick };
  int phase = 0, steps = 0;
  bool contact = false;
  Frame frame = kSteps;
  std::size_t upload_bytes = 0;
  std::uintptr_t pressures = 0;  ///< the state's pass arrays (its node_p: the set a graph bakes)
  int start = 0;                 ///< where the first step starts (StepStart, as an int)
  auto operator<=>(const GraphKey&) const = default;
};

/// What the device allows for the persistent modes.
struct PersistentLimits {
  int grid_blocks = 0;   ///< co-resident blocks of the grid kernel (0: no cooperative launch)
  int cluster_size = 0;  ///< blocks of the largest schedulable cluster (0: no clusters)
  int block = 0;         ///< threads per block of the cluster kernel
  int law_grid_blocks = 0, law_cluster_size = 0;  ///< the same for the law-term kernels (core/material.hpp)
  /// The most blocks of the fused force kernel (packed_forces_kernel) the
  /// device holds at once: the chained steps fuse passes 3 and 4 on a region
  /// of at most this many windows (Stepper::fuses_forces).
  index_t fused_force_blocks = 0;
  /// Surface nodes the contact stage's merge (gather_contacts_kernel) takes
  /// in one wave of blocks of kBlock threads; a surface of more is merged in
  /// blocks of kSmallMergeBlock (Stepper::merge_block).
  index_t merge_wave_nodes = 0;
  /// Regions of more elements than this write force slots (four an
  /// element) beyond half the L2 (half_l2_bytes, the size at which pass 4
  /// drops the whole mesh's slots): pass 3 then runs its streaming kernel
  /// (element_forces_streaming_kernel; Stepper::streams_slots). 0: the
  /// precision has none (kStreamingForceBlocks).
  index_t streaming_elems = 0;
};

/// Threads per block of the merge on a surface larger than one wave of
/// blocks of kBlock: its 148 registers a thread in float (216 in double)
/// let an SM hold one block of 256, so the 100k slab's 50k surface nodes
/// took two waves (docs/cuda.md, "The merge in smaller blocks").
inline constexpr int kSmallMergeBlock = 64;

template <class T>
class Stepper {
 public:
  /// Most steps captured in one graph (a multiple of 3 keeps the phase).
  static constexpr int kMaxGraphSteps = 30;

  /// Queries the device's limits for the persistent kernels.
  void init();
  /// Drops captured graphs (the region, and so the kernel arguments,
  /// changed). They are kept aside as instantiated, so that the next capture
  /// of the same key (its pass arrays aside) updates one in place rather than
  /// instantiating anew (capture_graph).
  void invalidate();
  /// Takes `other`'s graphs as invalidate() keeps them: a stepper that
  /// replaces another on the same device (a cut's new backend) updates them
  /// in its first captures. `other` keeps none.
  void adopt_graphs(Stepper& other);

  void set_mode(CudaStepMode mode);
  /// The model's law terms (DeviceStore::law()): pass 3 runs the law kernel
  /// when it has any.
  void set_law(const LawView<T>& law) {
    law_ = law;
    invalidate();
  }
  /// Contact between bodies in every step from now on (rows 0: none); the
  /// Graph and Launch modes run it (set_mode refuses the others while it is on).
  void set_body(BodySteps<T> body) {
    if (body.rows > 0 && (mode_ == CudaStepMode::Grid || mode_ == CudaStepMode::Cluster))
      throw std::invalid_argument("cuda step mode 'grid' or 'cluster' has no contact between bodies; use auto, graph "
                                  "or launch");
    body_ = body;
    invalidate();
  }
  CudaStepMode mode() const { return mode_; }
  /// The mode advance() uses for a region of this size (Auto resolved).
  CudaStepMode choose(const RegionView& r) const;
  const PersistentLimits& limits() const { return limits_; }

  // Single passes over region r (pass 1 of a region build passes the whole mesh).
  /// `gradients_of`: the region whose size picks the element gradients
  /// (recomputes()) when it is not r: pass 1 over the whole mesh after a
  /// region build uses the region's, as its steps will.
  void element_pressure(const ModelView<T>& m, const StateView<T>& s, const RegionView& r, const Packed3<T>* u,
                        cudaStream_t stream, const RegionView* gradients_of = nullptr);
  void nodal_pressure(const ModelView<T>& m, const StateView<T>& s, const RegionView& r, cudaStream_t stream);
  /// beside_check: the first pass 3 of a checked tick (StepStart::kPass3BesideCheck).
  void element_forces(const ModelView<T>& m, const StateView<T>& s, const RegionView& r, const Packed3<T>* u,
                      cudaStream_t stream, bool beside_check = false);
  void node_update(const ModelView<T>& m, const StateView<T>& s, const RegionView& r, StepBuffers<T> b,
                   cudaStream_t stream);
  /// Whether the chained steps over region r run passes 3 and 4 as one
  /// kernel: a model without law terms (whose Prony state pass 3 moves once
  /// per element), and a region whose windows' blocks the device holds at
  /// once (PersistentLimits::fused_force_blocks). Each slot's thread
  /// computes its element's forces itself, every element once per corner:
  /// four times pass 3's arithmetic for one dependent kernel less a step,
  /// which pays only while every block runs in the first wave (docs/cuda.md,
  /// "Passes 3 and 4 as one kernel").
  bool fuses_forces(const RegionView& r) const {
    // (a group's launch: every scene's windows, launch_scenes, must fit the device at once)
    return law_.neo_hookean() && r.n_packs > 0 && index_t(launch_scenes) * r.n_packs <= limits_.fused_force_blocks;
  }
  /// Sets PersistentLimits::fused_force_blocks (tests: 0 runs passes 3 and
  /// 4 apart on every region, until the next init()).
  void set_fused_force_blocks(index_t blocks) {
    limits_.fused_force_blocks = blocks;
    graphs_.clear();
  }
  /// Sets PersistentLimits::merge_wave_nodes (tests: 0 merges every surface
  /// in blocks of kSmallMergeBlock, the same bits).
  void set_merge_wave_nodes(index_t nodes) {
    limits_.merge_wave_nodes = nodes;
    graphs_.clear();
  }
  /// Whether pass 3 over region r runs its streaming kernel
  /// (PersistentLimits::streaming_elems; Neo-Hookean models).
  bool streams_slots(const RegionView& r) const {
    return limits_.streaming_elems > 0 && r.n_elems > limits_.streaming_elems;
  }
  /// Sets PersistentLimits::streaming_elems (tests: 1 runs the streaming
  /// kernel on every region of two elements or more, in either precision;
  /// 0 never; the same bits).
  void set_streaming_elems(index_t elems) {
    limits_.streaming_elems = elems;
    graphs_.clear();
  }
  /// Threads per block of the contact stage's merge over n_surf surface
  /// nodes: kBlock while one wave of such blocks holds them all, else
  /// kSmallMergeBlock.
  int merge_block(index_t n_surf) const;
  /// Passes 3 and 4 as one kernel (fuses_forces). early: the kernel lets
  /// the next one launch as it starts; else only once its wait is over,
  /// which the steps with a contact stage ask for (the sweep follows;
  /// docs/cuda.md, "Fused passes packed by windows").
  void forces_and_update(const ModelView<T>& m, const StateView<T>& s, const RegionView& r, StepBuffers<T> b,
                         cudaStream_t stream, bool early = true);

  /// `steps` whole steps from ring's current phase; advances the phase.
  /// With `tools` (device memory: the tools' motion over these steps), each
  /// step ends with the contact stage (cuda/contact.cuh); null: none.
  void advance(const ModelView<T>& m, const StateView<T>& s, const RegionView& r, BufferRing<T>& ring, int steps,
               const ContactTools<T>* tools, StepStart start, cudaStream_t stream);

  /// Queues the kernels of `steps` whole steps from buffers b (the Graph
  /// mode's launches), for a caller's own graph; the ring's phase is the
  /// caller's to advance.
  void enqueue_steps(const ModelView<T>& m, const StateView<T>& s, const RegionView& r, StepBuffers<T> b, int steps,
                     const ContactTools<T>* tools, StepStart start, cudaStream_t stream) {
    launch_steps(m, s, r, b, steps, tools, start, stream);
  }

  /// GraphKey::pressures of state view s.
  static std::uintptr_t pressures_of(const StateView<T>& s) { return reinterpret_cast<std::uintptr_t>(s.node_p); }

  /// The graph cached under `key`, captured on first use from what
  /// `enqueue` queues on the stream; dropped with the others (invalidate).
  cudaGraphExec_t cached_graph(const GraphKey& key, const std::function<void(cudaStream_t)>& enqueue,
                               cudaStream_t stream);
  /// How many graphs cached_graph captured so far, and how many of those
  /// updated a kept graph in place rather than instantiating one.
  long captures() const { return captures_; }
  long updates() const { return updates_; }

 private:
  void launch_steps(const ModelView<T>& m, const StateView<T>& s, const RegionView& r, StepBuffers<T> b, int steps,
                    const ContactTools<T>* tools, StepStart start, cudaStream_t stream);
  cudaGraphExec_t graph(const ModelView<T>& m, const StateView<T>& s, const RegionView& r, BufferRing<T>& ring,
                        int steps, const ContactTools<T>* tools, StepStart start, cudaStream_t stream);

  CudaStepMode mode_ = CudaStepMode::Auto;
  long captures_ = 0;
  long updates_ = 0;
  /// Most graphs kept aside for updates (invalidate): a handful of keys are in use at a time.
  static constexpr std::size_t kMaxKept = 64;
  PersistentLimits limits_;
  LawView<T> law_;
  BodySteps<T> body_;  ///< contact between bodies (rows 0: none)
  /// the tools' buffer is the backend's one device array
  std::map<GraphKey, GraphExec> graphs_;
  /// Dropped graphs under their key with `pressures` 0, to be updated in place (invalidate).
  std::multimap<GraphKey, GraphExec> kept_;
};

}  // namespace tissue::gpu
