// The cuda backend: the Backend interface over the device store, as a list
// of stages, each one kernel module (stepper with the contact stage,
// region_fill, contact, reduce).
// Semantics are the cpu backend's (cpu/constraints.hpp states the rule):
//   held (an axis mask per node) = fixed axes | driven axes, every axis
//   for a halo node; a fixed component is always held at 0 (also when
//   driven); a halo node is held (and stopped) at its displacement when the
//   region was built; a node leaving the region is frozen
//   (u_prev = u_next = u, f = 0), elements leaving it get zero forces; after
//   a region build or set_displacements pass 1 is recomputed over all
//   elements, so pass 2 averages valid p_e V_e on halo nodes too.
// Per haptic tick (one graph: do_advance_reduce) the only copies are the
// tools' motion (up: the head of ContactTools and one ToolStep per tool) and
// the Reductions struct (down), plus, while the region is not the whole
// mesh, the region check's answer (down); see transfers() and docs/cuda.md.
#include "cuda/cuda_backend.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "cuda/body_contact.hpp"
#include "cuda/contact.hpp"
#include "cuda/device_store.hpp"
#include "cuda/launch.cuh"
#include "cuda/reduce.hpp"
#include "cuda/region_fill.hpp"
#include "core/node_rules.hpp"
#include "core/step_guard.hpp"
#include "cuda/stepper.hpp"
#include "cuda/text.hpp"

namespace tissue {
namespace gpu {
namespace {

/// Releases driven nodes (cpu/constraints.hpp's rule): a released halo node
/// is held (every component) at its current u, any other keeps only its
/// fixed components (whose targets are 0).
template <class T>
__global__ void undrive_kernel(index_t n, const index_t* list, const std::uint8_t* flags, StateView<T> s,
                               const Packed3<T>* u) {
  const index_t i = thread_index();
  if (i >= n) return;
  const index_t a = list[i];
  const std::uint8_t fixed = fixed_axes(flags[a]);
  s.driven[a] = 0;
  if (s.role[a] == kHalo) {
    s.u_held[a] = Packed3<T>::of(halo_target(fixed, std::uint8_t(0), u[a].vec(), s.u_held[a].vec()));
    s.held[a] = kAllAxes;
  } else {
    s.held[a] = fixed;
  }
}

/// Roles of the given nodes (the region check of set_driven).
__global__ void probe_roles_kernel(index_t n, const index_t* nodes, const std::uint8_t* role, std::uint8_t* out) {
  const index_t i = thread_index();
  if (i < n) out[i] = role[nodes[i]];
}

/// Drives node ids[i] in the components of masks[i] to values[3 i + c]
/// (ids unique); a fixed component stays at 0 even under the tool.
template <class T>
__global__ void drive_kernel(index_t n, const T* values, const index_t* ids, const std::uint8_t* masks,
                             const std::uint8_t* flags, index_t* list, StateView<T> s) {
  const index_t i = thread_index();
  if (i >= n) return;
  const index_t a = ids[i];
  const std::uint8_t mask = masks[i], fixed = fixed_axes(flags[a]);
  list[i] = a;
  s.driven[a] |= mask;
  s.held[a] |= mask;
  Packed3<T> held_at = s.u_held[a];
  const std::uint8_t set = mask & ~fixed;
  if (set & 1) held_at.x = values[3 * i];
  if (set & 2) held_at.y = values[3 * i + 1];
  if (set & 4) held_at.z = values[3 * i + 2];
  s.u_held[a] = held_at;
}

/// u^n = u^{n+1} = src, u^{n-1} = src + 3 n (src: two 3 x n component-major
/// arrays, double); halo nodes are held at the new u in their components
/// that are neither driven nor fixed.
template <class T>
__global__ void set_motion_kernel(index_t n, const double* src, const std::uint8_t* flags, StateView<T> s,
                                  StepBuffers<T> b) {
  const index_t a = thread_index();
  if (a >= n) return;
  const Packed3<T> u = {T(src[a]), T(src[n + a]), T(src[2 * n + a]), T(0)};
  const double* prev = src + 3 * std::size_t(n);
  b.u_prev[a] = {T(prev[a]), T(prev[n + a]), T(prev[2 * n + a]), T(0)};
  b.u[a] = u;
  b.u_next[a] = u;
  if (s.role[a] == kHalo) {  // held at the new u, except driven and fixed components
    const std::uint8_t keep = s.driven[a] | fixed_axes(flags[a]);
    Packed3<T> held_at = s.u_held[a];
    if (!(keep & 1)) held_at.x = u.x;
    if (!(keep & 2)) held_at.y = u.y;
    if (!(keep & 4)) held_at.z = u.z;
    s.u_held[a] = held_at;
  }
}

/// Fields in double into dst: u (3 x n), node_p (n), f (3 x n), elem_J (ne).
template <class T>
__global__ void download_kernel(ModelView<T> m, StateView<T> s, const Packed3<T>* u, double* dst) {
  const index_t i = thread_index();
  const index_t n = m.n_nodes;
  if (i < n) {
    const Packed3<T> ui = u[i], fi = s.f[i];
    dst[i] = ui.x;
    dst[n + i] = ui.y;
    dst[2 * n + i] = ui.z;
    dst[3 * n + i] = s.node_p[i];
    dst[4 * n + i] = fi.x;
    dst[5 * n + i] = fi.y;
    dst[6 * n + i] = fi.z;
  }
  if (i < m.n_elems) dst[7 * n + i] = s.elem_J[i];
}

template <class T>
__global__ void positions_kernel(index_t n, const Packed3<T>* X, const Packed3<T>* u, float* dst) {
  const index_t a = thread_index();
  if (a >= n) return;
  const Packed3<T> x = X[a], d = u[a];
  dst[3 * a] = static_cast<float>(x.x + d.x);
  dst[3 * a + 1] = static_cast<float>(x.y + d.y);
  dst[3 * a + 2] = static_cast<float>(x.z + d.z);
}

std::string current_device_name() {
  int dev = 0;
  CUDA_CHECK(cudaGetDevice(&dev));
  cudaDeviceProp p;
  CUDA_CHECK(cudaGetDeviceProperties(&p, dev));
  return str(p.name, " (sm_", p.major, p.minor, ", ", p.multiProcessorCount, " SMs, ",
             (p.totalGlobalMem + (size_t(1) << 29)) >> 30, " GiB)");
}

template <class T>
class CudaBackend;

/// What a group tick's graph depends on: scenes whose ticks agree in it run
/// in one graph (their buffers at one phase, their pass arrays in one set).
struct GroupTickKey {
  int phase = 0, steps = 0, start = 0, pressures = 0;
  int load = 0;                ///< 1: the scene has a load (the node update's variant)
  std::size_t tool_bytes = 0;  ///< 0: no tool
  auto operator<=>(const GroupTickKey&) const = default;
};

/// Scenes of one mesh and one step stepped as one (BackendGroup;
/// docs/batch.md, "One launch per pass"); their materials may differ. Each
/// scene's backend allocates its arrays in its slot of the group's arena
/// (SceneArena), so that scene k's arrays are those of any other member
/// moved by whole slots. A tick: each scene stages its
/// tools' motion in the group's pinned array and its graph key (start);
/// launch() then runs, per key, one graph captured from one member with
/// every kernel over all slots (gridDim.y; the kernels move their
/// per-scene arrays, cuda/views.hpp SceneSlots): the tools' copy, the
/// slots' skip flags (non-zero for a slot not in this key's tick), the
/// steps, the reduction, and the copy of every slot's Reductions into the
/// group's pinned array. Graphs are cached per key.
template <class T>
class SceneGroup final : public BackendGroup {
 public:
  SceneGroup(int slots, std::size_t slot_bytes)
      : arena_(slots, slot_bytes), members_(slots, nullptr), started_(slots, 0), ran_(slots, 0), keys_(slots) {
    tools_dev_.allocate(slots);
    tools_host_.allocate(slots);
    for (int k = 0; k < slots; ++k) tools_host_[k] = ContactTools<T>{};
    results_host_.allocate(slots);
  }
  ~SceneGroup() override { cudaStreamSynchronize(stream_.get()); }

