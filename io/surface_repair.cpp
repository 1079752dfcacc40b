// The one translation unit that includes CGAL's Polygon Mesh Processing
// (header-heavy: keep it to this file). Kernel: exact predicates, inexact
// constructions (EPICK), the kernel PMP's repair and remeshing are written
// for; autorefinement computes its intersection points exactly internally.
#include "io/surface_repair.hpp"

#include <CGAL/AABB_face_graph_triangle_primitive.h>
#include <CGAL/AABB_traits.h>
#include <CGAL/AABB_tree.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/border.h>
#include <CGAL/Polygon_mesh_processing/measure.h>
#include <CGAL/Polygon_mesh_processing/corefinement.h>
#include <CGAL/Polygon_mesh_processing/orient_polygon_soup.h>
#include <CGAL/Polygon_mesh_processing/orientation.h>
#include <CGAL/Polygon_mesh_processing/polygon_soup_to_polygon_mesh.h>
#include <CGAL/Polygon_mesh_processing/remesh.h>
#include <CGAL/Polygon_mesh_processing/repair_degeneracies.h>
#include <CGAL/Polygon_mesh_processing/repair_polygon_soup.h>
#include <CGAL/Polygon_mesh_processing/repair_self_intersections.h>
#include <CGAL/Polygon_mesh_processing/self_intersections.h>
#include <CGAL/Polygon_mesh_processing/shape_predicates.h>
#include <CGAL/Polygon_mesh_processing/triangulate_hole.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/alpha_wrap_3.h>
#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <set>
#include <vector>

