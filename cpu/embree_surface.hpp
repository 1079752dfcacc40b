// The deformed tissue surface as an Embree 3 scene, for the tool-segment
// query of Backend::collide (DESIGN.md section 3, CPU variant). Private to
// cpu/: no Embree type leaves this header's implementation.
//
// One triangle geometry over the model's surface triangles. Its vertex
// buffer is shared with Embree and holds the deformed positions X + u of all
// nodes as float xyz (plus the 4 bytes of padding Embree reads past the last
// vertex); only surface nodes are written. The geometry's build quality is
// RTC_BUILD_QUALITY_REFIT: the BVH topology is built once from the first
// commit, later commits refit its boxes. The scene is refit before a query
// only when the displacements changed since the last one (mark_dirty()).
//
// Query: a ray from A with direction B - A, tnear 0, tfar 1 (so t is the
// fraction of |AB|). An intersect-filter callback collects every triangle
// the ray crosses (rejecting each hit so traversal continues), and each
// candidate is then re-intersected with core segment_triangle in the
// backend's precision: the winner is the smallest refined t, ties to the
// lowest triangle index, and t, barycentrics and the point come from the
// shared math. If Embree found candidates but none survives refinement (a
// graze along an edge or vertex that the two tests round differently), every
// surface triangle is tested with segment_triangle instead, which is the
// CUDA backend's brute-force rule.
#pragma once

#include <memory>
#include <vector>

#include "core/backend.hpp"
#include "core/model.hpp"

namespace tissue::cpu {

template <class T>
class EmbreeSurface {
 public:
  /// Builds the Embree device, scene and geometry over m's surface triangles
  /// (m must outlive this object). Throws std::runtime_error when Embree fails.
  explicit EmbreeSurface(const TissueModel<T>& m);
  ~EmbreeSurface();
  EmbreeSurface(const EmbreeSurface&) = delete;
  EmbreeSurface& operator=(const EmbreeSurface&) = delete;

  /// The displacements changed: refit before the next query.
  void mark_dirty() { dirty_ = true; }

  /// Segment a -> b (m) against the surface deformed by u (3 x n_nodes, m).
  /// a == b gives no hit. Throws std::invalid_argument for non-finite a or b.
  Hit query(const std::vector<T>& u, Vec3<double> a, Vec3<double> b);

  /// Number of refits done so far (tests: the scene is refit only when needed).
  long refits() const { return refits_; }

 private:
  struct Embree;  // RTCDevice, RTCScene, RTCGeometry
  void refit(const std::vector<T>& u);
  Vec3<T> position(const std::vector<T>& u, index_t i) const;
  /// segment_triangle of triangle t in T precision; < 0 = miss.
  T refine(const std::vector<T>& u, Vec3<T> a, Vec3<T> b, index_t t, T bary[2]) const;
  Hit make_hit(const std::vector<T>& u, Vec3<T> a, Vec3<T> b, index_t t) const;

  const TissueModel<T>& m_;
  std::unique_ptr<Embree> rtc_;
  std::vector<float> vertices_;         ///< (n_nodes x 3 + 1) float, deformed positions
  std::vector<unsigned> indices_;       ///< (n_tris x 3) triangle corners, interleaved
  std::vector<index_t> surface_nodes_;  ///< nodes used by a surface triangle, ascending
  bool dirty_ = true;
  long refits_ = 0;
};

}  // namespace tissue::cpu