  const SceneArena& arena() const { return arena_; }
  int slots() const { return arena_.slots(); }
  char* slot(int k) const { return arena_.slot(k); }

  void join(CudaBackend<T>* b, int k) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (members_.at(k) && members_[k] != b)
      throw std::logic_error(str("cuda scene group: slot ", k, " already has a scene"));
    members_[k] = b;
  }
  void leave(int k) {
    std::lock_guard<std::mutex> lock(mutex_);
    members_.at(k) = nullptr;
    started_[k] = ran_[k] = 0;
  }

  /// Whether `offsets` (a member's arrays from its slot's start) are the
  /// group's layout; the first member to ask sets it.
  bool same_layout(const std::vector<std::ptrdiff_t>& offsets) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (layout_.empty()) layout_ = offsets;
    return layout_ == offsets;
  }

  /// Scene k's tick, to run at the next launch().
  void start(int k, const GroupTickKey& key, const ContactTools<double>& tools) {
    if (key.tool_bytes > 0) tools_host_[k] = contact_tools_as<T>(tools);
    std::lock_guard<std::mutex> lock(mutex_);
    keys_[k] = key;
    started_[k] = 1;
  }

  void launch() override;

  /// Scene k's Reductions of the tick it started (launched now if no one has).
  Reductions finish(int k) {
    if (!ran_[k]) launch();
    ran_[k] = 0;
    return results_host_[k];
  }

  /// Slot k's entry of the tools' array (what its steps read in a group tick).
  const ContactTools<T>* device_tools(int k) const { return tools_dev_.data() + k; }

  void count_alone() { ticks_alone_.fetch_add(1, std::memory_order_relaxed); }
  std::int64_t ticks_together() const override { return ticks_together_.load(); }
  std::int64_t ticks_alone() const override { return ticks_alone_.load(); }

 private:
  struct Graph {
    GraphExec exec;
    DeviceArray<int> skip_dev;
    PinnedArray<int> skip_host;
  };
  Graph& graph(const GroupTickKey& key, int rep);

  SceneArena arena_;
  std::vector<CudaBackend<T>*> members_;
  std::vector<char> started_, ran_;
  std::vector<GroupTickKey> keys_;
  std::vector<std::ptrdiff_t> layout_;
  DeviceArray<ContactTools<T>> tools_dev_;   ///< one entry a slot
  PinnedArray<ContactTools<T>> tools_host_;  ///< its staging
  PinnedArray<Reductions> results_host_;     ///< one entry a slot
  std::map<GroupTickKey, std::unique_ptr<Graph>> graphs_;
  Stream stream_;
  std::mutex mutex_;
  std::atomic<std::int64_t> ticks_together_{0}, ticks_alone_{0};
};

template <class T>
class CudaBackend final : public Backend {
 public:
  /// Needs a usable device (make_cuda_backend checks first).
  CudaBackend() {
    device_name_ = current_device_name();
    stepper_.init();
  }
  ~CudaBackend() override {
    if (group_) group_->leave(slot_);
  }

  /// Makes this backend scene `slot` of `group`: its arrays go to that slot
  /// from its next upload, and its ticks run with the group's where they can.
  void join(std::shared_ptr<SceneGroup<T>> group, int slot) {
    group->join(this, slot);
    if (group_) group_->leave(slot_);
    group_ = std::move(group);
    slot_ = slot;
    in_group_layout_ = false;  // until its next upload, into the slot
  }

  /// Queues a group tick of `key` captured from this scene (SceneGroup::graph):
  /// the steps and the reduction over every slot, as tick_graph queues them.
  void enqueue_group_tick(const GroupTickKey& key, const SceneSlots& slots, const int* skip,
                          const ContactTools<T>* tools, cudaStream_t st) {
    const RegionView r = region_.view();
    StateView<T> s = store_.state();
    s.slots = slots;
    s.skip = skip;
    StateView<T> scratch = store_.pressure_scratch();
    scratch.slots = slots;
    scratch.skip = skip;
    stepper_.enqueue_steps(store_.model(), s, r, store_.u.current(), key.steps, tools,
                           static_cast<StepStart>(key.start), st);
    reducer_.enqueue(store_.model(), s, scratch, r, region_.front(), store_.u.at(store_.u.phase + key.steps), tools,
                     st, false);
  }
  const Reductions* result_device() const { return reducer_.result(); }

  /// The current displacement (which 0) or the internal force (1) where they lie.
  CudaNodeField node_field(int which) {
    int dev = 0;
    CUDA_CHECK(cudaGetDevice(&dev));
    const void* p = which == 0 ? static_cast<const void*>(store_.u.current().u) : static_cast<const void*>(store_.state().f);
    return {p, store_.n_nodes(), static_cast<std::int64_t>(sizeof(Packed3<T>)), static_cast<int>(sizeof(T)), dev};
  }

  std::string name() const override { return "cuda"; }
  Precision precision() const override { return sizeof(T) == 4 ? Precision::Float : Precision::Double; }
  std::string device_name() const override { return device_name_; }
  bool positions_on_device() const override { return true; }
  bool asynchronous_ticks() const override { return true; }
  TransferCounters transfers() const override { return log_.counters(); }
  DeviceMemory device_memory() const override {
    std::size_t free = 0, total = 0;
    CUDA_CHECK(cudaMemGetInfo(&free, &total));
    return {static_cast<std::int64_t>(device_bytes_held()), static_cast<std::int64_t>(free),
            static_cast<std::int64_t>(total)};
  }