namespace tissue::io {
namespace {

namespace PMP = CGAL::Polygon_mesh_processing;
using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = Kernel::Point_3;
using Mesh = CGAL::Surface_mesh<Point>;
using face_descriptor = Mesh::Face_index;
using halfedge_descriptor = Mesh::Halfedge_index;
using vertex_descriptor = Mesh::Vertex_index;
using Triangle = std::array<std::size_t, 3>;

/// The surface as a polygon soup (points, triangles).
void to_soup(const SurfaceMesh& s, std::vector<Point>& points, std::vector<Triangle>& tris) {
  points.clear();
  tris.clear();
  for (index_t v = 0; v < s.n_vertices(); ++v)
    points.emplace_back(s.vertices[3 * v], s.vertices[3 * v + 1], s.vertices[3 * v + 2]);
  for (index_t t = 0; t < s.n_triangles(); ++t)
    tris.push_back({std::size_t(s.triangles[3 * t]), std::size_t(s.triangles[3 * t + 1]),
                    std::size_t(s.triangles[3 * t + 2])});
}

/// A clean, manifold soup as a CGAL surface mesh; throws if CGAL refuses it.
Mesh soup_to_mesh(const std::vector<Point>& points, const std::vector<Triangle>& tris, const std::string& source) {
  Mesh m;
  if (!PMP::is_polygon_soup_a_polygon_mesh(tris))
    throw MeshError(source + ": the triangles do not form a manifold surface even after repair");
  PMP::polygon_soup_to_polygon_mesh(points, tris, m);
  return m;
}

/// A valid triangle surface (every corner in range, no repeated corner,
/// manifold) as a CGAL mesh; throws otherwise.
Mesh to_mesh(const SurfaceMesh& s, const std::string& source) {
  std::vector<Point> points;
  std::vector<Triangle> tris;
  to_soup(s, points, tris);
  for (const Triangle& t : tris)
    for (std::size_t c : t)
      if (c >= points.size()) throw MeshError(fmt::format("{}: a triangle refers to vertex {} of {}", source, c, points.size()));
  return soup_to_mesh(points, tris, source);
}

SurfaceMesh from_mesh(Mesh m) {
  m.collect_garbage();
  SurfaceMesh s;
  s.vertices.reserve(3 * m.number_of_vertices());
  for (vertex_descriptor v : m.vertices()) {
    const Point& p = m.point(v);
    s.vertices.insert(s.vertices.end(), {p.x(), p.y(), p.z()});
  }
  s.triangles.reserve(3 * m.number_of_faces());
  for (face_descriptor f : m.faces())
    for (vertex_descriptor v : CGAL::vertices_around_face(m.halfedge(f), m)) s.triangles.push_back(index_t(v.idx()));
  return s;
}

double bbox_diagonal(const Mesh& m) {
  const CGAL::Bbox_3 b = PMP::bbox(m);
  return std::sqrt(CGAL::square(b.xmax() - b.xmin()) + CGAL::square(b.ymax() - b.ymin()) +
                   CGAL::square(b.zmax() - b.zmin()));
}

std::string point_text(const Point& p) { return fmt::format("({:.4g}, {:.4g}, {:.4g}) m", p.x(), p.y(), p.z()); }

/// Soup-level repair: duplicate points, repeated-corner and duplicate
/// triangles, orientation, non-manifold vertices.
Mesh repair_soup(const SurfaceMesh& s, RepairReport& r, const std::string& source) {
  std::vector<Point> points;
  std::vector<Triangle> tris;
  to_soup(s, points, tris);
  const std::size_t np = points.size(), nt = tris.size();
  std::vector<std::vector<std::size_t>> polys;
  for (const Triangle& t : tris) polys.push_back({t[0], t[1], t[2]});
  PMP::repair_polygon_soup(points, polys);
  r.soup_polygons_removed = long(nt) - long(polys.size());
  const std::size_t np_clean = points.size();
  r.soup_points_merged = std::max(0L, long(np) - long(np_clean));
  if (polys.empty()) throw MeshError(source + ": every triangle is degenerate or duplicated");
  PMP::orient_polygon_soup(points, polys);
  r.non_manifold_vertices = long(points.size()) - long(np_clean);
  tris.clear();
  for (const auto& p : polys) {
    if (p.size() != 3) throw MeshError(fmt::format("{}: the repaired soup holds a {}-gon", source, p.size()));
    tris.push_back({p[0], p[1], p[2]});
  }
  return soup_to_mesh(points, tris, source);
}

double face_area(const Mesh& m, face_descriptor f) {
  const halfedge_descriptor h = m.halfedge(f);
  return std::sqrt(CGAL::squared_area(m.point(m.source(h)), m.point(m.target(h)), m.point(m.target(m.next(h)))));
}

/// One pass over the faces of (nearly) zero area, with the tolerance
/// check_closed() applies (1e-14 times the squared bounding-box diagonal):
/// a cap (one angle near 180 degrees) has its long edge flipped, a needle
/// (one edge near zero) has that edge collapsed. Returns the faces fixed.
long fix_thin_faces(Mesh& m, double area_eps) {
  long fixed = 0;
  std::vector<face_descriptor> thin;
  for (face_descriptor f : m.faces())
    if (face_area(m, f) <= area_eps) thin.push_back(f);
  for (face_descriptor f : thin) {
    if (m.is_removed(f) || face_area(m, f) > area_eps) continue;
    // the longest edge and the shortest edge of the face
    halfedge_descriptor longest = m.halfedge(f), shortest = longest;
    for (halfedge_descriptor h : CGAL::halfedges_around_face(m.halfedge(f), m)) {
      const double l = CGAL::squared_distance(m.point(m.source(h)), m.point(m.target(h)));
      if (l > CGAL::squared_distance(m.point(m.source(longest)), m.point(m.target(longest)))) longest = h;
      if (l < CGAL::squared_distance(m.point(m.source(shortest)), m.point(m.target(shortest)))) shortest = h;
    }
    const double lmax = std::sqrt(CGAL::squared_distance(m.point(m.source(longest)), m.point(m.target(longest))));
    const double lmin = std::sqrt(CGAL::squared_distance(m.point(m.source(shortest)), m.point(m.target(shortest))));
    if (lmin <= 1e-3 * lmax && CGAL::Euler::does_satisfy_link_condition(m.edge(shortest), m)) {
      CGAL::Euler::collapse_edge(m.edge(shortest), m);  // needle
      ++fixed;
      continue;
    }
    const halfedge_descriptor o = m.opposite(longest);
    if (m.is_border(o)) continue;
    const vertex_descriptor c = m.target(m.next(longest)), d = m.target(m.next(o));
    if (c == d || CGAL::halfedge(c, d, m).second) continue;  // the flipped edge exists already
    CGAL::Euler::flip_edge(longest, m);  // cap
    ++fixed;
  }
  return fixed;
}

void remove_degenerate(Mesh& m, RepairReport& r) {
  const double diag = bbox_diagonal(m);
  const double area_eps = 1e-14 * diag * diag;
  long n = 0;
  for (face_descriptor f : m.faces()) n += face_area(m, f) <= area_eps ? 1 : 0;
  if (n == 0) return;
  for (int pass = 0; pass < 8; ++pass)
    if (fix_thin_faces(m, area_eps) == 0) break;
  PMP::remove_degenerate_faces(m);  // exactly collinear ones the passes could not fix
  m.collect_garbage();
  r.degenerate_removed = n;
}

void fill_holes(Mesh& m, const RepairOptions& o, RepairReport& r, const std::string& source) {
  std::vector<halfedge_descriptor> cycles;
  PMP::extract_boundary_cycles(m, std::back_inserter(cycles));
  const double body = bbox_diagonal(m);
  for (halfedge_descriptor h : cycles) {
    CGAL::Bbox_3 box;
    long edges = 0;
    for (halfedge_descriptor e : CGAL::halfedges_around_face(h, m)) {
      box += m.point(m.source(e)).bbox();
      ++edges;
    }
    const double size = std::sqrt(CGAL::square(box.xmax() - box.xmin()) + CGAL::square(box.ymax() - box.ymin()) +
                                  CGAL::square(box.zmax() - box.zmin()));
    if (size > o.max_hole_fraction * body)
      throw MeshError(fmt::format(
          "{}: the surface has a hole of {} edges, {:.4g} m across near {} ({:.0f} % of the body's {:.4g} m "
          "diagonal; holes up to {:.0f} % are filled): it is open, not a closed organ surface with a small gap",
          source, edges, size, point_text(m.point(m.source(h))), 100 * size / body, body, 100 * o.max_hole_fraction));
    std::vector<face_descriptor> faces;
    std::vector<vertex_descriptor> verts;
    const bool faired = std::get<0>(
        PMP::triangulate_refine_and_fair_hole(m, h, std::back_inserter(faces), std::back_inserter(verts)));
    if (faces.empty())
      throw MeshError(fmt::format("{}: the hole of {} edges near {} could not be triangulated", source, edges,
                                  point_text(m.point(m.source(h)))));
    (void)faired;  // an unfaired (flat, refined) patch still closes the hole
    ++r.holes_filled;
    r.hole_triangles_added += long(faces.size());
    r.largest_hole = std::max(r.largest_hole, size);
  }
}

/// Where the remaining self-intersections are, for the error message.
std::string intersection_text(const Mesh& m, const std::vector<std::pair<face_descriptor, face_descriptor>>& pairs) {
  std::set<face_descriptor> faces;
  for (const auto& [a, b] : pairs) faces.insert({a, b});
  const Point p = m.point(m.target(m.halfedge(pairs.front().first)));
  return fmt::format("{} intersecting triangle pairs ({} triangles) remain, e.g. near {}", pairs.size(), faces.size(),
                     point_text(p));
}

/// Largest distance of a vertex of `after` from the surface `before` (m).
double max_distance(const Mesh& after, const Mesh& before) {
  using Primitive = CGAL::AABB_face_graph_triangle_primitive<Mesh>;
  using Tree = CGAL::AABB_tree<CGAL::AABB_traits<Kernel, Primitive>>;
  Tree tree(faces(before).first, faces(before).second, before);
  tree.accelerate_distance_queries();
  double d2 = 0;
  for (vertex_descriptor v : after.vertices()) d2 = std::max(d2, tree.squared_distance(after.point(v)));
  return std::sqrt(d2);
}

/// Largest relative change of the enclosed volume an autorefinement may
/// make. The divergence-theorem volume of a self-intersecting surface counts
/// an overlap twice and the union once, so overlaps up to this fraction of
/// the body are kept as their union; a larger change means the patches kept
/// are the wrong ones.
constexpr double kVolumeKept = 0.25;

void remove_intersections(Mesh& m, const RepairOptions& o, RepairReport& r, const std::string& source,
                          const Progress& progress) {
  std::vector<std::pair<face_descriptor, face_descriptor>> pairs;
  PMP::self_intersections(m, std::back_inserter(pairs));
  if (pairs.empty()) return;
  std::set<face_descriptor> involved;
  for (const auto& [a, b] : pairs) involved.insert({a, b});
  r.intersecting_pairs = long(pairs.size());
  r.intersecting_triangles = long(involved.size());
  if (o.max_intersecting_pairs > 0 && r.intersecting_pairs > o.max_intersecting_pairs)
    throw MeshError(fmt::format(
        "{}: the surface intersects itself in {} triangle pairs (more than the {} a repair attempts): it is not "
        "one organ with a few folds (two overlapping bodies in one file?)",
        source, pairs.size(), o.max_intersecting_pairs));
  if (progress)
    progress(fmt::format("repair: {} intersecting triangle pairs ({} triangles)", pairs.size(), involved.size()));
  const Mesh before = m;
  // 1. autorefinement: cut the triangles along their intersections and keep
  //    the outer envelope. Moves no point of the input surface.
  // Its choice of patches can drop most of a body (a spike poking through
  // a thin wall leaves it with the spike's tip): the result must keep the
  // enclosed volume within kVolumeKept.
  bool fixed = false;
  const double volume_before = PMP::volume(before);
  try {
    fixed = PMP::experimental::autorefine_and_remove_self_intersections(m) && CGAL::is_closed(m) &&
            !PMP::does_self_intersect(m) &&
            std::fabs(PMP::volume(m) - volume_before) <= kVolumeKept * std::fabs(volume_before);
  } catch (const std::exception&) {
    fixed = false;  // CGAL refuses some configurations (e.g. coplanar overlaps); try the local repair
  }
  if (fixed) {
    r.autorefined = true;
  } else {
    // 2. local repair: remove the intersecting patches, fill and smooth them
    m = before;
    if (progress) progress("repair: autorefinement left intersections; local remeshing of the folds");
    fixed = PMP::experimental::remove_self_intersections(m, PMP::parameters::preserve_genus(false));
    m.collect_garbage();
    pairs.clear();
    PMP::self_intersections(m, std::back_inserter(pairs));
    if (!pairs.empty())
      throw MeshError(fmt::format("{}: the surface intersects itself and the repair failed: {}", source,
                                  intersection_text(m, pairs)));
    if (!CGAL::is_closed(m))
      throw MeshError(source + ": removing the self-intersections left the surface open (a fold too large to refill)");
    r.smoothed = true;
  }
  m.collect_garbage();
  r.max_moved = max_distance(m, before);
}

}  // namespace

bool RepairReport::changed() const {
  return soup_points_merged || soup_polygons_removed || non_manifold_vertices || degenerate_removed ||
         intersecting_pairs || holes_filled || reoriented;
}

std::string RepairReport::summary() const {
  std::string s;
  auto line = [&s](const std::string& l) { s += "  " + l + "\n"; };
  if (soup_points_merged) line(fmt::format("duplicate points merged: {}", soup_points_merged));
  if (soup_polygons_removed) line(fmt::format("degenerate or duplicate triangles removed: {}", soup_polygons_removed));
  if (non_manifold_vertices) line(fmt::format("non-manifold vertices split: {}", non_manifold_vertices));
  if (degenerate_removed) line(fmt::format("zero-area triangles removed: {}", degenerate_removed));
  if (holes_filled)
    line(fmt::format("holes filled: {} ({} triangles added, largest {:.3g} mm across)", holes_filled,
                     hole_triangles_added, 1e3 * largest_hole));
  if (intersecting_pairs)
    line(fmt::format("self-intersections: {} triangle pairs ({} triangles) resolved by {}; largest move {:.3g} mm",
                     intersecting_pairs, intersecting_triangles,
                     autorefined ? "autorefinement (outer envelope kept)" : "local remeshing and smoothing",
                     1e3 * max_moved));
  if (reoriented) line("faces turned outward");
  line(fmt::format("triangles: {} -> {}", triangles_before, triangles_after));
  return s;
}

RepairReport repair_surface(SurfaceMesh& s, const RepairOptions& o, const std::string& source,
                            const Progress& progress) {
  RepairReport r;
  r.triangles_before = s.n_triangles();
  Mesh m = repair_soup(s, r, source);
  remove_degenerate(m, r);
  fill_holes(m, o, r, source);
  remove_intersections(m, o, r, source, progress);
  if (!CGAL::is_closed(m)) throw MeshError(source + ": the repaired surface is still not closed");
  if (!PMP::is_outward_oriented(m)) {
    PMP::reverse_face_orientations(m);
    r.reoriented = true;
  }
  r.triangles_after = index_t(m.number_of_faces());
  if (r.changed()) s = from_mesh(std::move(m));
  return r;
}

long count_self_intersections(const SurfaceMesh& s, const std::string& source) {
  const Mesh m = to_mesh(s, source);
  std::vector<std::pair<face_descriptor, face_descriptor>> pairs;
  PMP::self_intersections(m, std::back_inserter(pairs));
  return long(pairs.size());
}

index_t remesh_surface(SurfaceMesh& s, double edge_length, int passes, const std::string& source,
                       const Progress& progress) {
  if (!(edge_length > 0) || !std::isfinite(edge_length))
    throw MeshError(fmt::format("{}: remeshing edge length {} m must be > 0", source, edge_length));
  Mesh m = to_mesh(s, source);
  for (int pass = 1; pass <= passes; ++pass) {
    PMP::isotropic_remeshing(faces(m), edge_length, m, PMP::parameters::number_of_iterations(1));
    if (progress)
      progress(fmt::format("remeshing to {:.3g} mm edges: pass {} of {}, {} triangles", 1e3 * edge_length, pass,
                           passes, m.number_of_faces()));
  }
  m.collect_garbage();
  if (!CGAL::is_closed(m)) throw MeshError(source + ": isotropic remeshing left the surface open");
  s = from_mesh(std::move(m));
  return s.n_triangles();
}

index_t wrap_surface(SurfaceMesh& s, double alpha, double offset, const std::string& source) {
  if (!(alpha > 0) || !(offset > 0) || !std::isfinite(alpha) || !std::isfinite(offset))
    throw MeshError(fmt::format("{}: the alpha wrap's alpha {} m and offset {} m must be > 0", source, alpha, offset));
  const Mesh m = to_mesh(s, source);
  Mesh wrap;
  CGAL::alpha_wrap_3(m, alpha, offset, wrap);
  if (wrap.is_empty() || !CGAL::is_closed(wrap)) throw MeshError(source + ": the alpha wrap is empty or not closed");
  s = from_mesh(std::move(wrap));
  return s.n_triangles();
}

double mean_edge_length(const SurfaceMesh& s) {
  double sum = 0;
  for (index_t t = 0; t < s.n_triangles(); ++t)
    for (int k = 0; k < 3; ++k) {
      const index_t a = s.triangles[3 * t + k], b = s.triangles[3 * t + (k + 1) % 3];
      double d2 = 0;
      for (int c = 0; c < 3; ++c) d2 += (s.vertices[3 * a + c] - s.vertices[3 * b + c]) * (s.vertices[3 * a + c] - s.vertices[3 * b + c]);
      sum += std::sqrt(d2);
    }
  return s.n_triangles() > 0 ? sum / (3.0 * s.n_triangles()) : 0.0;
}

}  // namespace tissue::io
