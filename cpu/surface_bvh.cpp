#include "cpu/surface_bvh.hpp"

#include <embree3/rtcore.h>
#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace tissue::cpu {
namespace {

void throw_if_error(RTCDevice device, const char* what) {
  const RTCError err = rtcGetDeviceError(device);
  if (err != RTC_ERROR_NONE)
    throw std::runtime_error(fmt::format("cpu backend: Embree failed during {} (RTCError {})", what, int(err)));
}

void bounds_of(const RTCBoundsFunctionArguments* args) {
  const float* b = static_cast<const float*>(args->geometryUserPtr) + 6 * std::size_t(args->primID);
  RTCBounds* o = args->bounds_o;
  o->lower_x = b[0];
  o->lower_y = b[1];
  o->lower_z = b[2];
  o->upper_x = b[3];
  o->upper_y = b[4];
  o->upper_z = b[5];
}

/// What a point query collects: the boxes, the query box and the hits.
struct Collect {
  const float* boxes;
  const Box* box;
  std::vector<index_t>* out;
};

bool collect(RTCPointQueryFunctionArguments* args) {
  auto* c = static_cast<Collect*>(args->userPtr);
  const float* b = c->boxes + 6 * std::size_t(args->primID);
  for (int k = 0; k < 3; ++k)
    if (b[k] > c->box->hi[k] || b[3 + k] < c->box->lo[k]) return false;
  c->out->push_back(static_cast<index_t>(args->primID));
  return false;  // the query radius is unchanged
}

}  // namespace

void Box::add(const double p[3], double pad) {
  for (int k = 0; k < 3; ++k) {
    lo[k] = empty ? p[k] - pad : std::min(lo[k], p[k] - pad);
    hi[k] = empty ? p[k] + pad : std::max(hi[k], p[k] + pad);
  }
  empty = false;
}

