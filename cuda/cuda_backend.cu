// The cuda backend: the Backend interface over the device store, as a list
// of stages, each one kernel module (stepper, region_fill, collide, reduce).
// Semantics are the cpu backend's (cpu/constraints.hpp states the rule):
//   held (an axis mask per node) = fixed axes | driven axes, every axis
//   for a halo node; a fixed component is always held at 0 (also when
//   driven); a halo node is held (and stopped) at its displacement when the
//   region was built; a node leaving the region is frozen
//   (u_prev = u_next = u, f = 0), elements leaving it get zero forces; after
//   a region build or set_displacements pass 1 is recomputed over all
//   elements, so pass 2 averages valid p_e V_e on halo nodes too.
// Per haptic tick the only copies are set_driven's targets (up) and the Hit
// and Reductions structs (down); see transfers().
#include "cuda/cuda_backend.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "cuda/collide.hpp"
#include "cuda/device_store.hpp"
#include "cuda/launch.cuh"
#include "cuda/reduce.hpp"
#include "cuda/region_fill.hpp"
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
    Packed3<T> held_at = s.u_held[a];
    hold_halo(fixed, std::uint8_t(0), u[a], held_at);
    s.u_held[a] = held_at;
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

/// u^n = u^{n-1} = u^{n+1} = src (src: 3 x n component-major, double);
/// halo nodes are held at the new u in their components that are neither
/// driven nor fixed.
template <class T>
__global__ void set_displacements_kernel(index_t n, const double* src, const std::uint8_t* flags, StateView<T> s,
                                         StepBuffers<T> b) {
  const index_t a = thread_index();
  if (a >= n) return;
  const Packed3<T> u = {T(src[a]), T(src[n + a]), T(src[2 * n + a]), T(0)};
  b.u_prev[a] = u;
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
class CudaBackend final : public Backend {
 public:
  /// Needs a usable device (make_cuda_backend checks first).
  CudaBackend() {
    device_name_ = current_device_name();
    stepper_.init();
  }

  std::string name() const override { return "cuda"; }
  Precision precision() const override { return sizeof(T) == 4 ? Precision::Float : Precision::Double; }
  std::string device_name() const override { return device_name_; }

  void upload(const TissueModel<double>& model) override {
    const TissueModel<T> m = convert<T>(model);
    uploaded_ = false;
    store_.upload(m, log_, stream());
    const index_t n = m.n_nodes;
    region_.allocate(n, m.n_elems, stream());
    collider_.allocate(m.n_tris);
    reducer_.allocate(n, m.n_elems);
    driven_list_.allocate(n);
    drive_dev_.allocate(n * (3 * sizeof(T) + sizeof(index_t) + 1));
    if (drive_pending_) drive_copied_.sync();  // before its staging is freed
    drive_pending_ = false;
    drive_host_.allocate(drive_dev_.size());
    scratch_.allocate(7 * size_t(n) + m.n_elems);
    probe_dev_.allocate(n);
    probe_host_.allocate(n);
    drive_ids_.reserve(64);
    drive_masks_.reserve(64);
    drive_values_.reserve(192);
    n_driven_ = 0;
    uploaded_ = true;
    build_region({}, kDepthAll);
    stream_.sync();
  }

  void set_displacements(std::span<const double> u) override {
    require_model("set_displacements");
    const index_t n = store_.n_nodes();
    if (u.size() != 3 * size_t(n))
      throw std::invalid_argument(str("set_displacements: ", u.size(), " values for ", n, " nodes (need 3 x n_nodes = ",
                                      3 * size_t(n), ")"));
    for (size_t k = 0; k < u.size(); ++k)
      if (!std::isfinite(u[k]))
        throw std::invalid_argument(
            str("set_displacements: node ", k % n, " axis ", "xyz"[k / n], " is not finite (", u[k], ")"));
    log_.to_device_now(scratch_.data(), u.data(), u.size_bytes(), stream());
    launch(n, stream(), set_displacements_kernel<T>, n, scratch_.data(), store_.model().node_flags, store_.state(),
           store_.u.current());
    pass1_all();
  }

  RegionSizes build_region(std::span<const index_t> seeds, int depth) override {
    require_model("build_region");
    const Topology topo = topology(store_.model());
    StateView<T> s = store_.state();
    RegionSizes sizes;
    if (depth == kDepthAll) {
      sizes = region_.whole(topo, s.role, stream());
    } else {
      if (depth < 0) throw std::invalid_argument(str("region depth ", depth, " must be >= 0 or 'all'"));
      for (index_t a : seeds)
        if (a < 0 || a >= topo.n_nodes)
          throw std::out_of_range(str("region seed node ", a, " out of range (0..", topo.n_nodes - 1, ")"));
      sizes = region_.build(topo, seeds, depth, s.role, log_, stream());
    }
    seeds_.assign(seeds.begin(), seeds.end());
    region_.apply(store_.model(), s, store_.u.current(), stream());
    pass1_all();
    stepper_.invalidate();
    return sizes;
  }

  Region region() override {
    require_model("region");
    return region_.download(topology(store_.model()), store_.state().role, seeds_, log_, stream());
  }

  /// One upload per call (targets, ids and axis masks in one pinned block).
  /// The nodes must lie in the region: checked on the host when they are
  /// seeds (the Scheduler's case), else by one small download of their
  /// roles. A node given twice is driven in the union of its masks, each
  /// component at its last target (as on the cpu).
  void set_driven(std::span<const index_t> nodes, std::span<const double> u) override {
    require_model("set_driven");
    drive(nodes, u, {}, "set_driven");
  }

  void set_driven_axes(std::span<const index_t> nodes, std::span<const double> u,
                       std::span<const std::uint8_t> axes) override {
    require_model("set_driven_axes");
    if (axes.size() != nodes.size())
      throw std::invalid_argument(
          str("set_driven_axes: ", axes.size(), " axis masks for ", nodes.size(), " nodes (need one per node)"));
    drive(nodes, u, axes, "set_driven_axes");
  }

  void clear_driven() override {
    require_model("clear_driven");
    launch(n_driven_, stream(), undrive_kernel<T>, n_driven_, driven_list_.data(), store_.model().node_flags,
           store_.state(), store_.u.current().u);
    n_driven_ = 0;
  }

  void element_pressure() override {
    require_model("element_pressure");
    stepper_.element_pressure(store_.model(), store_.state(), region_.view(), store_.u.current().u, stream());
  }
  void nodal_pressure() override {
    require_model("nodal_pressure");
    stepper_.nodal_pressure(store_.model(), store_.state(), region_.view(), stream());
  }
  void element_forces() override {
    require_model("element_forces");
    stepper_.element_forces(store_.model(), store_.state(), region_.view(), store_.u.current().u, stream());
  }
  void node_update() override {
    require_model("node_update");
    stepper_.node_update(store_.model(), store_.state(), region_.view(), store_.u.current(), stream());
    store_.u.advance(1);
  }

  void advance(int steps) override {
    require_model("advance");
    if (steps < 0) throw std::invalid_argument(str("advance: step count ", steps, " must be >= 0"));
    stepper_.advance(store_.model(), store_.state(), region_.view(), store_.u, steps, stream());
  }

  Hit collide(Vec3<double> a, Vec3<double> b) override {
    require_model("collide");
    return collider_.query(store_.model(), store_.u.current().u, a, b, log_, stream());
  }

  Reductions reduce() override {
    require_model("reduce");
    return reducer_.run(store_.model(), store_.state(), region_.view(), region_.front(), store_.u.current(), log_,
                        stream());
  }

  Fields download() override {
    require_model("download");
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

  void write_positions(float* dst) override {
    require_model("write_positions");
    cudaPointerAttributes attr;
    if (dst == nullptr || cudaPointerGetAttributes(&attr, dst) != cudaSuccess ||
        (attr.type != cudaMemoryTypeDevice && attr.type != cudaMemoryTypeManaged)) {
      cudaGetLastError();
      throw std::invalid_argument("cuda write_positions: dst must be device memory (n_nodes x 3 floats)");
    }
    const index_t n = store_.n_nodes();
    launch(n, stream(), positions_kernel<T>, n, store_.model().X, store_.u.current().u, dst);
    stream_.sync();  // the caller (a GL interop unmap) may use dst right away
  }

  TransferCounters transfers() const override { return log_.counters(); }

  Stepper<T>& stepper() { return stepper_; }
  RegionView region_view() const { return region_.view(); }

 private:
  cudaStream_t stream() const { return stream_.get(); }

  void require_model(const char* what) const {
    if (!uploaded_) throw std::logic_error(str("cuda backend: ", what, "() called before upload()"));
  }

  /// set_driven(_axes): validate, merge duplicates on the host, one upload,
  /// release the old set, drive the new one. axes empty = every component.
  void drive(std::span<const index_t> nodes, std::span<const double> u, std::span<const std::uint8_t> axes,
             const char* what) {
    check_driven(nodes, u, axes, what);
    if (drive_pending_) drive_copied_.sync();  // the staging buffer is free again
    // merge into unique (id, mask, targets) entries, in first-seen order
    drive_ids_.clear();
    drive_masks_.clear();
    drive_values_.clear();
    for (size_t k = 0; k < nodes.size(); ++k) {
      const std::uint8_t mask = axes.empty() ? kAllAxes : axes[k];
      auto it = std::find(drive_ids_.begin(), drive_ids_.end(), nodes[k]);
      size_t j = size_t(it - drive_ids_.begin());
      if (it == drive_ids_.end()) {
        drive_ids_.push_back(nodes[k]);
        drive_masks_.push_back(0);
        drive_values_.insert(drive_values_.end(), 3, 0.0);
      }
      drive_masks_[j] |= mask;
      for (int c = 0; c < 3; ++c)
        if (mask >> c & 1) drive_values_[3 * j + c] = u[3 * k + c];
    }
    const auto n = static_cast<index_t>(drive_ids_.size());
    T* values = reinterpret_cast<T*>(drive_host_.data());
    index_t* ids = reinterpret_cast<index_t*>(values + 3 * size_t(n));
    std::uint8_t* masks = reinterpret_cast<std::uint8_t*>(ids + n);
    for (index_t k = 0; k < n; ++k) {
      ids[k] = drive_ids_[k];
      masks[k] = drive_masks_[k];
      for (int c = 0; c < 3; ++c) values[3 * k + c] = static_cast<T>(drive_values_[3 * k + c]);
    }
    const T* dvalues = reinterpret_cast<const T*>(drive_dev_.data());
    const index_t* dids = reinterpret_cast<const index_t*>(dvalues + 3 * size_t(n));
    const std::uint8_t* dmasks = reinterpret_cast<const std::uint8_t*>(dids + n);
    log_.to_device(drive_dev_.data(), drive_host_.data(), n * (3 * sizeof(T) + sizeof(index_t) + 1), stream());
    drive_copied_.record(stream());
    drive_pending_ = true;
    check_in_region(n, ids, dids, what);
    clear_driven();
    launch(n, stream(), drive_kernel<T>, n, dvalues, dids, dmasks, store_.model().node_flags, driven_list_.data(),
           store_.state());
    n_driven_ = n;
  }

  /// Pass 1 over every element (after a region build or new displacements).
  void pass1_all() {
    const RegionView all = {nullptr, nullptr, store_.n_nodes(), store_.n_elems()};
    stepper_.element_pressure(store_.model(), store_.state(), all, store_.u.current().u, stream());
  }

  /// Throws std::invalid_argument if a node to drive lies outside the region.
  void check_in_region(index_t n, const index_t* ids, const index_t* dids, const char* what) {
    if (region_.sizes().whole()) return;
    bool all_seeds = true;
    for (index_t k = 0; k < n; ++k)
      all_seeds = all_seeds && std::find(seeds_.begin(), seeds_.end(), ids[k]) != seeds_.end();
    if (all_seeds) return;  // seeds are inner nodes
    launch(n, stream(), probe_roles_kernel, n, dids, store_.state().role, probe_dev_.data());
    log_.to_host(probe_host_.data(), probe_dev_.data(), n, stream());
    for (index_t k = 0; k < n; ++k)
      if (probe_host_[k] == kOutside)
        throw std::invalid_argument(
            str(what, ": node ", ids[k], " is outside the deformation region (build_region from it first)"));
  }

  void check_driven(std::span<const index_t> nodes, std::span<const double> u, std::span<const std::uint8_t> axes,
                    const char* what) const {
    if (u.size() != 3 * nodes.size())
      throw std::invalid_argument(
          str(what, ": ", u.size(), " displacement values for ", nodes.size(), " nodes (need 3 per node)"));
    const index_t n = store_.n_nodes();
    for (size_t i = 0; i < nodes.size(); ++i) {
      if (nodes[i] < 0 || nodes[i] >= n)
        throw std::invalid_argument(str(what, ": node ", nodes[i], " out of range (0..", n - 1, ")"));
      if (!axes.empty() && (axes[i] == 0 || axes[i] > kAllAxes))
        throw std::invalid_argument(str(what, ": node ", nodes[i], ": axis mask ", int(axes[i]),
                                        " must be 1..7 (bit 0 = x, 1 = y, 2 = z)"));
      for (int c = 0; c < 3; ++c)
        if (!std::isfinite(u[3 * i + c]))
          throw std::invalid_argument(str(what, ": node ", nodes[i], ": displacement ", "xyz"[c], " = ",
                                          u[3 * i + c], " is not finite"));
    }
  }

  Stream stream_;
  Transfers log_;
  DeviceStore<T> store_;
  RegionFill region_;
  Collider<T> collider_;
  Reducer<T> reducer_;
  Stepper<T> stepper_;
  std::vector<index_t> seeds_;
  DeviceArray<index_t> driven_list_;      ///< current driven nodes (n_driven_)
  DeviceArray<unsigned char> drive_dev_;  ///< set_driven upload: values (3n T), ids (n), axis masks (n bytes)
  PinnedArray<unsigned char> drive_host_; ///< its pinned staging
  Event drive_copied_;                    ///< the staging's last upload has been read
  bool drive_pending_ = false;
  index_t n_driven_ = 0;
  std::vector<index_t> drive_ids_;        ///< set_driven's merge scratch (host)
  std::vector<std::uint8_t> drive_masks_;
  std::vector<double> drive_values_;
  DeviceArray<std::uint8_t> probe_dev_;   ///< roles of nodes to drive (n_nodes)
  PinnedArray<std::uint8_t> probe_host_;
  DeviceArray<double> scratch_;           ///< set_displacements / download staging (7 n + ne)
  bool uploaded_ = false;
  std::string device_name_;
};

template <class F>
decltype(auto) with_cuda_backend(Backend& b, F&& f) {
  if (auto* p = dynamic_cast<CudaBackend<float>*>(&b)) return f(*p);
  if (auto* p = dynamic_cast<CudaBackend<double>*>(&b)) return f(*p);
  throw std::invalid_argument("backend '" + b.name() + "' is not a cuda backend");
}

}  // namespace
}  // namespace gpu

std::unique_ptr<Backend> make_cuda_backend(Precision precision) {
  std::string why;  // checked before any CUDA object is made, for a clear message
  if (!cuda_available(&why)) throw std::runtime_error("backend 'cuda' cannot run here: " + why);
  if (precision == Precision::Float) return std::make_unique<gpu::CudaBackend<float>>();
  return std::make_unique<gpu::CudaBackend<double>>();
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

}  // namespace tissue
