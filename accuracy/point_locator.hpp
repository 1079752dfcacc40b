// Point location in a tetrahedral mesh and P1 field sampling, for comparing
// answers computed on different meshes of the same body (the tradeoff's mesh
// rows against the finest mesh's reference) and for moving constraints and
// element sets onto a re-meshed body.
//
// A uniform grid over the mesh's bounding box (about one tet per cell) lists
// the tets whose bounding box overlaps each cell. A query tests the tets of
// the point's cell, then of the 26 neighbouring cells; the tet with the
// largest smallest barycentric coordinate wins, so a point inside the mesh
// gets the tet that contains it and a point just outside (the boundary of a
// different discretisation of the same surface, off by rounding or by a
// facet's chord) gets the nearest tet, whose barycentric coordinates are
// then clamped to >= 0 and renormalised.
#pragma once

#include <array>
#include <span>
#include <vector>

#include "core/model.hpp"
#include "core/vec.hpp"

namespace tissue::accuracy {

/// Where a point lies in a mesh.
struct Location {
  index_t elem = -1;                 ///< containing (or nearest) element; -1 = no element near the point
  std::array<double, 4> bary = {};   ///< barycentric coordinates of its corners (clamped >= 0, sum 1)
  double outside = 0;                ///< -(smallest raw barycentric) when the point is outside elem, else 0
};

class PointLocator {
 public:
  /// Indexes the reference configuration of `model` (kept by reference: it
  /// must outlive the locator).
  explicit PointLocator(const TissueModel<double>& model);

  /// Locates the point p (m).
  Location locate(Vec3<double> p) const;

 private:
  std::array<int, 3> cell_of(Vec3<double> p) const;
  double raw_bary(index_t e, Vec3<double> p, std::array<double, 4>& b) const;

  const TissueModel<double>& m_;
  Vec3<double> lo_ = {}, size_ = {};  ///< grid origin and cell size (m)
  int n_[3] = {1, 1, 1};              ///< cells per axis
  std::vector<index_t> start_;        ///< CSR offsets per cell (n_cells + 1)
  std::vector<index_t> elems_;        ///< tets overlapping each cell
};

/// Largest Location::outside sample_field accepts: a point at most about
/// half an element beyond the mesh (another discretisation's boundary).
inline constexpr double kMaxOutside = 0.5;

/// Samples the P1 field (3 x n_nodes of `model`, component-major) at
/// `points` (n_points x 3, xyz interleaved, m). Returns (3 x n_points,
/// component-major). Throws std::runtime_error naming the point when it
/// lies outside the mesh by more than kMaxOutside.
std::vector<double> sample_field(const TissueModel<double>& model, std::span<const double> field,
                                 std::span<const double> points);

}  // namespace tissue::accuracy