  Stepper<T>& stepper() { return stepper_; }
  /// The selection for the next upload; once a model is uploaded, what the
  /// element passes over the current region use (Stored or Recomputed).
  void set_gradients(CudaGradients g) { gradients_ = g; }
  CudaGradients gradients() const {
    if (store_.n_elems() == 0) return gradients_;
    return recomputes(store_.model(), region_view()) ? CudaGradients::Recomputed : CudaGradients::Stored;
  }
  RegionView region_view() const { return region_.view(); }
  /// ModelView::lanes_node_min of the uploaded model, and its override.
  index_t lanes_node_min() const { return store_.model().lanes_node_min; }
  bool discard_slots() const { return store_.model().discard_slots; }
  void set_discard_slots(bool discard) {
    store_.set_discard_slots(discard);
    stepper_.invalidate();  // the graphs bake the model view
  }
  void set_lanes_node_min(index_t nodes) {
    store_.set_lanes_node_min(nodes);
    stepper_.invalidate();  // the graphs bake the node kernels
  }

 protected:
  void do_upload(const TissueModel<double>& model) override {
    try {
      std::optional<SceneArena::SlotScope> in_slot;  // a group's scene: its arrays in its slot
      if (group_) in_slot.emplace(group_->arena(), slot_);
      upload_arrays(model);
    } catch (const OutOfDeviceMemory& e) {
      throw OutOfDeviceMemory("cuda backend: the model (" + std::to_string(model.n_nodes) + " nodes, " +
                              std::to_string(model.n_elems) + " tets, " + (sizeof(T) == 4 ? "float" : "double") +
                              ") does not fit in GPU memory: " + e.what() +
                              "; use a coarser mesh, precision float, or --backend cpu");
    }
  }

  void upload_arrays(const TissueModel<double>& model) {
    const TissueModel<T> m = convert<T>(model);
    store_.set_reserve_load(group_ != nullptr);
    store_.upload(m, model, gradients_, log_, stream());
    const index_t n = m.n_nodes;
    region_.allocate(n, m.n_elems, store_.model().n_windows, stream());
    reducer_.allocate(stream());
    reducer_.set_law(store_.law());
    stepper_.set_law(store_.law());
    contact_.allocate(n, m.n_surf);
    body_.clear();
    stepper_.set_body({});
    surface_ = {};  // what the bodies' lists are built from: the surface and the reference positions
    surface_.n_nodes = model.n_nodes;
    surface_.n_tris = model.n_tris;
    surface_.n_surf = model.n_surf;
    surface_.X = model.X;
    surface_.tris = model.tris;
    surface_.surf_nodes = model.surf_nodes;
    surface_.node_flags = model.node_flags;  // a face on a symmetry plane is no candidate
    reduce_tools_ = nullptr;
    driven_list_.allocate(n);
    drive_dev_.allocate(n * (3 * sizeof(T) + sizeof(index_t) + 1));
    if (drive_pending_) drive_copied_.sync();  // before its staging is freed
    drive_pending_ = false;
    drive_host_.allocate(drive_dev_.size());
    scratch_.allocate(7 * size_t(n) + m.n_elems);
    probe_dev_.allocate(n);
    probe_host_.allocate(n);
    n_driven_ = 0;
    do_build_region({}, kDepthAll);
    in_group_layout_ = group_ && store_.pressure_set() == 0 && slot_layout_matches();
    stream_.sync();
  }

  void do_set_masses(const NodeMasses& k) override {
    TissueModel<T> m;
    m.mass.assign(k.mass.begin(), k.mass.end());
    m.cd_A.assign(k.cd_A.begin(), k.cd_A.end());
    m.cd_B.assign(k.cd_B.begin(), k.cd_B.end());
    m.cd_C.assign(k.cd_C.begin(), k.cd_C.end());
    store_.set_masses(m, log_, stream());
  }

  void do_set_motion(std::span<const double> u, std::span<const double> u_prev) override {
    const index_t n = store_.n_nodes();
    log_.to_device_now(scratch_.data(), u.data(), u.size_bytes(), stream());
    log_.to_device_now(scratch_.data() + u.size(), u_prev.data(), u_prev.size_bytes(), stream());
    launch(n, stream(), set_motion_kernel<T>, n, scratch_.data(), store_.model().node_flags, store_.state(),
           store_.u.current());
    store_.clear_law_state(stream());  // a new initial state: no Prony history
    if (body_.active()) body_.rebuild(surface_, positions(), log_, stream());  // the lists at the new motion
    body_.clear_anchors(stream());
    pass1_all();
  }

  RegionSizes do_build_region(std::span<const index_t> seeds, int depth) override {
    const Topology topo = topology(store_.model());
    StateView<T> s = store_.state();
    const RegionSizes sizes = depth == kDepthAll ? region_.whole(topo, s.role, stream())
                                                 : region_.build(topo, seeds, depth, s.role, log_, stream());
    seeds_.assign(seeds.begin(), seeds.end());
    region_.apply(store_.model(), s, store_.u.current(), stream());
    pass1_all();
    stepper_.invalidate();
    return sizes;
  }

  Region do_region() override {
    return region_.download(topology(store_.model()), store_.state().role, seeds_, log_, stream());
  }

  /// One small download of the nodes' roles (none when they are all seeds,
  /// which are inner nodes: the Scheduler's case).
  std::vector<std::uint8_t> do_roles(std::span<const index_t> nodes) override {
    std::vector<std::uint8_t> roles(nodes.size(), kInner);
    if (region_.sizes().whole() || nodes.empty()) return roles;
    bool all_seeds = true;
    for (index_t a : nodes) all_seeds = all_seeds && std::find(seeds_.begin(), seeds_.end(), a) != seeds_.end();
    if (all_seeds) return roles;
    const index_t n = static_cast<index_t>(nodes.size());
    log_.to_device_now(scratch_.data(), nodes.data(), nodes.size_bytes(), stream());
    launch(n, stream(), probe_roles_kernel, n, reinterpret_cast<const index_t*>(scratch_.data()), store_.state().role,
           probe_dev_.data());
    log_.to_host(probe_host_.data(), probe_dev_.data(), n, stream());
    for (index_t k = 0; k < n; ++k) roles[k] = probe_host_[k];
    return roles;
  }