template <class T>
struct SurfaceBvh<T>::Embree {
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
SurfaceBvh<T>::SurfaceBvh(const TissueModel<T>& m, double margin)
    : m_(m), margin_(margin), rtc_(std::make_unique<Embree>()) {
  if (!(margin > 0) || !std::isfinite(margin))
    throw std::invalid_argument(fmt::format("cpu backend: surface BVH margin {} m must be > 0", margin));
  at_build_.assign(3 * std::size_t(m.n_surf), 0.0);
  surf_index_.assign(std::size_t(m.n_nodes), -1);
  for (index_t i = 0; i < m.n_surf; ++i) surf_index_[m.surf_nodes[i]] = i;
  boxes_.assign(6 * std::size_t(m.n_tris), 0.0f);
  if (m.n_tris == 0) return;
  // default configuration: "threads=1" made Embree (built on TBB) cap the whole process at one TBB
  // thread, serialising every element pass (measured: the kidney step 1.5-2.2x slower on 2 cores)
  rtc_->device = rtcNewDevice(nullptr);
  if (!rtc_->device) throw std::runtime_error("cpu backend: Embree could not create a device");
  rtc_->scene = rtcNewScene(rtc_->device);
  rtcSetSceneFlags(rtc_->scene, RTC_SCENE_FLAG_DYNAMIC);
  rtcSetSceneBuildQuality(rtc_->scene, RTC_BUILD_QUALITY_LOW);
  rtc_->geom = rtcNewGeometry(rtc_->device, RTC_GEOMETRY_TYPE_USER);
  rtcSetGeometryUserPrimitiveCount(rtc_->geom, static_cast<unsigned>(m.n_tris));
  rtcSetGeometryUserData(rtc_->geom, boxes_.data());  // the bounds callback reads it as geometryUserPtr
  rtcSetGeometryBoundsFunction(rtc_->geom, bounds_of, nullptr);
  rtcAttachGeometry(rtc_->scene, rtc_->geom);
  throw_if_error(rtc_->device, "creating the surface geometry");
}

template <class T>
SurfaceBvh<T>::~SurfaceBvh() = default;

template <class T>
void SurfaceBvh<T>::build(const T* u) {
  const index_t n = m_.n_nodes, nt = m_.n_tris;
  for (index_t i = 0; i < m_.n_surf; ++i) {
    const index_t a = m_.surf_nodes[i];
    for (int c = 0; c < 3; ++c) at_build_[3 * std::size_t(i) + c] = double(m_.X[c * n + a]) + double(u[c * n + a]);
  }
  for (index_t t = 0; t < nt; ++t) {
    float* b = boxes_.data() + 6 * std::size_t(t);
    for (int c = 0; c < 3; ++c) {
      double lo = INFINITY, hi = -INFINITY;
      for (int k = 0; k < 3; ++k) {
        const index_t a = m_.tris[k * nt + t];
        const double x = double(m_.X[c * n + a]) + double(u[c * n + a]);
        lo = std::min(lo, x);
        hi = std::max(hi, x);
      }
      // rounded outward to float, so the float box contains the double one
      b[c] = std::nextafter(float(lo - margin_), -INFINITY);
      b[3 + c] = std::nextafter(float(hi + margin_), INFINITY);
    }
  }
  rtcCommitGeometry(rtc_->geom);
  rtcCommitScene(rtc_->scene);
  throw_if_error(rtc_->device, "building the surface BVH");
  ++builds_;
  built_ = true;
  kept_box_ = Box{};  // query_within_skin's triangles were found in the old boxes
}

template <class T>
void SurfaceBvh<T>::update(const T* u) {
  if (m_.n_tris == 0) return;
  full_check_ = false;
  if (!built_) return build(u);
  const index_t n = m_.n_nodes;
  for (index_t i = 0; i < m_.n_surf; ++i) {
    const index_t a = m_.surf_nodes[i];
    for (int c = 0; c < 3; ++c) {
      const double x = double(m_.X[c * n + a]) + double(u[c * n + a]);
      if (!(std::fabs(x - at_build_[3 * std::size_t(i) + c]) <= margin_)) return build(u);
    }
  }
}

template <class T>
void SurfaceBvh<T>::update(const T* u, std::span<const index_t> moved) {
  if (m_.n_tris == 0) return;
  update_checked(u, !full_check_ && left_margin(u, moved));  // (a full check needs no partial one)
}

template <class T>
bool SurfaceBvh<T>::left_margin(const T* u, std::span<const index_t> nodes) const {
  if (m_.n_tris == 0 || !built_) return false;
  const index_t n = m_.n_nodes;
  for (index_t a : nodes) {
    const index_t i = surf_index_[a];
    if (i < 0) continue;
    for (int c = 0; c < 3; ++c) {
      const double x = double(m_.X[c * n + a]) + double(u[c * n + a]);
      if (!(std::fabs(x - at_build_[3 * std::size_t(i) + c]) <= margin_)) return true;
    }
  }
  return false;
}

template <class T>
void SurfaceBvh<T>::update_checked(const T* u, bool left) {
  if (m_.n_tris == 0) return;
  if (full_check_ || !built_) return update(u);
  if (left) build(u);
}

template <class T>
void SurfaceBvh<T>::query(const Box& box, std::vector<index_t>& out) {
  out.clear();
  if (m_.n_tris == 0 || box.empty || !built_) return;
  RTCPointQuery q;
  double r2 = 0;
  for (int k = 0; k < 3; ++k) r2 += 0.25 * (box.hi[k] - box.lo[k]) * (box.hi[k] - box.lo[k]);
  q.x = float(0.5 * (box.lo[0] + box.hi[0]));
  q.y = float(0.5 * (box.lo[1] + box.hi[1]));
  q.z = float(0.5 * (box.lo[2] + box.hi[2]));
  q.time = 0;
  q.radius = std::nextafter(float(std::sqrt(r2)), INFINITY) * 1.0001f;  // encloses the box despite float rounding
  RTCPointQueryContext ctx;
  rtcInitPointQueryContext(&ctx);
  Collect c{boxes_.data(), &box, &out};
  rtcPointQuery(rtc_->scene, &q, &ctx, collect, &c);
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
}

template <class T>
void SurfaceBvh<T>::set_skin(double skin) {
  if (!(skin >= 0) || !std::isfinite(skin))
    throw std::invalid_argument(fmt::format("cpu backend: surface BVH query skin {} m must be >= 0", skin));
  skin_ = skin;
  kept_box_ = Box{};
}

template <class T>
const std::vector<index_t>& SurfaceBvh<T>::query_within_skin(const Box& box) {
  // reused while the padded box holds `box` and is not much larger than it (after one large box --
  // a fast tool's step -- the smaller boxes that follow would otherwise keep sweeping its triangles)
  bool holds = skin_ > 0 && !box.empty && !kept_box_.empty;
  for (int k = 0; k < 3 && holds; ++k)
    holds = kept_box_.lo[k] <= box.lo[k] && box.hi[k] <= kept_box_.hi[k] && box.lo[k] - kept_box_.lo[k] <= 2 * skin_ &&
            kept_box_.hi[k] - box.hi[k] <= 2 * skin_;
  if (holds) return kept_;
  kept_box_ = Box{};
  if (!box.empty) {
    kept_box_.add(box.lo, skin_);
    kept_box_.add(box.hi, skin_);
  }
  query(kept_box_, kept_);
  if (!built_) kept_box_ = Box{};  // nothing to keep before the first build
  ++skin_queries_;
  return kept_;
}

template class SurfaceBvh<float>;
template class SurfaceBvh<double>;

}  // namespace tissue::cpu
