#include "cpu/embree_surface.hpp"

#include <embree3/rtcore.h>
#include <fmt/format.h>

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "core/tet.hpp"

namespace tissue::cpu {
namespace {

/// Most triangles one segment is expected to cross; beyond this the
/// candidates farthest from A are dropped (the nearest are kept).
constexpr int kMaxCandidates = 32;

struct Candidate {
  unsigned tri;
  float t;
};

/// Intersect context extended with the candidate list (the Embree "all
/// hits" pattern: RTCIntersectContext must be the first member).
struct CollectContext {
  RTCIntersectContext ctx;
  Candidate c[kMaxCandidates];
  int n = 0;

  void add(unsigned tri, float t) {
    for (int k = 0; k < n; ++k)
      if (c[k].tri == tri) return;
    if (n < kMaxCandidates) {
      c[n++] = {tri, t};
      return;
    }
    int far = 0;
    for (int k = 1; k < n; ++k)
      if (c[k].t > c[far].t) far = k;
    if (t < c[far].t) c[far] = {tri, t};
  }
};

/// Records every hit and rejects it, so traversal visits all crossings.
void collect_hits(const RTCFilterFunctionNArguments* args) {
  auto* cc = reinterpret_cast<CollectContext*>(args->context);
  for (unsigned i = 0; i < args->N; ++i) {
    if (args->valid[i] == 0) continue;
    cc->add(RTCHitN_primID(args->hit, args->N, i), RTCRayN_tfar(args->ray, args->N, i));
    args->valid[i] = 0;
  }
}

void throw_if_error(RTCDevice device, const char* what) {
  const RTCError err = rtcGetDeviceError(device);
  if (err != RTC_ERROR_NONE)
    throw std::runtime_error(fmt::format("cpu backend: Embree failed during {} (RTCError {})", what, int(err)));
}

}  // namespace

template <class T>
struct EmbreeSurface<T>::Embree {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  RTCGeometry geom = nullptr;
  ~Embree() {
    if (geom) rtcReleaseGeometry(geom);
    if (scene) rtcReleaseScene(scene);
    if (device) rtcReleaseDevice(device);
  }
};

template <class T>
EmbreeSurface<T>::EmbreeSurface(const TissueModel<T>& m) : m_(m), rtc_(std::make_unique<Embree>()) {
  const index_t n = m.n_nodes, nt = m.n_tris;
  if (nt < 1) throw std::runtime_error("cpu backend: the model has no surface triangles to collide with");
  vertices_.assign(3 * std::size_t(n) + 1, 0.0f);  // + 1: Embree loads each vertex as 16 bytes
  indices_.resize(3 * std::size_t(nt));
  std::vector<std::uint8_t> used(n, 0);
  for (index_t t = 0; t < nt; ++t)
    for (int v = 0; v < 3; ++v) {
      const index_t i = m.tris[v * nt + t];
      indices_[3 * t + v] = unsigned(i);
      used[i] = 1;
    }
  for (index_t i = 0; i < n; ++i)
    if (used[i]) surface_nodes_.push_back(i);

  Embree& r = *rtc_;
  r.device = rtcNewDevice(nullptr);
  if (!r.device)
    throw std::runtime_error(
        fmt::format("cpu backend: rtcNewDevice failed (RTCError {})", int(rtcGetDeviceError(nullptr))));
  r.scene = rtcNewScene(r.device);
  rtcSetSceneFlags(r.scene, RTC_SCENE_FLAG_DYNAMIC | RTC_SCENE_FLAG_ROBUST);
  rtcSetSceneBuildQuality(r.scene, RTC_BUILD_QUALITY_LOW);
  r.geom = rtcNewGeometry(r.device, RTC_GEOMETRY_TYPE_TRIANGLE);
  rtcSetGeometryBuildQuality(r.geom, RTC_BUILD_QUALITY_REFIT);
  rtcSetSharedGeometryBuffer(r.geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, vertices_.data(), 0,
                             3 * sizeof(float), std::size_t(n));
  rtcSetSharedGeometryBuffer(r.geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, indices_.data(), 0,
                             3 * sizeof(unsigned), std::size_t(nt));
  rtcSetGeometryIntersectFilterFunction(r.geom, collect_hits);
  rtcCommitGeometry(r.geom);
  rtcAttachGeometry(r.scene, r.geom);
  throw_if_error(r.device, "scene setup");
}

template <class T>
EmbreeSurface<T>::~EmbreeSurface() = default;

template <class T>
Vec3<T> EmbreeSurface<T>::position(const std::vector<T>& u, index_t i) const {
  const index_t n = m_.n_nodes;
  return {m_.X[i] + u[i], m_.X[n + i] + u[n + i], m_.X[2 * n + i] + u[2 * n + i]};
}

template <class T>
void EmbreeSurface<T>::refit(const std::vector<T>& u) {
  for (index_t i : surface_nodes_) {
    const Vec3<T> p = position(u, i);
    vertices_[3 * i] = float(p.x);
    vertices_[3 * i + 1] = float(p.y);
    vertices_[3 * i + 2] = float(p.z);
  }
  rtcUpdateGeometryBuffer(rtc_->geom, RTC_BUFFER_TYPE_VERTEX, 0);
  rtcCommitGeometry(rtc_->geom);
  rtcCommitScene(rtc_->scene);
  throw_if_error(rtc_->device, "the surface refit");
  dirty_ = false;
  ++refits_;
}

template <class T>
T EmbreeSurface<T>::refine(const std::vector<T>& u, Vec3<T> a, Vec3<T> b, index_t t, T bary[2]) const {
  const index_t nt = m_.n_tris;
  return segment_triangle(a, b, position(u, m_.tris[t]), position(u, m_.tris[nt + t]), position(u, m_.tris[2 * nt + t]),
                          bary);
}

template <class T>
Hit EmbreeSurface<T>::make_hit(const std::vector<T>& u, Vec3<T> a, Vec3<T> b, index_t t) const {
  const index_t n = m_.n_nodes, nt = m_.n_tris;
  T bary[2];
  Hit h;
  h.tri = t;
  h.t = double(refine(u, a, b, t, bary));
  h.bary[0] = double(bary[0]);
  h.bary[1] = double(bary[1]);
  Vec3<T> P[3];
  for (int k = 0; k < 3; ++k) {
    const index_t i = m_.tris[k * nt + t];
    h.nodes[k] = i;
    h.u[k] = {double(u[i]), double(u[n + i]), double(u[2 * n + i])};
    P[k] = position(u, i);
  }
  const Vec3<T> p = P[0] + bary[0] * (P[1] - P[0]) + bary[1] * (P[2] - P[0]);
  h.point = {double(p.x), double(p.y), double(p.z)};
  const Vec3<T> nrm = cross(P[1] - P[0], P[2] - P[0]);
  const Vec3<double> nd = {double(nrm.x), double(nrm.y), double(nrm.z)};
  h.normal = (1.0 / norm(nd)) * nd;
  return h;
}

template <class T>
Hit EmbreeSurface<T>::query(const std::vector<T>& u, Vec3<double> a, Vec3<double> b) {
  for (int c = 0; c < 3; ++c)
    if (!std::isfinite(a[c]) || !std::isfinite(b[c]))
      throw std::invalid_argument(fmt::format("collide: tool segment ({}, {}, {}) -> ({}, {}, {}) is not finite", a.x,
                                              a.y, a.z, b.x, b.y, b.z));
  if (a.x == b.x && a.y == b.y && a.z == b.z) return {};
  if (dirty_) refit(u);

  CollectContext cc;
  rtcInitIntersectContext(&cc.ctx);
  RTCRayHit rh;
  rh.ray.org_x = float(a.x);
  rh.ray.org_y = float(a.y);
  rh.ray.org_z = float(a.z);
  rh.ray.dir_x = float(b.x - a.x);
  rh.ray.dir_y = float(b.y - a.y);
  rh.ray.dir_z = float(b.z - a.z);
  rh.ray.tnear = 0.0f;
  rh.ray.tfar = 1.0f + 1e-5f;  // a little past B: refinement applies the exact t <= 1
  rh.ray.time = 0.0f;
  rh.ray.mask = ~0u;
  rh.ray.id = 0;
  rh.ray.flags = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(rtc_->scene, &cc.ctx, &rh);
  if (cc.n == 0) return {};

  const Vec3<T> aT = {T(a.x), T(a.y), T(a.z)}, bT = {T(b.x), T(b.y), T(b.z)};
  index_t best = -1;
  T best_t = std::numeric_limits<T>::infinity();
  auto consider = [&](index_t t) {
    T bary[2];
    const T s = refine(u, aT, bT, t, bary);
    if (s >= T(0) && (s < best_t || (s == best_t && t < best))) {
      best = t;
      best_t = s;
    }
  };
  for (int k = 0; k < cc.n; ++k) consider(index_t(cc.c[k].tri));
  if (best < 0)  // Embree and segment_triangle disagree on a graze: brute force
    for (index_t t = 0; t < m_.n_tris; ++t) consider(t);
  if (best < 0) return {};
  return make_hit(u, aT, bT, best);
}

template class EmbreeSurface<float>;
template class EmbreeSurface<double>;

}  // namespace tissue::cpu
