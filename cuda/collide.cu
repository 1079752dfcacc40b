#include "cuda/collide.hpp"

#include <cub/device/device_reduce.cuh>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <cuda/std/limits>

#include "core/tet.hpp"
#include "cuda/launch.cuh"
#include "cuda/text.hpp"

namespace tissue::gpu {
namespace {

template <class T>
__device__ void triangle_corners(const ModelView<T>& m, const Packed3<T>* u, index_t t, index_t c[3], Vec3<T> P[3]) {
#pragma unroll
  for (int k = 0; k < 3; ++k) {
    c[k] = m.tris[k * m.n_tris + t];
    P[k] = m.X[c[k]].vec() + u[c[k]].vec();
  }
}

template <class T>
__global__ void hit_distance_kernel(ModelView<T> m, const Packed3<T>* u, Vec3<T> a, Vec3<T> b, T* key) {
  const index_t t = thread_index();
  if (t >= m.n_tris) return;
  index_t c[3];
  Vec3<T> P[3];
  triangle_corners(m, u, t, c, P);
  T bary[2];
  const T s = segment_triangle(a, b, P[0], P[1], P[2], bary);
  key[t] = s >= T(0) ? s : ::cuda::std::numeric_limits<T>::infinity();
}

template <class T>
__global__ void finish_hit_kernel(ModelView<T> m, const Packed3<T>* u, Vec3<T> aT, Vec3<T> bT, const T* key,
                                  const std::int64_t* index, Hit* out) {
  Hit h;
  const std::int64_t t = *index;
  if (t >= 0 && t < m.n_tris && key[t] < ::cuda::std::numeric_limits<T>::infinity()) {
    index_t c[3];
    Vec3<T> P[3];
    triangle_corners(m, u, static_cast<index_t>(t), c, P);
    T bary[2] = {T(0), T(0)};
    const T s = segment_triangle(aT, bT, P[0], P[1], P[2], bary);
    h.tri = static_cast<index_t>(t);
    h.t = s;
    h.bary[0] = bary[0];
    h.bary[1] = bary[1];
    for (int k = 0; k < 3; ++k) {
      h.nodes[k] = c[k];
      const Packed3<T> uk = u[c[k]];
      h.u[k] = {double(uk.x), double(uk.y), double(uk.z)};
    }
    // point and normal in T, as the cpu backend computes them
    const Vec3<T> p = P[0] + bary[0] * (P[1] - P[0]) + bary[1] * (P[2] - P[0]);
    h.point = {double(p.x), double(p.y), double(p.z)};
    const Vec3<T> nrm = cross(P[1] - P[0], P[2] - P[0]);
    const Vec3<double> nd = {double(nrm.x), double(nrm.y), double(nrm.z)};
    h.normal = (1.0 / norm(nd)) * nd;
  }
  *out = h;
}

}  // namespace

template <class T>
void Collider<T>::allocate(index_t n_tris) {
  key_.allocate(n_tris);
  min_key_.allocate(1);
  min_index_.allocate(1);
  hit_.allocate(1);
  hit_host_.allocate(1);
  size_t bytes = 0;
  if (n_tris > 0)
    CUDA_CHECK(cub::DeviceReduce::ArgMin(nullptr, bytes, key_.data(), min_key_.data(), min_index_.data(), n_tris));
  cub_temp_.allocate(std::max<size_t>(bytes, 1));
}

template <class T>
Hit Collider<T>::query(const ModelView<T>& m, const Packed3<T>* u, Vec3<double> a, Vec3<double> b, Transfers& log,
                       cudaStream_t stream) {
  for (int c = 0; c < 3; ++c)
    if (!std::isfinite(a[c]) || !std::isfinite(b[c]))
      throw std::invalid_argument(str("collide: tool segment (", a.x, ", ", a.y, ", ", a.z, ") -> (", b.x, ", ", b.y,
                                      ", ", b.z, ") is not finite"));
  if (m.n_tris == 0 || (a.x == b.x && a.y == b.y && a.z == b.z)) return Hit{};
  const Vec3<T> aT = {T(a.x), T(a.y), T(a.z)}, bT = {T(b.x), T(b.y), T(b.z)};
  launch(m.n_tris, stream, hit_distance_kernel<T>, m, u, aT, bT, key_.data());
  size_t bytes = cub_temp_.bytes();
  CUDA_CHECK(cub::DeviceReduce::ArgMin(cub_temp_.data(), bytes, key_.data(), min_key_.data(), min_index_.data(),
                                       m.n_tris, stream));
  launch(1, stream, finish_hit_kernel<T>, m, u, aT, bT, key_.data(), min_index_.data(), hit_.data());
  log.to_host(hit_host_.data(), hit_.data(), sizeof(Hit), stream);
  return hit_host_[0];
}

template class Collider<float>;
template class Collider<double>;

}  // namespace tissue::gpu