  /// One upload per call (targets, ids and axis masks in one pinned block).
  void do_set_driven(std::span<const index_t> nodes, std::span<const double> u,
                     std::span<const std::uint8_t> axes) override {
    if (drive_pending_) drive_copied_.sync();  // the staging buffer is free again
    const auto n = static_cast<index_t>(nodes.size());
    T* values = reinterpret_cast<T*>(drive_host_.data());
    index_t* ids = reinterpret_cast<index_t*>(values + 3 * size_t(n));
    std::uint8_t* masks = reinterpret_cast<std::uint8_t*>(ids + n);
    for (index_t k = 0; k < n; ++k) {
      ids[k] = nodes[k];
      masks[k] = axes[k];
      for (int c = 0; c < 3; ++c) values[3 * k + c] = static_cast<T>(u[3 * k + c]);
    }
    const T* dvalues = reinterpret_cast<const T*>(drive_dev_.data());
    const index_t* dids = reinterpret_cast<const index_t*>(dvalues + 3 * size_t(n));
    const std::uint8_t* dmasks = reinterpret_cast<const std::uint8_t*>(dids + n);
    log_.to_device(drive_dev_.data(), drive_host_.data(), n * (3 * sizeof(T) + sizeof(index_t) + 1), stream());
    drive_copied_.record(stream());
    drive_pending_ = true;
    do_clear_driven();
    launch(n, stream(), drive_kernel<T>, n, dvalues, dids, dmasks, store_.model().node_flags, driven_list_.data(),
           store_.state());
    n_driven_ = n;
  }

  void do_clear_driven() override {
    launch(n_driven_, stream(), undrive_kernel<T>, n_driven_, driven_list_.data(), store_.model().node_flags,
           store_.state(), store_.u.current().u);
    n_driven_ = 0;
  }

  /// The load is in the StateView the captured graphs hold: they are made again.
  void do_set_loads(std::span<const double> load) override {
    stepper_.invalidate();  // first: no graph may keep the old array if the new one fails to allocate
    store_.set_load(load, log_, stream());
  }

  void do_begin_grasp(int tool, const ToolPose& pose) override {
    contact_.begin_grasp(store_.model(), store_.state(), store_.u.current().u, tool, pose.tip, stream());
  }
  void do_end_grasp(int tool) override { contact_.end_grasp(store_.model(), store_.state(), tool, stream()); }
  void do_reset_contacts() override { contact_.reset(store_.model(), store_.state(), stream()); }

  void do_element_pressure() override {
    pressures_fresh_ = false;  // a caller running the passes one by one
    stepper_.element_pressure(store_.model(), store_.state(), region_.view(), store_.u.current().u, stream());
  }
  void do_nodal_pressure() override {
    pressures_fresh_ = false;
    stepper_.nodal_pressure(store_.model(), store_.state(), region_.view(), stream());
  }
  void do_element_forces() override {
    stepper_.element_forces(store_.model(), store_.state(), region_.view(), store_.u.current().u, stream());
  }
  void do_node_update() override {
    pressures_fresh_ = false;  // u moves
    stepper_.node_update(store_.model(), store_.state(), region_.view(), store_.u.current(), stream());
    store_.u.advance(1);
  }

  /// Steps in chunks of at most the stepper's graph length; each chunk's
  /// slice of the tools' motion is one small upload.
  void do_advance(int steps, const ContactTools<double>& tools) override {
    refresh_body();
    const int chunk = Stepper<T>::kMaxGraphSteps;
    StepStart start = take_pressures();
    for (int done = 0; done < steps;) {
      const int k = std::min(chunk, steps - done);
      const ContactTools<T>* dtools = nullptr;
      if (tools.n_tools > 0) dtools = contact_.upload(contact_tools_as<T>(slice(tools, done, k)), log_, stream());
      stepper_.advance(store_.model(), store_.state(), region_.view(), store_.u, k, dtools, start, stream());
      start = StepStart::kPass1;
      done += k;
      reduce_tools_ = dtools;
    }
  }

  /// The haptic tick's work as one graph (Graph mode, the usual case): the
  /// tools' upload, the steps with their contact stage, the reductions and
  /// their download, then one wait. Kernels and order are advance()'s and
  /// reduce()'s, so the results are the same bits. A tick of more steps than
  /// one graph holds, and the other modes, run the two calls (do_advance cuts
  /// the tools' motion into its chunks from the first step).
  Reductions do_advance_reduce(int steps, const ContactTools<double>& tools) override {
    if (!tick_graph_runs(steps)) return Backend::do_advance_reduce(steps, tools);
    return *tick_graph(steps, tools, false);
  }

  /// The same graph, led by the candidates' test (DeviceContact::enqueue_reach_check):
  /// when the motion reaches beyond the region, every later kernel of the
  /// graph does nothing (StateView::skip) and the answer says so. It replaces
  /// the candidates' query and its round trip before each tick of a limited region.
  std::optional<Reductions> do_advance_reduce_in_region(int steps, const ContactTools<double>& tools) override {
    if (!tick_graph_runs(steps) || store_.model().n_surf == 0) return Backend::do_advance_reduce_in_region(steps, tools);
    return tick_graph(steps, tools, true);
  }

  std::vector<index_t> do_contact_candidates(const ContactTools<double>& sweep) override {
    return contact_.candidates(store_.model(), store_.state(), store_.u.current().u, contact_tools_as<T>(sweep),
                               log_, stream());
  }

  std::vector<ContactNode> do_contacts() override { return contact_.contacts(store_.model(), store_.state(), log_, stream()); }

  Reductions do_reduce() override {
    const bool passes = prepare_reduction(region_.view());
    const Reductions out = reducer_.run(store_.model(), store_.state(), store_.pressure_scratch(), region_.view(),
                                        region_.front(), store_.u.current(), reduce_tools_, log_, stream());
    pressures_fresh_ = passes;
    return out;
  }

  Fields do_download() override {
    const index_t n = store_.n_nodes(), ne = store_.n_elems();
    launch(std::max(n, ne), stream(), download_kernel<T>, store_.model(), store_.state(), store_.u.current().u,
           scratch_.data());
    std::vector<double> all(scratch_.size());
    log_.to_host(all.data(), scratch_.data(), scratch_.bytes(), stream());
    Fields f;
    const auto at = [&](size_t k) { return all.begin() + k * n; };
    f.u.assign(at(0), at(3));
    f.node_p.assign(at(3), at(4));
    f.f.assign(at(4), at(7));
    f.elem_J.assign(at(7), at(7) + ne);
    return f;
  }

  /// Downloads u only (the pattern of do_previous_displacements), not the whole state.
  std::vector<double> do_deformed_altitudes(const TissueModel<double>& model, std::span<const index_t> elems) override {
    const index_t n = store_.n_nodes(), ne = store_.n_elems();
    launch(std::max(n, ne), stream(), download_kernel<T>, store_.model(), store_.state(), store_.u.current().u,
           scratch_.data());
    std::vector<double> u(3 * std::size_t(n));
    log_.to_host(u.data(), scratch_.data(), u.size() * sizeof(double), stream());
    std::vector<double> out(elems.size());
    for (std::size_t k = 0; k < elems.size(); ++k) out[k] = deformed_altitude(model, std::span<const double>(u), elems[k]);
    return out;
  }

