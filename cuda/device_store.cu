#include "cuda/device_store.hpp"

#include <algorithm>
#include <stdexcept>
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

template <class T>
__global__ void reset_nodes_kernel(index_t n, const std::uint8_t* flags, std::uint8_t* held, std::uint8_t* driven,
                                   std::uint8_t* role) {
  const index_t a = thread_index();
  if (a >= n) return;
  held[a] = fixed_axes(flags[a]);
  driven[a] = 0;
  role[a] = kInner;
}

template <class T>
__global__ void reset_elems_kernel(index_t ne, T* elem_J) {
  const index_t e = thread_index();
  if (e < ne) elem_J[e] = T(1);
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
  upload_array(mu_, m.mu, log, stream);
  upload_array(K_, m.K, log, stream);
  upload_array(mass_, m.mass, log, stream);
  upload_array(cd_A_, m.cd_A, log, stream);
  upload_array(cd_B_, m.cd_B, log, stream);
  upload_array(cd_C_, m.cd_C, log, stream);
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
  model_.mu = mu_.data();
  model_.K = K_.data();
  model_.mass = mass_.data();
  model_.cd_A = cd_A_.data();
  model_.cd_B = cd_B_.data();
  model_.cd_C = cd_C_.data();
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

  for (auto& b : u.buf) b.allocate(n);
  u_held_.allocate(n);
  f_.allocate(n);
  f_slot_.allocate(4 * size_t(ne));
  model_.discard_slots = f_slot_.bytes() > half_l2_bytes();  // the whole mesh's slots (pass 3's streaming kernel: a region's)
  elem_dv_[0].allocate(ne);
  held_.allocate(n);
  driven_.allocate(n);
  role_.allocate(n);
  elem_J_[0].allocate(ne);
  node_p_[0].allocate(n);
  bad_.allocate(1);
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
  contact_.allocate(n);
  contact_tool_.allocate(n);
  contact_normal_.allocate(n);
  grasp_offset_.allocate(n);
  corner_dx_.allocate(3 * size_t(m.n_tris));
  corner_tool_.allocate(3 * size_t(m.n_tris));
  corner_blocked_.allocate(3 * size_t(m.n_tris));
  proposed_.allocate(n);
  elem_dv_[1].allocate(ne);  // (the second set last: set 0 where the state's one set was)
  elem_J_[1].allocate(ne);
  node_p_[1].allocate(n);
  reset_state(stream);
}

template <class T>
void DeviceStore<T>::reset_state(cudaStream_t stream) {
  for (auto& b : u.buf) b.fill_bytes(0, stream);
  u.phase = 0;
  u_held_.fill_bytes(0, stream);
  f_.fill_bytes(0, stream);
  f_slot_.fill_bytes(0, stream);
  pressures_ = 0;
  for (int k = 0; k < 2; ++k) {
    elem_dv_[k].fill_bytes(0, stream);
    node_p_[k].fill_bytes(0, stream);
    launch(model_.n_elems, stream, reset_elems_kernel<T>, model_.n_elems, elem_J_[k].data());
  }
  bad_.fill_bytes(0xff, stream);
  clear_law_state(stream);
  contact_.fill_bytes(kNoContact, stream);
  contact_tool_.fill_bytes(0xff, stream);  // -1
  contact_normal_.fill_bytes(0, stream);
  grasp_offset_.fill_bytes(0, stream);
  corner_dx_.fill_bytes(0, stream);
  corner_tool_.fill_bytes(0xff, stream);
  corner_blocked_.fill_bytes(0, stream);
  proposed_.fill_bytes(0, stream);
  launch(model_.n_nodes, stream, reset_nodes_kernel<T>, model_.n_nodes, model_.node_flags, held_.data(),
         driven_.data(), role_.data());
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
  s.u_held = u_held_.data();
  s.held = held_.data();
  s.driven = driven_.data();
  s.role = role_.data();
  s.elem_dv = elem_dv_[pressures_].data();
  s.elem_J = elem_J_[pressures_].data();
  s.node_p = node_p_[pressures_].data();
  s.f_slot = f_slot_.data();
  s.f = f_.data();
  s.load = load_on_ ? load_.data() : nullptr;
  s.bad = bad_.data();
  s.contact = contact_.data();
  s.contact_tool = contact_tool_.data();
  s.contact_normal = contact_normal_.data();
  s.grasp_offset = grasp_offset_.data();
  s.corner_dx = corner_dx_.data();
  s.corner_tool = corner_tool_.data();
  s.corner_blocked = corner_blocked_.data();
  s.proposed = proposed_.data();
  return s;
}

template <class T>
StateView<T> DeviceStore<T>::pressure_scratch() {
  StateView<T> s = state();
  const int k = pressures_ ^ 1;
  s.elem_dv = elem_dv_[k].data();
  s.elem_J = elem_J_[k].data();
  s.node_p = node_p_[k].data();
  return s;
}

template <class T>
void DeviceStore<T>::copy_pressures_to_scratch(cudaStream_t stream) {
  const int from = pressures_, to = pressures_ ^ 1;
  for (auto [dst, src] : {std::pair{&elem_dv_[to], &elem_dv_[from]}, std::pair{&elem_J_[to], &elem_J_[from]},
                          std::pair{&node_p_[to], &node_p_[from]}})
    if (src->bytes() > 0)
      CUDA_CHECK(cudaMemcpyAsync(dst->data(), src->data(), src->bytes(), cudaMemcpyDeviceToDevice, stream));
}

template class DeviceStore<float>;
template class DeviceStore<double>;

}  // namespace tissue::gpu
