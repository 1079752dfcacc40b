// The deformed tissue surface as an Embree 3 BVH for the contact stage's
// box queries (docs/contact.md, cpu backend). Private to cpu/: no Embree
// type leaves this header's implementation.
//
// One Embree user geometry: one primitive per surface triangle, whose
// bounds are the triangle's box at the last build fattened by `margin` on
// every side. The BVH stays valid while no surface node has moved more than
// the margin (in any coordinate) from where it was at the build, because
// each triangle then still lies in its fattened box; only then is it
// rebuilt (no refit of the whole surface per query). Checking that is
// O(surface nodes) when anything may have moved (the first query, after
// invalidate()); otherwise only the nodes the caller says can have moved
// since the last check -- the region's, since nodes outside it are held --
// are checked: O(region), not O(surface), per query (a 100k
// triangle surface spent half its contact step in the full check). A query is an axis-aligned box: Embree's point query
// (a sphere enclosing the box) walks the BVH, and each primitive it reports
// is kept when its fattened box overlaps the query box.
#pragma once

#include <memory>
#include <span>
#include <vector>

#include "core/model.hpp"

namespace tissue::cpu {

/// Axis-aligned box (m).
struct Box {
  double lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0};
  bool empty = true;
  void add(const double p[3], double pad);
};

template <class T>
class SurfaceBvh {
 public:
  /// Over m's surface triangles (m must outlive this object), fattened by
  /// margin (m) > 0. Throws std::runtime_error when Embree fails.
  SurfaceBvh(const TissueModel<T>& m, double margin);
  ~SurfaceBvh();
  SurfaceBvh(const SurfaceBvh&) = delete;
  SurfaceBvh& operator=(const SurfaceBvh&) = delete;

  /// Makes the BVH valid for the surface deformed by u (3 x n_nodes, m):
  /// rebuilds it when a surface node has left its margin. Checks every
  /// surface node.
  void update(const T* u);
  /// The same, checking only the nodes of `moved` (any order; non-surface
  /// nodes are skipped) -- the caller's promise that no other node has
  /// moved since the last update -- unless invalidate() was called since,
  /// when every surface node is checked.
  void update(const T* u, std::span<const index_t> moved);
  /// Whether a surface node of `nodes` has left its margin in u since the
  /// last build (update's test; false before the first build). Const, so
  /// that the members of a team can check their shares of the moved nodes
  /// at once.
  bool left_margin(const T* u, std::span<const index_t> nodes) const;
  /// update(u, moved) for a caller that has checked every node of `moved`
  /// with left_margin: `left` is whether any had left.
  void update_checked(const T* u, bool left);
  /// The next update() checks every surface node (after a change of u that
  /// is not confined to the nodes it will be given).
  void invalidate() { full_check_ = true; }

  /// Surface triangles whose fattened box overlaps `box`, ascending, into
  /// out (cleared first). Call update() for the current u first.
  void query(const Box& box, std::vector<index_t>& out);

  /// A superset of query(box): the triangles whose fattened box overlaps
  /// `box` padded by the skin (set_skin) on every side. They are those of
  /// the last such query while its padded box still holds `box`, reaches at
  /// most 2 skins beyond it, and the BVH has not been rebuilt since (a
  /// fattened box does not change between builds); otherwise the padded box
  /// is queried and kept. A tool that moves less than the skin between
  /// steps thus walks the BVH once per skin's travel, not per step (the
  /// Verlet skin of particle neighbour lists). Skin 0: query(box) every
  /// time. Call update() for the current u first.
  const std::vector<index_t>& query_within_skin(const Box& box);
  /// The skin (m, >= 0; default 0) of query_within_skin.
  void set_skin(double skin);
  /// BVH walks query_within_skin has made (tests, benchmarks).
  long skin_queries() const { return skin_queries_; }

  double margin() const { return margin_; }
  /// BVH builds so far (tests: rebuilt only when the surface left the margin).
  long builds() const { return builds_; }

 private:
  struct Embree;  // RTCDevice, RTCScene, RTCGeometry
  void build(const T* u);

  const TissueModel<T>& m_;
  double margin_;
  std::unique_ptr<Embree> rtc_;
  std::vector<double> at_build_;  ///< surface node positions at the last build (n_surf x 3)
  std::vector<float> boxes_;      ///< fattened triangle boxes (n_tris x 6: lo xyz, hi xyz)
  std::vector<index_t> surf_index_;  ///< node -> its surface index, -1 off the surface (n_nodes)
  long builds_ = 0;
  double skin_ = 0;                  ///< set_skin
  Box kept_box_;                     ///< the padded box of query_within_skin's last walk (empty after a build)
  std::vector<index_t> kept_;        ///< its triangles, ascending
  long skin_queries_ = 0;
  bool built_ = false;
  bool full_check_ = true;
};

}  // namespace tissue::cpu