  std::vector<double> do_previous_displacements() override {
    const index_t n = store_.n_nodes(), ne = store_.n_elems();
    launch(std::max(n, ne), stream(), download_kernel<T>, store_.model(), store_.state(), store_.u.current().u_prev,
           scratch_.data());
    std::vector<double> u_prev(3 * std::size_t(n));
    log_.to_host(u_prev.data(), scratch_.data(), u_prev.size() * sizeof(double), stream());
    return u_prev;
  }

  void do_write_positions(float* dst) override {
    cudaPointerAttributes attr;
    if (cudaPointerGetAttributes(&attr, dst) != cudaSuccess ||
        (attr.type != cudaMemoryTypeDevice && attr.type != cudaMemoryTypeManaged)) {
      cudaGetLastError();
      throw std::invalid_argument("write_positions: the cuda backend writes device memory: dst must be device "
                                  "memory (n_nodes x 3 floats), e.g. a mapped GL buffer");
    }
    const index_t n = store_.n_nodes();
    launch(n, stream(), positions_kernel<T>, n, store_.model().X, store_.u.current().u, dst);
    stream_.sync();  // the caller (a GL interop unmap) may use dst right away
  }

  void do_set_body_contact(const BodyContactSpec& spec) override {
    if (spec.empty()) {
      body_.clear();
      stepper_.set_body({});
      return;
    }
    if (stepper_.mode() == CudaStepMode::Grid || stepper_.mode() == CudaStepMode::Cluster)
      stepper_.set_body({nullptr, 1});  // (refuses, naming the modes)
    body_.set(surface_, spec, positions(), log_, stream());
    stepper_.set_body(body_.steps());
  }
  std::vector<BodyContactNode> do_body_contacts() override { return body_.contacts(log_, stream()); }

 public:
  long body_list_builds() const override { return body_.builds(); }
  long graph_captures() const override { return stepper_.captures(); }
  long graph_updates() const override { return stepper_.updates(); }
  void adopt_graphs(Backend& from) override {
    if (auto* other = dynamic_cast<CudaBackend*>(&from)) stepper_.adopt_graphs(other->stepper_);
  }

 private:
  cudaStream_t stream() const { return stream_.get(); }

  /// X + u of every node, xyz (downloads u).
  std::vector<double> positions() {
    const Fields f = do_download();
    const index_t n = surface_.n_nodes;
    std::vector<double> x(3 * std::size_t(n));
    for (index_t a = 0; a < n; ++a)
      for (int c = 0; c < 3; ++c) x[3 * size_t(a) + c] = surface_.X[c * size_t(n) + a] + f.u[c * size_t(n) + a];
    return x;
  }

  /// Before steps: rebuilds the bodies' lists when the last steps flagged a
  /// node beyond their reach (the flag is read once the stream is done).
  void refresh_body() {
    if (!body_.active()) return;
    stream_.sync();
    if (body_.stale()) body_.rebuild(surface_, positions(), log_, stream());
  }

  /// Whether a tick of `steps` steps runs as one graph: the Graph mode,
  /// something moves, and one graph holds the steps.
  bool tick_graph_runs(int steps) const {
    const RegionView r = region_.view();
    return stepper_.choose(r) == CudaStepMode::Graph && (r.n_elems > 0 || r.n_nodes > 0 || n_tools() > 0) &&
           steps <= Stepper<T>::kMaxGraphSteps;
  }

  /// One tick graph of `steps` (<= kMaxGraphSteps) steps over `tools`,
  /// cached per buffer phase, step count, upload size, check, pass-array set
  /// and start (GraphKey); with
  /// `check`, led by the region's reach check: empty when the region must
  /// grow first (nothing ran).
  std::optional<Reductions> tick_graph(int steps, const ContactTools<double>& tools, bool check) {
    launch_tick_graph(steps, tools, check);
    return finish_tick_graph();
  }

  /// A launched tick graph that finish_tick_graph has not yet waited for.
  struct LaunchedTick {
    bool launched = false;
    bool check = false;
    int steps = 0;
    std::size_t tool_bytes = 0;
    StepStart start = StepStart::kPass1;
    bool passes = false;
    bool group = false;  ///< staged in the scene group (start_group_tick)
  };

  /// tick_graph's first half: stages the tools, launches the graph on the
  /// backend's stream and returns without waiting.
  void launch_tick_graph(int steps, const ContactTools<double>& tools, bool check) {
    refresh_body();
    const RegionView r = region_.view();
    const std::size_t tool_bytes = tools.n_tools > 0 ? contact_.stage(contact_tools_as<T>(tools)) : 0;
    const ContactTools<T>* dtools = tools.n_tools > 0 ? contact_.device_tools() : nullptr;
    check = check && dtools != nullptr;
    const StepStart start = take_pressures();
    // a checked tick's first pass 3 runs beside the check (cuda/tled.cuh element_forces_beside_check_kernel)
    const StepStart steps_start = check && start == StepStart::kPass3 ? StepStart::kPass3BesideCheck : start;
    const bool passes = prepare_reduction(r);  // (its copy before the graph, on its stream)
    const GraphKey key{store_.u.phase, steps, dtools != nullptr, check ? GraphKey::kCheckedTick : GraphKey::kTick,
                       tool_bytes, Stepper<T>::pressures_of(store_.state()), static_cast<int>(steps_start)};
    const cudaGraphExec_t exec = stepper_.cached_graph(
        key,
        [&](cudaStream_t st) {
          StateView<T> s = store_.state();
          if (tool_bytes > 0) contact_.enqueue_copy(tool_bytes, st);
          if (check) {
            contact_.enqueue_reach_check(store_.model(), s, store_.u.current().u, st);
            s.skip = contact_.reach();
          }
          StateView<T> scratch = store_.pressure_scratch();
          scratch.skip = s.skip;
          stepper_.enqueue_steps(store_.model(), s, r, store_.u.current(), steps, dtools, steps_start, st);
          // the reduction and the check write their answers into mapped host memory themselves: the
          // graph has no copy nodes, and its answers are read once the stream is done
          reducer_.enqueue(store_.model(), s, scratch, r, region_.front(), store_.u.at(store_.u.phase + steps), dtools,
                           st, true);
        },
        stream());
    if (check) contact_.reach_host()[0] = 0;  // the check kernel writes 1 when the region must grow
    CUDA_CHECK(cudaGraphLaunch(exec, stream()));
    reduce_tools_ = dtools;
    launched_ = {true, check, steps, tool_bytes, start, passes};
  }

