#include "cuda/body_contact.hpp"

#include "core/node_rules.hpp"
#include "cuda/check.hpp"
#include "cuda/contact.cuh"
#include "cuda/launch.cuh"

namespace tissue::gpu {
namespace {

template <class T>
__device__ __forceinline__ T inverse_mass(const ModelView<T>& m, const StateView<T>& s, index_t a) {
  const bool still = s.held[a] == kAllAxes || s.role[a] != kInner || s.contact[a] == kGrasped;
  return still ? T(0) : T(1) / T(m.mass[a]);
}

template <class T>
__global__ void body_hits_kernel(ModelView<T> m, StateView<T> s, const BodyView<T>* view, const Packed3<T>* u,
                                 const Packed3<T>* u_next) {
  const index_t r = index_t(blockIdx.x) * blockDim.x + threadIdx.x;
  wait_for_previous_pass();
  const BodyView<T> v = *view;
  if (r >= v.rows || skipped(s)) return;
  const auto pos = [&](index_t a) { return m.X[a].vec() + u_next[a].vec(); };
  const auto prev = [&](index_t a) { return m.X[a].vec() + u[a].vec(); };
  const auto inv_mass = [&](index_t a) { return inverse_mass(m, s, a); };
  const auto tri = [&](index_t t, int k) { return m.tris[k * m.n_tris + t]; };
  const auto geom = [&](index_t t) { return body_tri<T>(t, pos, tri); };
  const BodyAnchor<T> was = v.anchors[r];
  BodyAnchor<T> now;
  v.hits[r] = body_row_hit<T>(v.node[r], v.cand_start[r], v.cand_start[r + 1], v.cand_tri, v.cand_mu, v.reach, pos,
                              prev, inv_mass, tri, geom, was, now);
  v.anchors[r] = now;
}

template <class T>
__global__ void body_counts_kernel(StateView<T> s, const BodyView<T>* view) {
  const index_t r = index_t(blockIdx.x) * blockDim.x + threadIdx.x;
  wait_for_previous_pass();
  const BodyView<T> v = *view;
  if (r >= v.rows || skipped(s)) return;
  const auto hits = [&](index_t q) -> const BodyHit<T>& { return v.hits[q]; };
  v.counts[r] = body_row_count<T>(r, v.corner_start[r], v.corner_start[r + 1], v.corner_cand, v.corner_row,
                                  v.corner_slot, hits);
}

template <class T>
__global__ void body_scales_kernel(StateView<T> s, const BodyView<T>* view) {
  const index_t r = index_t(blockIdx.x) * blockDim.x + threadIdx.x;
  wait_for_previous_pass();
  const BodyView<T> v = *view;
  if (r >= v.rows || skipped(s)) return;
  BodyHit<T> h = v.hits[r];
  if (h.cand < 0) return;
  body_scale_hit(h, r, v.cand_rows, v.counts);
  v.hits[r] = h;
}

template <class T>
__global__ void body_moves_kernel(ModelView<T> m, StateView<T> s, const BodyView<T>* view, Packed3<T>* u_next) {
  const index_t r = index_t(blockIdx.x) * blockDim.x + threadIdx.x;
  wait_for_previous_pass();
  const BodyView<T> v = *view;
  if (r >= v.rows || skipped(s)) return;
  const index_t a = v.node[r];
  const auto hits = [&](index_t q) -> const BodyHit<T>& { return v.hits[q]; };
  const Vec3<T> d = free_part(s.held[a], body_row_move<T>(r, inverse_mass(m, s, a), v.corner_start[r],
                                                          v.corner_start[r + 1], v.corner_cand, v.corner_row,
                                                          v.corner_slot, hits));
  if (d.x == T(0) && d.y == T(0) && d.z == T(0)) return;
  u_next[a] = Packed3<T>::of(u_next[a].vec() + d);  // (w, the float carry, 0: a contact's position carries no rounding)
}

template <class T>
__global__ void body_check_kernel(ModelView<T> m, StateView<T> s, const BodyView<T>* view, const Packed3<T>* u) {
  const index_t r = index_t(blockIdx.x) * blockDim.x + threadIdx.x;
  wait_for_previous_pass();
  const BodyView<T> v = *view;
  if (r >= v.rows || skipped(s)) return;
  const index_t a = v.node[r];
  const Vec3<T> d = (m.X[a].vec() + u[a].vec()) - v.x_built[r].vec();
  if (dot(d, d) > v.stale2) *v.stale = 1;
}

template <class A>
void upload_array(DeviceArray<A>& d, const std::vector<A>& h, Transfers& log, cudaStream_t stream) {
  d.allocate(std::max<std::size_t>(h.size(), 1));
  if (!h.empty()) log.to_device_now(d.data(), h.data(), h.size() * sizeof(A), stream);
}

}  // namespace

template <class T>
void enqueue_body_step(const ModelView<T>& m, const StateView<T>& s, BodySteps<T> body, StepBuffers<T> b,
                       cudaStream_t stream) {
  launch_chained(body.rows, stream, body_hits_kernel<T>, m, s, body.view, static_cast<const Packed3<T>*>(b.u),
                 static_cast<const Packed3<T>*>(b.u_next));
  launch_chained(body.rows, stream, body_counts_kernel<T>, s, body.view);
  launch_chained(body.rows, stream, body_scales_kernel<T>, s, body.view);
  launch_chained(body.rows, stream, body_moves_kernel<T>, m, s, body.view, b.u_next);
}

template <class T>
void enqueue_body_check(const ModelView<T>& m, const StateView<T>& s, BodySteps<T> body, const Packed3<T>* u,
                        cudaStream_t stream) {
  launch_chained(body.rows, stream, body_check_kernel<T>, m, s, body.view, u);
}

template <class T>
void DeviceBodyContact<T>::clear() {
  spec_ = {};
  lists_ = {};
  rows_ = 0;
}

template <class T>
void DeviceBodyContact<T>::set(const TissueModel<double>& mesh, const BodyContactSpec& spec,
                               const std::vector<double>& x, Transfers& log, cudaStream_t stream) {
  clear();
  if (spec.empty()) return;
  spec_ = spec;
  anchors_.allocate(0);  // a new contact: no anchors carried
  if (stale_.size() == 0) stale_.allocate(1);
  view_.allocate(1);
  rebuild(mesh, x, log, stream);
}

template <class T>
void DeviceBodyContact<T>::rebuild(const TissueModel<double>& mesh, const std::vector<double>& x, Transfers& log,
                                   cudaStream_t stream) {
  lists_ = build_body_lists(mesh, spec_, x);
  ++builds_;
  rows_ = lists_.rows();
  const auto as_t = [](const std::vector<double>& v) { return std::vector<T>(v.begin(), v.end()); };
  std::vector<Packed3<T>> built(static_cast<std::size_t>(rows_));
  for (index_t r = 0; r < rows_; ++r)
    built[r] = Packed3<T>::of(Vec3<T>{T(lists_.x_built[3 * size_t(r)]), T(lists_.x_built[3 * size_t(r) + 1]),
                                      T(lists_.x_built[3 * size_t(r) + 2])});
  upload_array(node_, lists_.node, log, stream);
  upload_array(cand_start_, lists_.cand_start, log, stream);
  upload_array(cand_tri_, lists_.cand_tri, log, stream);
  upload_array(cand_mu_, as_t(lists_.cand_mu), log, stream);
  upload_array(cand_rows_, lists_.cand_rows, log, stream);
  upload_array(corner_start_, lists_.corner_start, log, stream);
  upload_array(corner_cand_, lists_.corner_cand, log, stream);
  upload_array(corner_row_, lists_.corner_row, log, stream);
  upload_array(corner_slot_, lists_.corner_slot, log, stream);
  upload_array(x_built_, built, log, stream);
  hits_.allocate(std::max<std::size_t>(std::size_t(rows_), 1));
  hits_.fill_bytes(0xff, stream);  // cand -1 everywhere until the first step
  // the rows, and so the anchors, outlast a rebuild: allocated (and cleared) only for a new contact
  if (const std::size_t want = std::max<std::size_t>(std::size_t(rows_), 1); anchors_.size() != want) {
    anchors_.allocate(want);
    clear_anchors(stream);
  }
  counts_.allocate(std::max<std::size_t>(std::size_t(rows_), 1));
  BodyView<T> v;
  v.rows = rows_;
  v.reach = T(lists_.skin);
  v.stale2 = T(0.0625 * lists_.skin * lists_.skin);
  v.node = node_.data();
  v.cand_start = cand_start_.data();
  v.cand_tri = cand_tri_.data();
  v.cand_mu = cand_mu_.data();
  v.cand_rows = cand_rows_.data();
  v.corner_start = corner_start_.data();
  v.corner_cand = corner_cand_.data();
  v.corner_row = corner_row_.data();
  v.corner_slot = corner_slot_.data();
  v.x_built = x_built_.data();
  v.hits = hits_.data();
  v.anchors = anchors_.data();
  v.counts = counts_.data();
  v.stale = stale_.device();
  stale_host()[0] = 0;
  log.to_device_now(view_.data(), &v, sizeof(v), stream);
}

template <class T>
std::vector<BodyContactNode> DeviceBodyContact<T>::contacts(Transfers& log, cudaStream_t stream) {
  std::vector<BodyContactNode> out;
  if (rows_ == 0) return out;
  std::vector<BodyHit<T>> h(static_cast<std::size_t>(rows_));
  log.to_host(h.data(), hits_.data(), h.size() * sizeof(BodyHit<T>), stream);
  for (index_t r = 0; r < rows_; ++r)
    if (h[r].cand >= 0) out.push_back({lists_.node[r], lists_.cand_tri[h[r].cand], double(h[r].gap)});
  return out;
}

template class DeviceBodyContact<float>;
template class DeviceBodyContact<double>;
template void enqueue_body_step(const ModelView<float>&, const StateView<float>&, BodySteps<float>,
                                StepBuffers<float>, cudaStream_t);
template void enqueue_body_step(const ModelView<double>&, const StateView<double>&, BodySteps<double>,
                                StepBuffers<double>, cudaStream_t);
template void enqueue_body_check(const ModelView<float>&, const StateView<float>&, BodySteps<float>,
                                 const Packed3<float>*, cudaStream_t);
template void enqueue_body_check(const ModelView<double>&, const StateView<double>&, BodySteps<double>,
                                 const Packed3<double>*, cudaStream_t);

}  // namespace tissue::gpu
