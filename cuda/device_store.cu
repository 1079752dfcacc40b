#include "cuda/device_store.hpp"

#include <algorithm>
#include <stdexcept>
#include <type_traits>
#include <utility>
#include <vector>

#include "core/region.hpp"
#include "cuda/launch.cuh"
#include "cuda/text.hpp"

namespace tissue::gpu {
namespace {

/// Allocates `dst` for v.size() elements and queues the upload of v.
template <class T>
void upload_array(DeviceArray<T>& dst, const std::vector<T>& v, Transfers& log, cudaStream_t stream) {
  dst.allocate(v.size());
  log.to_device(dst.data(), v.data(), dst.bytes(), stream);
}

/// The fused passes' windows over the slots (ModelView::pack_first): window
/// w holds the nodes whose first slot lies in [w S, (w + 1) S), S =
/// kPackedBlock - (most slots of a node) + 1, so that its nodes' slots span
/// at most kPackedBlock; its first node is the first whose first slot is
/// at least w S. None (span 0) when a node has more than kPackedBlock slots.
struct PackedWindows {
  std::vector<index_t> first;
  index_t span = 0;
};
PackedWindows packed_windows(const std::vector<index_t>& start) {
  PackedWindows p;
  const auto n = static_cast<index_t>(start.size()) - 1;
  index_t most = 0;
  for (index_t a = 0; a < n; ++a) most = std::max(most, start[a + 1] - start[a]);
  if (most > kPackedBlock) {
    p.first = {0};
    return p;
  }
  p.span = kPackedBlock - most + 1;
  const index_t windows = start[n] / p.span + 1;
  p.first.resize(windows + 1);
  index_t a = 0;
  for (index_t w = 0; w <= windows; ++w) {  // (the last entry: n, since windows * span > start[n - 1])
    while (a < n && start[a] < w * p.span) ++a;
    p.first[w] = a;
  }
  return p;
}

/// ModelView::lanes_node_min on the current device: two waves of its
/// resident threads at kNodeLanes threads a node. On an H100 (132 SMs of
/// 2,048 threads) 67,584 nodes: 1M tets (175,616 nodes) and 4M take two
/// lanes a thread, 100k tets (19,683) eight threads a node.
index_t lanes_node_min() {
  const std::int64_t resident = std::int64_t(current_device_attribute(cudaDevAttrMultiProcessorCount)) *
                                current_device_attribute(cudaDevAttrMaxThreadsPerMultiProcessor);
  return static_cast<index_t>(2 * resident / kNodeLanes);
}

/// The model's reference positions, one Packed3 per node.
template <class S>
std::vector<Packed3<S>> packed_positions(const TissueModel<S>& m) {
  std::vector<Packed3<S>> X(m.n_nodes);
  for (index_t i = 0; i < m.n_nodes; ++i) X[i] = Packed3<S>::of(reference_position(m, i));
  return X;
}

/// held[a] = the node's fixed axes (Init::FixedAxes).
__global__ void fixed_axes_kernel(index_t n, const std::uint8_t* flags, std::uint8_t* held) {
  const index_t a = thread_index();
  if (a < n) held[a] = fixed_axes(flags[a]);
}

template <class V>
__global__ void fill_kernel(index_t n, V* v, V value) {
  const index_t i = thread_index();
  if (i < n) v[i] = value;
}

/// Sets a store array to its declared initial value (core/store.hpp Init).
template <class V>
void reset_array(DeviceArray<V>& a, Init init, const std::uint8_t* node_flags, cudaStream_t stream) {
  if (a.size() == 0) return;
  switch (init) {
    case Init::Zero:
      return a.fill_bytes(0, stream);
    case Init::NoTool:  // -1
    case Init::NoBad:   // every bit
      return a.fill_bytes(0xff, stream);
    case Init::Inner:
      if constexpr (sizeof(V) == 1) return a.fill_bytes(kInner, stream);
      break;
    case Init::One:
      if constexpr (std::is_arithmetic_v<V>) return launch(index_t(a.size()), stream, fill_kernel<V>, index_t(a.size()), a.data(), V(1));
      break;
    case Init::FixedAxes:
      if constexpr (std::is_same_v<V, std::uint8_t>)
        return launch(index_t(a.size()), stream, fixed_axes_kernel, index_t(a.size()), node_flags, a.data());
      break;
  }
  throw std::logic_error("cuda store: an array's initial value does not suit its type (core/store.hpp)");
}

}  // namespace

template <class T>
void DeviceStore<T>::upload(const TissueModel<T>& m, const TissueModel<double>& ref, CudaGradients gradients,
                            Transfers& log, cudaStream_t stream) {
  const index_t n = m.n_nodes, ne = m.n_elems;
  // the gradients' checks before anything is replaced (a refused model leaves the last one intact);
  // Auto on a mesh too small for any region to recompute keeps the gradients alone, unchecked
  const bool may_recompute = gradients == CudaGradients::Recomputed ||
                             (gradients == CudaGradients::Auto && ne >= kRecomputeMinElements);
  const Precision p = sizeof(T) == 4 ? Precision::Float : Precision::Double;
  const GradientDeviation dev =
      may_recompute ? worst_gradient_deviation(ref, p, kGradientTolerance) : GradientDeviation{};
  const bool accurate = dev.deviation <= kGradientTolerance;
  // float's recomputation reads points of this grid (cuda/views.hpp ReferencePoint), as the check did
  const ReferenceGrid grid = sizeof(T) == 4 && may_recompute ? reference_grid(ref) : ReferenceGrid{};
  if (gradients == CudaGradients::Recomputed && !accurate) {
    const std::string cause = sizeof(T) == 4
                                  ? str("a sliver, or an element too small for float's reference grid, whose step is ",
                                        grid.step, " m over the whole mesh")
                                  : std::string("a sliver");
    throw std::invalid_argument(str("cuda backend, gradients 'recomputed': element ", dev.elem,
                                    "'s shape gradients recomputed in ", sizeof(T) == 4 ? "float" : "double",
                                    " stray by ", dev.deviation, " from the model's (more than ", kGradientTolerance,
                                    ": ", cause, "); use gradients 'auto' or 'stored'"));
  }
  // Stored: the gradients only; Recomputed: the reference positions only;
  // Auto: both on a large mesh whose recomputation is accurate enough (the
  // passes then choose by region size: cuda/views.hpp recomputes()), else
  // the gradients
  const bool keep_X_ref = may_recompute && accurate;
  const bool keep_dndx = gradients != CudaGradients::Recomputed;
  const std::vector<Packed3<T>> X = packed_positions(m);
  upload_array(X_, X, log, stream);
  std::vector<ReferencePoint<T>> X_ref;
  if (keep_X_ref) {
    if constexpr (sizeof(T) == 4) {
      X_ref.resize(n);
      for (index_t a = 0; a < n; ++a) X_ref[a] = grid_point(grid, ref, a);
    } else {
      X_ref = packed_positions(ref);
    }
    upload_array(X_ref_, X_ref, log, stream);
  } else {
    X_ref_.allocate(0);
  }
  if (keep_dndx) {
    upload_array(dndx_, m.dndx, log, stream);
    upload_array(volume_, m.volume, log, stream);
  } else {
    dndx_.allocate(0);
    volume_.allocate(0);
  }
  upload_array(elem_nodes_, m.elem_nodes, log, stream);
  upload_array(node_elem_start_, m.node_elem_start, log, stream);
  upload_array(node_elem_, m.node_elem, log, stream);
  const PackedWindows packs = packed_windows(m.node_elem_start);
  upload_array(pack_first_, packs.first, log, stream);
  upload_array(slot_of_, m.elem_slot, log, stream);
  upload_array(tris_, m.tris, log, stream);
#define TISSUE_MATERIAL_UPLOAD(name, ...) upload_array(arrays_.name, m.name, log, stream);
  TISSUE_MATERIAL_ARRAYS(TISSUE_MATERIAL_UPLOAD)
#undef TISSUE_MATERIAL_UPLOAD
  upload_array(node_flags_, m.node_flags, log, stream);
  const std::vector<T> node_divisor = nodal_pressure_divisors(m);
  upload_array(node_divisor_, node_divisor, log, stream);
  upload_array(surf_nodes_, m.surf_nodes, log, stream);
  upload_array(surf_slot_start_, m.surf_slot_start, log, stream);
  upload_array(surf_slot_, m.surf_slot, log, stream);
#define TISSUE_LAW_UPLOAD(kind, name, len) upload_array(law_arrays_.name, m.name, log, stream);
  TISSUE_LAW_MODEL_FIELDS(TISSUE_LAW_UPLOAD)
#undef TISSUE_LAW_UPLOAD
  CUDA_CHECK(cudaStreamSynchronize(stream));  // the host sources above must outlive the copies

  model_ = {};
  model_.n_nodes = n;
  model_.n_elems = ne;
  model_.n_tris = m.n_tris;
  model_.X = X_.data();
  model_.elem_nodes = elem_nodes_.data();
  model_.dndx = keep_dndx ? dndx_.data() : nullptr;
  model_.volume = keep_dndx ? volume_.data() : nullptr;
  model_.X_ref = keep_X_ref ? X_ref_.data() : nullptr;
  model_.grid_step = static_cast<T>(grid.step);
#define TISSUE_MATERIAL_POINT(name, ...) model_.name = arrays_.name.data();
  TISSUE_MATERIAL_ARRAYS(TISSUE_MATERIAL_POINT)
#undef TISSUE_MATERIAL_POINT
  model_.node_elem_start = node_elem_start_.data();
  model_.node_elem = node_elem_.data();
  model_.pack_first = pack_first_.data();
  model_.n_windows = static_cast<index_t>(packs.first.size()) - 1;
  model_.pack_span = packs.span;
  model_.lanes_node_min = lanes_node_min();
  model_.slot_of = slot_of_.data();
  model_.node_divisor = node_divisor_.data();
  model_.tris = tris_.data();
  model_.node_flags = node_flags_.data();
  model_.n_surf = m.n_surf;
  model_.surf_nodes = surf_nodes_.data();
  model_.surf_slot_start = surf_slot_start_.data();
  model_.surf_slot = surf_slot_.data();
  model_.dt = m.dt;
  model_.ianp = m.ianp;

  // the state: each array of core/store.hpp's lists at its declared shape,
  // in the lists' order (every scene of a group allocates the same arrays
  // in the same order, so that they lie at one offset in every slot)
  for (auto& b : u.buf) b.allocate(n);
#define TISSUE_STATE_ALLOCATE(name, type, per, components, ...)                                     \
  static_assert((components) == 1 || (components) == 3, #name ": the device holds 1 or 3 per entry"); \
  arrays_.name.allocate(store_entries(Per::per, m));
#define TISSUE_PASS_ALLOCATE(name, type, per, components, ...) \
  arrays_.name[0].allocate(store_entries(Per::per, m));
  TISSUE_STATE_ARRAYS(TISSUE_STATE_ALLOCATE)
  TISSUE_PASS_ARRAYS(TISSUE_PASS_ALLOCATE)
  TISSUE_DEVICE_STATE_ARRAYS(TISSUE_STATE_ALLOCATE)
#undef TISSUE_PASS_ALLOCATE
  model_.discard_slots = arrays_.f_slot.bytes() > half_l2_bytes();  // the whole mesh's slots (pass 3's streaming kernel: a region's)
  load_.allocate(reserve_load_ ? std::size_t(m.n_nodes) : 0);  // a group's scene: its load's room in its slot
  load_on_ = false;
  // the law arrays (core/material.hpp's lists): state sized from the model,
  // and a null pointer for every empty array
#define TISSUE_LAW_ALLOCATE(kind, name, len) law_arrays_.name.allocate(len);
  TISSUE_LAW_STATE_FIELDS(TISSUE_LAW_ALLOCATE)
#undef TISSUE_LAW_ALLOCATE
  law_ = {};
  law_.n_visco = m.n_visco;
  law_.n_prony = m.n_prony;
#define TISSUE_LAW_POINT(kind, name, len) law_.name = law_arrays_.name.size() ? law_arrays_.name.data() : nullptr;
  TISSUE_LAW_MODEL_FIELDS(TISSUE_LAW_POINT)
  TISSUE_LAW_STATE_FIELDS(TISSUE_LAW_POINT)
#undef TISSUE_LAW_POINT
#define TISSUE_SCRATCH_ALLOCATE(name, type, per, components, ...) \
  arrays_.name[1].allocate(store_entries(Per::per, m));
  TISSUE_PASS_ARRAYS(TISSUE_SCRATCH_ALLOCATE)  // (the scratch set last)
#undef TISSUE_SCRATCH_ALLOCATE
#undef TISSUE_STATE_ALLOCATE
  reset_state(stream);
}

template <class T>
void DeviceStore<T>::reset_state(cudaStream_t stream) {
  for (auto& b : u.buf) b.fill_bytes(0, stream);
  u.phase = 0;
  pressures_ = 0;
  const std::uint8_t* flags = model_.node_flags;
#define TISSUE_STATE_RESET(name, type, per, components, init, ...) reset_array(arrays_.name, Init::init, flags, stream);
#define TISSUE_PASS_RESET(name, type, per, components, init, ...) \
  for (auto& set : arrays_.name) reset_array(set, Init::init, flags, stream);
  TISSUE_STATE_ARRAYS(TISSUE_STATE_RESET)
  TISSUE_PASS_ARRAYS(TISSUE_PASS_RESET)
  TISSUE_DEVICE_STATE_ARRAYS(TISSUE_STATE_RESET)
#undef TISSUE_PASS_RESET
#undef TISSUE_STATE_RESET
  clear_law_state(stream);
}

template <class T>
void DeviceStore<T>::clear_law_state(cudaStream_t stream) {
#define TISSUE_LAW_ZERO(kind, name, len) \
  if (law_arrays_.name.size()) law_arrays_.name.fill_bytes(0, stream);
  TISSUE_LAW_STATE_FIELDS(TISSUE_LAW_ZERO)
#undef TISSUE_LAW_ZERO
}

template <class T>
void DeviceStore<T>::set_load(std::span<const double> load, Transfers& log, cudaStream_t stream) {
  const index_t n = model_.n_nodes;
  load_on_ = false;
  if (load.empty()) {
    if (!reserve_load_) load_.allocate(0);
    return;
  }
  std::vector<Packed3<T>> r(n);
  for (index_t i = 0; i < n; ++i)
    r[i] = {T(load[i]), T(load[n + i]), T(load[2 * std::size_t(n) + i]), T(0)};
  if (load_.size() != r.size()) load_.allocate(r.size());  // (a reserved load keeps its place)
  log.to_device_now(load_.data(), r.data(), load_.bytes(), stream);  // r is pageable and local
  load_on_ = true;
}

template <class T>
StateView<T> DeviceStore<T>::state() {
  StateView<T> s;
#define TISSUE_STATE_POINT(name, ...) s.name = arrays_.name.data();
#define TISSUE_PASS_POINT(name, ...) s.name = arrays_.name[pressures_].data();
  TISSUE_STATE_ARRAYS(TISSUE_STATE_POINT)
  TISSUE_PASS_ARRAYS(TISSUE_PASS_POINT)
  TISSUE_DEVICE_STATE_ARRAYS(TISSUE_STATE_POINT)
#undef TISSUE_PASS_POINT
#undef TISSUE_STATE_POINT
  s.load = load_on_ ? load_.data() : nullptr;
  return s;
}

template <class T>
StateView<T> DeviceStore<T>::pressure_scratch() {
  StateView<T> s = state();
  const int k = pressures_ ^ 1;
#define TISSUE_SCRATCH_POINT(name, ...) s.name = arrays_.name[k].data();
  TISSUE_PASS_ARRAYS(TISSUE_SCRATCH_POINT)
#undef TISSUE_SCRATCH_POINT
  return s;
}

template <class T>
void DeviceStore<T>::copy_pressures_to_scratch(cudaStream_t stream) {
  const int from = pressures_, to = pressures_ ^ 1;
  const auto copy = [&](auto& set) {
    if (set[from].bytes() > 0)
      CUDA_CHECK(cudaMemcpyAsync(set[to].data(), set[from].data(), set[from].bytes(), cudaMemcpyDeviceToDevice, stream));
  };
#define TISSUE_PASS_COPY(name, ...) copy(arrays_.name);
  TISSUE_PASS_ARRAYS(TISSUE_PASS_COPY)
#undef TISSUE_PASS_COPY
}

template <class T>
void DeviceStore<T>::set_masses(const TissueModel<T>& m, Transfers& log, cudaStream_t stream) {
  const auto copy = [&](auto& dst, const std::vector<T>& v) {
    if (dst.bytes() != v.size() * sizeof(T))
      throw std::invalid_argument(str("cuda backend: set_masses: ", v.size(), " values for an array of ",
                                      dst.bytes() / sizeof(T)));
    log.to_device(dst.data(), v.data(), dst.bytes(), stream);
  };
  copy(arrays_.mass, m.mass);
  copy(arrays_.cd_A, m.cd_A);
  copy(arrays_.cd_B, m.cd_B);
  copy(arrays_.cd_C, m.cd_C);
  CUDA_CHECK(cudaStreamSynchronize(stream));  // the host sources must outlive the copies
}

template class DeviceStore<float>;
template class DeviceStore<double>;

}  // namespace tissue::gpu