  /// tick_graph's second half: waits for the launched graph and reads its answers.
  std::optional<Reductions> finish_tick_graph() {
    const LaunchedTick t = launched_;
    launched_ = {};
    stream_.sync();
    if (t.tool_bytes > 0) log_.count_to_device(t.tool_bytes);
    if (t.check) {
      log_.count_to_host(sizeof(int));
      if (contact_.reach_host()[0] != 0) {  // nothing ran: the same phase, the same state
        if (t.start == StepStart::kPass3) {  // and the same pass arrays (download() sees no change)
          store_.swap_pressures();
          pressures_fresh_ = true;
        }
        return std::nullopt;
      }
    }
    pressures_fresh_ = t.passes;
    log_.count_to_host(sizeof(Reductions));  // (a tick that did nothing wrote none)
    store_.u.advance(t.steps);
    return reducer_.result_host()[0];
  }

  /// Starts the tick as one graph on this backend's stream (a batch's
  /// scenes then run side by side) where tick_graph would run it; otherwise
  /// runs it now (Backend's default).
  void do_start_tick(int steps, const ContactTools<double>& tools, bool in_region) override {
    if (group_ && !in_region && group_takes(steps)) {
      start_group_tick(steps, tools);
      return;
    }
    if (group_) group_->count_alone();
    if (tick_graph_runs(steps) && !(in_region && store_.model().n_surf == 0))
      launch_tick_graph(steps, tools, in_region);
    else
      Backend::do_start_tick(steps, tools, in_region);
  }

  std::optional<Reductions> do_finish_tick() override {
    if (launched_.group) return finish_group_tick();
    return launched_.launched ? finish_tick_graph() : Backend::do_finish_tick();
  }

  /// Whether the group can run this scene's tick of `steps` steps with
  /// others: a tick graph over the whole mesh and its arrays in its slot
  /// at the group's layout (checked at upload). A scene with a load and one
  /// without run in graphs of different keys.
  bool group_takes(int steps) {
    const RegionView r = region_.view();
    return in_group_layout_ && tick_graph_runs(steps) && !r.nodes && !r.elems && !body_.active();
  }

  /// Whether every array a group tick's kernels touch per scene (the state,
  /// the buffers, the reduction's, the model's that follow its material, the
  /// law terms')
  /// lies in this scene's slot at the group's layout (the first member's
  /// offsets). Those arrays change only at an upload, where this is asked.
  bool slot_layout_matches() {
    std::vector<std::ptrdiff_t> offsets;
    const char* base = group_->slot(slot_);
    const auto add = [&](const void* p) {
      const std::ptrdiff_t d = static_cast<const char*>(p) - base;
      offsets.push_back(p && d >= 0 && std::size_t(d) < group_->arena().stride() ? d : -1);
    };
    // the state's arrays (core/store.hpp's lists: what StateView::moved moves), both pass-array sets
#define TISSUE_STATE_OFFSET(name, ...) add(v.name);
    for (const StateView<T>& v : {store_.state(), store_.pressure_scratch()}) {  // (set 0 first: just uploaded)
      TISSUE_STATE_ARRAYS(TISSUE_STATE_OFFSET)
      TISSUE_PASS_ARRAYS(TISSUE_STATE_OFFSET)
      TISSUE_DEVICE_STATE_ARRAYS(TISSUE_STATE_OFFSET)
    }
#undef TISSUE_STATE_OFFSET
    for (auto& b : store_.u.buf) add(b.data());
    const ModelView<T>& m = store_.model();  // the arrays that follow the scene's material (materials_moved)
#define TISSUE_MATERIAL_OFFSET(name, ...) add(m.name);
    TISSUE_MATERIAL_ARRAYS(TISSUE_MATERIAL_OFFSET)
#undef TISSUE_MATERIAL_OFFSET
    if (m.node_divisor) add(m.node_divisor);  // (null without IANP: alike in every member of one mesh)
    if (const void* load = store_.load_space()) add(load);  // reserved in a group's slot
    const LawView<T>& w = store_.law();  // the law arrays (LawView::moved): null where no set uses them
#define TISSUE_LAW_OFFSET(kind, name, len) \
  if (w.name) add(w.name);
    TISSUE_LAW_MODEL_FIELDS(TISSUE_LAW_OFFSET)
    TISSUE_LAW_STATE_FIELDS(TISSUE_LAW_OFFSET)
#undef TISSUE_LAW_OFFSET
    for (const void* p : reducer_.device_arrays()) add(p);
    if (std::find(offsets.begin(), offsets.end(), std::ptrdiff_t(-1)) != offsets.end()) return false;
    return group_->same_layout(offsets);
  }

  /// A group tick's first half: what launch_tick_graph does before its
  /// launch, the tools staged in the group's array.
  void start_group_tick(int steps, const ContactTools<double>& tools) {
    const StepStart start = take_pressures();
    const bool passes = prepare_reduction(region_.view());
    // work this scene queued on its own stream (a grasp, a copy of the pass arrays) before the group's
    if (cudaStreamQuery(stream()) != cudaSuccess) {
      cudaGetLastError();  // (cudaErrorNotReady is not an error)
      stream_.sync();
    }
    const std::size_t tool_bytes =
        tools.n_tools > 0 ? offsetof(ContactTools<T>, tool) + sizeof(ToolStep<T>) * size_t(tools.n_tools) : 0;
    group_->start(slot_,
                  {store_.u.phase, steps, static_cast<int>(start), store_.pressure_set(),
                   store_.state().load ? 1 : 0, tool_bytes},
                  tools);
    reduce_tools_ = tool_bytes > 0 ? group_->device_tools(slot_) : nullptr;
    launched_ = {false, false, steps, tool_bytes, start, passes, true};
  }

  std::optional<Reductions> finish_group_tick() {
    const LaunchedTick t = launched_;
    launched_ = {};
    const Reductions out = group_->finish(slot_);
    if (t.tool_bytes > 0) log_.count_to_device(t.tool_bytes);
    pressures_fresh_ = t.passes;
    log_.count_to_host(sizeof(Reductions));
    store_.u.advance(t.steps);
    return out;
  }

  /// The part of the tools' motion covering steps [first, first + count) of
  /// `steps`, as a motion of its own over `count` steps.
  static ContactTools<double> slice(const ContactTools<double>& all, int first, int count) {
    if (first == 0 && count == all.steps) return all;
    ContactTools<double> c = all;
    c.steps = count;
    const double s0 = double(first) / all.steps, s1 = double(first + count) / all.steps;
    for (int t = 0; t < all.n_tools; ++t) {
      const ToolStep<double>& a = all.tool[t];
      ToolStep<double>& b = c.tool[t];
      interpolate_pose(a.tip0, a.axis0, a.tip1, a.axis1, s0, b.tip0, b.axis0);
      interpolate_pose(a.tip0, a.axis0, a.tip1, a.axis1, s1, b.tip1, b.axis1);
    }
    return c;
  }

