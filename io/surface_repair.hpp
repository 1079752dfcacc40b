// Surface repair and isotropic remeshing of imported organ surfaces, through
// CGAL's Polygon Mesh Processing (docs/meshing.md). Segmented and smoothed
// surfaces come with degenerate triangles, small self-intersections and
// holes; repair_surface() fixes what can be fixed safely and reports every
// change, and throws a MeshError saying why when it cannot. CGAL stays inside
// surface_repair.cpp: this header has no CGAL types.
#pragma once

#include <functional>
#include <string>

#include "io/surface_import.hpp"

namespace tissue::io {

/// What repair_surface() may do.
struct RepairOptions {
  /// Largest hole filled, as a fraction of the body's bounding-box diagonal
  /// (the hole boundary's own bounding-box diagonal); larger holes are an
  /// error (a cut-open organ is not a small segmentation gap).
  double max_hole_fraction = 0.25;
  /// Most intersecting triangle pairs repaired; more are an error (the
  /// surface is not an organ with a few folds but something else, e.g. two
  /// overlapping bodies in one file). 0 = no limit.
  long max_intersecting_pairs = 100000;
};

/// What repair_surface() changed. Counts are of the input as given.
struct RepairReport {
  long soup_points_merged = 0;       ///< duplicate points merged by the soup repair
  long soup_polygons_removed = 0;    ///< degenerate (repeated-corner) or duplicate triangles removed
  long non_manifold_vertices = 0;    ///< vertices duplicated to make the surface a manifold
  long degenerate_removed = 0;       ///< zero-area (collinear) triangles removed by edge collapse or flip
  long intersecting_pairs = 0;       ///< intersecting triangle pairs found before repair
  long intersecting_triangles = 0;   ///< triangles involved in them
  bool autorefined = false;          ///< self-intersections resolved by autorefinement (outer envelope kept)
  bool smoothed = false;             ///< resolved by local remeshing/smoothing (CGAL remove_self_intersections)
  long holes_filled = 0;
  long hole_triangles_added = 0;
  double largest_hole = 0;           ///< bounding-box diagonal of the largest hole filled (m)
  double max_moved = 0;              ///< largest distance of a repaired vertex from the input surface (m)
  bool reoriented = false;           ///< the faces were turned outward
  index_t triangles_before = 0, triangles_after = 0;

  /// True when the surface was changed.
  bool changed() const;
  /// Lines for the user, one per kind of change ("self-intersections: 12
  /// pairs (20 triangles) resolved by autorefinement; largest move 0 m").
  std::string summary() const;
};

/// Repairs the surface in place: polygon-soup repair (duplicate points,
/// repeated-corner and duplicate triangles), orientation and manifoldness
/// (non-manifold vertices duplicated), collinear triangles removed, holes up
/// to max_hole_fraction filled (triangulated, refined and faired), then
/// self-intersections removed (autorefinement, which keeps the outer
/// envelope and moves nothing; where that fails, CGAL's local remeshing),
/// and the faces turned outward. Throws MeshError starting with `source`
/// when the surface cannot be repaired: a hole too large (naming its size),
/// self-intersections that remain (naming how many and where), or a result
/// that is still not closed. A surface needing nothing is left unchanged.
RepairReport repair_surface(SurfaceMesh& surface, const RepairOptions& options, const std::string& source,
                            const Progress& progress = {});

/// Number of intersecting triangle pairs (CGAL self_intersections); 0 for a
/// clean surface. Throws MeshError when the surface is not a valid
/// triangle mesh (use check_closed() first).
long count_self_intersections(const SurfaceMesh& surface, const std::string& source);

/// Isotropic remeshing (CGAL isotropic_remeshing) of a closed surface to
/// edges of about `edge_length` (m, > 0), in `passes` passes (each one
/// split, collapse, flip, tangential relaxation), with one progress line per
/// pass; the result is projected on the input surface. Throws MeshError if
/// the result is not closed. Returns the number of triangles.
index_t remesh_surface(SurfaceMesh& surface, double edge_length, int passes, const std::string& source,
                       const Progress& progress = {});

/// Replaces a closed surface by its alpha wrap (CGAL alpha_wrap_3): the
/// boundary of the union of balls of radius `alpha` (m, > 0) rolled over
/// it, offset outward by `offset` (m, > 0). Grooves, folds and gaps
/// narrower than about alpha close, so a mesher no longer has to resolve
/// them; lobes thinner than about alpha / 2 lose their tips. The result is
/// closed, manifold and free of self-intersections. Returns the number of
/// triangles; throws MeshError naming `source` for bad sizes or a result
/// that is not closed.
index_t wrap_surface(SurfaceMesh& surface, double alpha, double offset, const std::string& source);

/// Mean edge length of the surface (m).
double mean_edge_length(const SurfaceMesh& surface);

}  // namespace tissue::io