  /// The reduction's passes 1-2 (in the scratch set) taken as the next
  /// steps' own: swaps the sets when they are at the current u over the
  /// current region (the cpu's take_passes; docs/cuda.md, "Passes 1-2 taken
  /// from the reduction").
  StepStart take_pressures() {
    if (!pressures_fresh_) return StepStart::kPass1;
    pressures_fresh_ = false;
    store_.swap_pressures();
    return StepStart::kPass3;
  }

  /// Whether a reduction over region r runs passes 1-2 (into the scratch
  /// set); if so, first makes the scratch set equal the state's outside the
  /// region, which the reduction leaves as it finds: a copy only after
  /// something wrote the state's set outside the region (pass1_all), since
  /// steps and reductions write the region's entries only.
  bool prepare_reduction(const RegionView& r) {
    if (!Reducer<T>::runs_passes(store_.model(), r)) return false;
    if (!pressures_synced_) store_.copy_pressures_to_scratch(stream());
    pressures_synced_ = true;
    return true;
  }

  /// Pass 1 over every element (after a region build or new displacements).
  void pass1_all() {
    pressures_fresh_ = pressures_synced_ = false;
    const RegionView all = {nullptr, nullptr, store_.n_nodes(), store_.n_elems()};
    const RegionView region = region_view();  // its gradients: those of the steps to come
    stepper_.element_pressure(store_.model(), store_.state(), all, store_.u.current().u, stream(), &region);
  }

  // first: destroyed last, after every array that may lie in the group's arena
  std::shared_ptr<SceneGroup<T>> group_;
  int slot_ = -1;
  bool in_group_layout_ = false;  ///< its arrays lie in its slot at the group's layout (slot_layout_matches)
  Stream stream_;
  LaunchedTick launched_;  ///< the graph do_start_tick launched, until do_finish_tick
  Transfers log_;
  DeviceStore<T> store_;
  RegionFill region_;
  Reducer<T> reducer_;
  DeviceContact<T> contact_;
  DeviceBodyContact<T> body_;     ///< contact between bodies (inactive: none)
  TissueModel<double> surface_;   ///< the mesh's surface and reference positions (the bodies' lists)
  /// The tools the last advance read on the device (null: none): reduce()'s
  /// contact reactions take their friction coefficients.
  const ContactTools<T>* reduce_tools_ = nullptr;
  Stepper<T> stepper_;
  CudaGradients gradients_ = CudaGradients::Auto;  ///< set_cuda_gradients: for the next upload
  std::vector<index_t> seeds_;
  DeviceArray<index_t> driven_list_;      ///< current driven nodes (n_driven_)
  DeviceArray<unsigned char> drive_dev_;  ///< set_driven upload: values (3n T), ids (n), axis masks (n bytes)
  PinnedArray<unsigned char> drive_host_; ///< its pinned staging
  Event drive_copied_;                    ///< the staging's last upload has been read
  bool drive_pending_ = false;
  index_t n_driven_ = 0;
  bool pressures_fresh_ = false;   ///< the scratch set holds passes 1-2 at the current u (the last reduction's)
  bool pressures_synced_ = false;  ///< the scratch set equals the state's outside the region
  DeviceArray<std::uint8_t> probe_dev_;   ///< roles of nodes to drive (n_nodes)
  PinnedArray<std::uint8_t> probe_host_;
  DeviceArray<double> scratch_;           ///< set_displacements / download / role-probe staging (7 n + ne)
  std::string device_name_;
};

template <class T>
typename SceneGroup<T>::Graph& SceneGroup<T>::graph(const GroupTickKey& key, int rep) {
  std::unique_ptr<Graph>& g = graphs_[key];
  if (g && g->exec.get()) return *g;
  g = std::make_unique<Graph>();
  const int n = slots();
  g->skip_dev.allocate(n);
  g->skip_host.allocate(n);
  const SceneSlots where{rep, static_cast<std::int64_t>(arena_.stride()), static_cast<std::int64_t>(sizeof(ContactTools<T>))};
  g->exec = capture_graph(stream_.get(), [&](cudaStream_t st) {
    if (key.tool_bytes > 0)
      CUDA_CHECK(cudaMemcpy2DAsync(tools_dev_.data(), sizeof(ContactTools<T>), tools_host_.data(),
                                   sizeof(ContactTools<T>), key.tool_bytes, n, cudaMemcpyHostToDevice, st));
    CUDA_CHECK(cudaMemcpyAsync(g->skip_dev.data(), g->skip_host.data(), sizeof(int) * n, cudaMemcpyHostToDevice, st));
    {
      ScenesInLaunches over(n);
      members_[rep]->enqueue_group_tick(key, where, g->skip_dev.data() + rep,
                                        key.tool_bytes > 0 ? tools_dev_.data() + rep : nullptr, st);
    }
    // every slot's Reductions: rep's result moved to slot 0, one slot apart
    const char* first = reinterpret_cast<const char*>(members_[rep]->result_device()) - std::size_t(rep) * arena_.stride();
    CUDA_CHECK(cudaMemcpy2DAsync(results_host_.data(), sizeof(Reductions), first, arena_.stride(), sizeof(Reductions),
                                 n, cudaMemcpyDeviceToHost, st));
  });
  return *g;
}

template <class T>
void SceneGroup<T>::launch() {
  std::lock_guard<std::mutex> lock(mutex_);
  const int n = slots();
  std::vector<int> order;
  for (int k = 0; k < n; ++k)
    if (started_[k] && members_[k]) order.push_back(k);
  if (order.empty()) return;
  std::vector<char> done(n, 0);
  for (int k : order) {
    if (done[k]) continue;
    const GroupTickKey key = keys_[k];
    Graph& g = graph(key, k);
    for (int j = 0; j < n; ++j) g.skip_host[j] = 1;
    for (int j : order)
      if (!done[j] && keys_[j] == key) {
        g.skip_host[j] = 0;
        done[j] = 1;
      }
    CUDA_CHECK(cudaGraphLaunch(g.exec.get(), stream_.get()));
    // the next key's graph may share this one's tools and results arrays: the copies are in stream order
  }
  stream_.sync();
  for (int k : order) {
    started_[k] = 0;
    ran_[k] = 1;
  }
  ticks_together_.fetch_add(std::int64_t(order.size()), std::memory_order_relaxed);
}

template <class F>
decltype(auto) with_cuda_backend(Backend& b, F&& f) {
  if (auto* p = dynamic_cast<CudaBackend<float>*>(&b)) return f(*p);
  if (auto* p = dynamic_cast<CudaBackend<double>*>(&b)) return f(*p);
  throw std::invalid_argument("backend '" + b.name() + "' is not a cuda backend");
}

}  // namespace
}  // namespace gpu

void set_cuda_memory_limit(std::size_t bytes) { gpu::set_device_memory_limit(bytes); }

std::shared_ptr<BackendGroup> make_cuda_scene_group(Precision precision, int slots, std::size_t slot_bytes) {
  if (slots < 1 || slots > kMaxCudaGroupScenes)
    throw std::invalid_argument(gpu::str("cuda scene group: ", slots, " scenes (1..", kMaxCudaGroupScenes, ")"));
  if (precision == Precision::Float) return std::make_shared<gpu::SceneGroup<float>>(slots, slot_bytes);
  return std::make_shared<gpu::SceneGroup<double>>(slots, slot_bytes);
}

void join_cuda_scene_group(Backend& backend, const std::shared_ptr<BackendGroup>& group, int slot) {
  if (auto* b = dynamic_cast<gpu::CudaBackend<float>*>(&backend)) {
    auto g = std::dynamic_pointer_cast<gpu::SceneGroup<float>>(group);
    if (!g) throw std::invalid_argument("join_cuda_scene_group: a float backend needs a float group");
    return b->join(std::move(g), slot);
  }
  if (auto* b = dynamic_cast<gpu::CudaBackend<double>*>(&backend)) {
    auto g = std::dynamic_pointer_cast<gpu::SceneGroup<double>>(group);
    if (!g) throw std::invalid_argument("join_cuda_scene_group: a double backend needs a double group");
    return b->join(std::move(g), slot);
  }
  throw std::invalid_argument("backend '" + backend.name() + "' is not a cuda backend");
}

std::unique_ptr<Backend> make_cuda_backend(Precision precision) {
  std::string why;  // checked before any CUDA object is made, for a clear message
  if (!cuda_available(&why)) throw std::runtime_error("backend 'cuda' cannot run here: " + why);
  if (precision == Precision::Float) return std::make_unique<gpu::CudaBackend<float>>();
  return std::make_unique<gpu::CudaBackend<double>>();
}

CudaNodeField cuda_node_field(Backend& backend, int which) {
  return gpu::with_cuda_backend(backend, [&](auto& b) { return b.node_field(which); });
}

void cuda_copy_to_host(const void* src, void* dst, std::size_t bytes) {
  cudaPointerAttributes attr;
  if (cudaPointerGetAttributes(&attr, src) != cudaSuccess ||
      (attr.type != cudaMemoryTypeDevice && attr.type != cudaMemoryTypeManaged)) {
    cudaGetLastError();
    throw std::invalid_argument(gpu::str("a device array at ", src, " is not CUDA device memory"));
  }
  CUDA_CHECK(cudaMemcpy(dst, src, bytes, cudaMemcpyDeviceToHost));
}

const char* to_string(CudaStepMode mode) {
  switch (mode) {
    case CudaStepMode::Auto: return "auto";
    case CudaStepMode::Launch: return "launch";
    case CudaStepMode::Graph: return "graph";
    case CudaStepMode::Grid: return "grid";
    case CudaStepMode::Cluster: return "cluster";
  }
  return "?";
}

void set_cuda_step_mode(Backend& backend, CudaStepMode mode) {
  gpu::with_cuda_backend(backend, [&](auto& b) { b.stepper().set_mode(mode); });
}

CudaStepMode cuda_step_mode(Backend& backend) {
  return gpu::with_cuda_backend(backend, [](auto& b) { return b.stepper().choose(b.region_view()); });
}

bool cuda_fuses_forces(Backend& backend) {
  return gpu::with_cuda_backend(backend, [](auto& b) { return b.stepper().fuses_forces(b.region_view()); });
}

index_t cuda_fused_force_blocks(Backend& backend) {
  return gpu::with_cuda_backend(backend, [](auto& b) { return b.stepper().limits().fused_force_blocks; });
}

void set_cuda_fused_force_blocks(Backend& backend, index_t blocks) {
  gpu::with_cuda_backend(backend, [&](auto& b) { b.stepper().set_fused_force_blocks(blocks); });
}

index_t cuda_lanes_node_min(Backend& backend) {
  return gpu::with_cuda_backend(backend, [](auto& b) { return b.lanes_node_min(); });
}

void set_cuda_lanes_node_min(Backend& backend, index_t nodes) {
  gpu::with_cuda_backend(backend, [&](auto& b) { b.set_lanes_node_min(nodes); });
}

bool cuda_discards_slots(Backend& backend) {
  return gpu::with_cuda_backend(backend, [](auto& b) { return b.discard_slots(); });
}

void set_cuda_discards_slots(Backend& backend, bool discard) {
  gpu::with_cuda_backend(backend, [&](auto& b) { b.set_discard_slots(discard); });
}

CudaNodePassLaunches cuda_node_pass_launches() {
  const auto& c = gpu::node_pass_launches;
  return {c.pressures.load(), c.pressures_lanes.load(), c.updates.load(), c.updates_lanes.load()};
}

index_t cuda_merge_wave_nodes(Backend& backend) {
  return gpu::with_cuda_backend(backend, [](auto& b) { return b.stepper().limits().merge_wave_nodes; });
}

void set_cuda_merge_wave_nodes(Backend& backend, index_t nodes) {
  gpu::with_cuda_backend(backend, [&](auto& b) { b.stepper().set_merge_wave_nodes(nodes); });
}

index_t cuda_streaming_elems(Backend& backend) {
  return gpu::with_cuda_backend(backend, [](auto& b) { return b.stepper().limits().streaming_elems; });
}

void set_cuda_streaming_elems(Backend& backend, index_t elems) {
  gpu::with_cuda_backend(backend, [&](auto& b) { b.stepper().set_streaming_elems(elems); });
}

std::int64_t cuda_streaming_force_launches() { return gpu::streaming_force_launches.load(); }

void set_cuda_element_first_wave(index_t blocks) { gpu::element_first_wave_cap.store(std::max<index_t>(-1, blocks)); }

void set_cuda_small_element_blocks(bool always) { gpu::small_element_blocks_forced.store(always); }

CudaSmallElementBlockLaunches cuda_small_element_block_launches() {
  const auto& c = gpu::small_element_block_launches;
  return {c.pressures.load(), c.forces.load()};
}

const char* to_string(CudaGradients g) {
  switch (g) {
    case CudaGradients::Auto: return "auto";
    case CudaGradients::Stored: return "stored";
    case CudaGradients::Recomputed: return "recomputed";
  }
  return "?";
}

void set_cuda_gradients(Backend& backend, CudaGradients g) {
  gpu::with_cuda_backend(backend, [&](auto& b) { b.set_gradients(g); });
}

CudaGradients cuda_gradients(Backend& backend) {
  return gpu::with_cuda_backend(backend, [](auto& b) { return b.gradients(); });
}

}  // namespace tissue
