#include "io/organ_mesher.hpp"

#include <fmt/format.h>

#include "io/cgal_mesher.hpp"

#include <algorithm>
#include <cmath>

namespace tissue::io {
namespace {

double surface_area(const SurfaceMesh& s) {
  double a = 0;
  for (index_t t = 0; t < s.n_triangles(); ++t) {
    const index_t* c = &s.triangles[3 * t];
    const Vec3<double> p0{s.vertices[3 * c[0]], s.vertices[3 * c[0] + 1], s.vertices[3 * c[0] + 2]};
    const Vec3<double> p1{s.vertices[3 * c[1]], s.vertices[3 * c[1] + 1], s.vertices[3 * c[1] + 2]};
    const Vec3<double> p2{s.vertices[3 * c[2]], s.vertices[3 * c[2] + 1], s.vertices[3 * c[2] + 2]};
    a += 0.5 * norm(cross(p1 - p0, p2 - p0));
  }
  return a;
}

/// Edge length for which the surface has about n equilateral triangles.
double edge_for_triangles(const SurfaceMesh& s, double n) {
  return std::sqrt(4.0 * surface_area(s) / (std::sqrt(3.0) * n));
}

void say(const OrganMeshOptions& o, const std::string& line) {
  if (o.meshing.progress) o.meshing.progress(line);
}

void clean(NamedSurface& n, const OrganMeshOptions& o, SurfaceSteps& steps) {
  if (o.repair) {
    steps.repair = repair_surface(n.surface, o.repair_options, n.source, o.meshing.progress);
    steps.repaired = true;
    std::string text = steps.repair.summary();
    if (!text.empty() && text.back() == '\n') text.pop_back();
    say(o, steps.repair.changed() ? fmt::format("repaired {}:\n{}", n.source, text)
                                  : fmt::format("repair: {} needed none", n.source));
  } else {
    check_closed(n.surface, n.source);
  }
}

/// The edge to remesh to under the auto rule (0 = leave the surface).
double auto_edge(const SurfaceMesh& s, double target_edge, bool inclusion) {
  const double h = mean_edge_length(s);
  double edge = 0;
  if (target_edge > 0 && h < kRemeshBelow * target_edge) edge = target_edge;
  if (target_edge <= 0 && s.n_triangles() > kMaxTriangles) edge = edge_for_triangles(s, kMaxTriangles / 4.0);
  if (inclusion && edge > 0) {
    const Vec3<double> e = surface_extents(s);
    edge = std::min(edge, 0.1 * norm(e));
    if (h >= kRemeshBelow * edge && s.n_triangles() <= kMaxTriangles) edge = 0;
  }
  return edge;
}

void remesh(NamedSurface& n, double edge, const OrganMeshOptions& o, SurfaceSteps& steps) {
  if (edge <= 0) return;
  const index_t before = n.surface.n_triangles();
  remesh_surface(n.surface, edge, o.remesh_passes, n.source, o.meshing.progress);
  steps.remeshed_to = edge;
  say(o, fmt::format("remeshed {} to {:.3g} mm edges: {} -> {} triangles", n.source, 1e3 * edge, before,
                     n.surface.n_triangles()));
  if (count_self_intersections(n.surface, n.source) > 0) {
    if (!o.repair) throw MeshError(n.source + ": the remeshed surface intersects itself (run without --no-repair)");
    const RepairReport again = repair_surface(n.surface, o.repair_options, n.source, o.meshing.progress);
    steps.repair.intersecting_pairs += again.intersecting_pairs;
    steps.repair.intersecting_triangles += again.intersecting_triangles;
    steps.repair.max_moved = std::max(steps.repair.max_moved, again.max_moved);
  }
}

/// Every vertex of the inclusion inside the organ and outside the other
/// inclusions (winding numbers); throws naming the vertex.
void check_inclusion(const NamedSurface& inc, const NamedSurface& organ, const std::vector<NamedSurface>& others,
                     size_t self) {
  const SurfaceMesh& s = inc.surface;
  for (index_t v = 0; v < s.n_vertices(); ++v) {
    const Vec3<double> p{s.vertices[3 * v], s.vertices[3 * v + 1], s.vertices[3 * v + 2]};
    if (winding_number(organ.surface, p) < 0.5)
      throw MeshError(fmt::format(
          "{}: inclusion vertex {} at ({:.4g}, {:.4g}, {:.4g}) m lies outside the organ {}: an inclusion must lie "
          "inside the organ (check both files' units and positions)",
          inc.source, v, p.x, p.y, p.z, organ.source));
    for (size_t k = 0; k < others.size(); ++k)
      if (k != self && winding_number(others[k].surface, p) > 0.5)
        throw MeshError(fmt::format("{}: inclusion vertex {} at ({:.4g}, {:.4g}, {:.4g}) m lies inside inclusion {}: "
                                    "inclusions must not overlap",
                                    inc.source, v, p.x, p.y, p.z, others[k].source));
  }
}

/// One conforming TetGen meshing of the organ with its inclusions as regions.
VolumeMesh tetrahedralize(const NamedSurface& organ, const std::vector<NamedSurface>& inclusions,
                          MeshingOptions m, Mesher mesher) {
  m.regions.clear();
  if (mesher == Mesher::Auto)
    mesher = inclusions.empty() && (m.target_tets > 0 || m.max_volume > 0) ? Mesher::Mesh3 : Mesher::TetGen;
  if (mesher == Mesher::Mesh3) {
    if (!inclusions.empty())
      throw MeshError(organ.source + ": inclusions are meshed by TetGen's regions only (use --mesher tetgen)");
    Mesh3Options o3;
    o3.target_tets = m.target_tets;
    if (m.target_tets == 0) {
      if (!(m.max_volume > 0)) throw MeshError(organ.source + ": Mesh_3 needs --target-tets or --max-volume");
      o3.cell_size = std::sqrt(6.0) / 4 * regular_tet_edge(m.max_volume);
      o3.cell_size_from = fmt::format("--max-volume {:g} m^3", m.max_volume);
    }
    o3.progress = m.progress;
    return mesh3_surface(organ.surface, o3, organ.source);
  }
  SurfaceMesh combined = organ.surface;
  for (size_t k = 0; k < inclusions.size(); ++k) {
    check_inclusion(inclusions[k], organ, inclusions, k);
    m.regions.push_back({interior_point(inclusions[k].surface, inclusions[k].source), int(k + 1)});
    const index_t base = combined.n_vertices();
    const SurfaceMesh& s = inclusions[k].surface;
    combined.vertices.insert(combined.vertices.end(), s.vertices.begin(), s.vertices.end());
    for (index_t v : s.triangles) combined.triangles.push_back(base + v);
  }
  VolumeMesh v = tetrahedralize_surface(combined, m, organ.source);
  // TetGen numbers the regions nobody seeded itself (the organ's tissue
  // around the inclusions): every attribute that is not an inclusion's is
  // tissue.
  for (int& r : v.tet_region)
    if (r < 1 || r > int(inclusions.size())) r = 0;
  return v;
}

}  // namespace

double regular_tet_edge(double volume) { return std::cbrt(6.0 * std::sqrt(2.0) * volume); }

OrganMesh mesh_organ(NamedSurface organ, std::vector<NamedSurface> inclusions, const OrganMeshOptions& o) {
  OrganMesh out;
  std::vector<NamedSurface*> all{&organ};
  for (NamedSurface& inc : inclusions) all.push_back(&inc);
  out.surfaces.resize(all.size());
  for (size_t k = 0; k < all.size(); ++k) {
    out.surfaces[k].source = all[k]->source;
    out.surfaces[k].triangles_in = all[k]->surface.n_triangles();
    clean(*all[k], o, out.surfaces[k]);
  }
  const double volume = std::fabs(enclosed_volume(organ.surface));
  if (o.meshing.target_tets > 0)
    out.target_edge = regular_tet_edge(volume / o.meshing.target_tets);
  else if (o.meshing.max_volume > 0)
    out.target_edge = regular_tet_edge(o.meshing.max_volume);
  out.mesher = o.mesher != Mesher::Auto ? o.mesher
                : inclusions.empty() && (o.meshing.target_tets > 0 || o.meshing.max_volume > 0) ? Mesher::Mesh3
                                                                                               : Mesher::TetGen;
  if (o.wrap && out.mesher == Mesher::Mesh3 && out.target_edge > 0 && inclusions.empty()) {
    // the tets the size asks for must fit before the wrap, whose surface grows as the size shrinks
    const bool by_count = o.meshing.target_tets > 0;
    check_tet_memory(by_count ? double(o.meshing.target_tets) : volume / o.meshing.max_volume, kMesh3BytesPerTet,
                     by_count ? fmt::format("a target of {} tets", o.meshing.target_tets)
                              : fmt::format("--max-volume {:g} m^3", o.meshing.max_volume),
                     organ.source);
    SurfaceSteps& steps = out.surfaces[0];
    const index_t before = organ.surface.n_triangles();
    steps.wrapped_alpha = kWrapAlpha * out.target_edge;
    say(o, fmt::format("wrapping {} at alpha {:.3g} mm ({} triangles in)", organ.source, 1e3 * steps.wrapped_alpha,
                       before));
    wrap_surface(organ.surface, steps.wrapped_alpha, kWrapOffset * out.target_edge, organ.source);
    steps.wrap_volume_change = std::fabs(enclosed_volume(organ.surface)) / volume - 1;
    say(o, fmt::format("wrapped {} at alpha {:.3g} mm (half the target edge): {} -> {} triangles, enclosed volume "
                       "{:+.2f} %",
                       organ.source, 1e3 * steps.wrapped_alpha, before, organ.surface.n_triangles(),
                       100 * steps.wrap_volume_change));
  }
  for (size_t k = 0; k < all.size(); ++k) {
    const double edge = o.remesh_edge < 0 ? 0 : o.remesh_edge > 0 ? o.remesh_edge
                                                                : auto_edge(all[k]->surface, out.target_edge, k > 0);
    remesh(*all[k], edge, o, out.surfaces[k]);
    out.surfaces[k].triangles_out = all[k]->surface.n_triangles();
  }
  MeshingOptions m = o.meshing;
  m.regions.clear();
  for (int attempt = 0;; ++attempt) {
    out.mesh = tetrahedralize(organ, inclusions, m, out.mesher);
    const double n = out.mesh.n_tets(), target = m.target_tets;
    // The surface alone forces more tets than the target: remesh it coarser
    // (tet count ~ edge^-3) and try again.
    if (target <= 0 || n <= (1 + kTargetPromise) * target || o.remesh_edge != 0 || attempt == 3) break;
    // with inclusions, only when the organ's own surface is finer than the size asks: the excess may come
    // from an inclusion's finer surface instead, and coarsening a coarse organ destroys its shape (a
    // 24-triangle box became a 4-triangle tetrahedron, leaving its inclusion outside)
    if (!inclusions.empty() && !(mean_edge_length(organ.surface) < kRemeshBelow * out.target_edge)) {
      say(o, fmt::format("{} tets, over the target {}: the inclusions' surfaces force them (the organ's is not too "
                         "fine)",
                         n, target));
      break;
    }
    const double edge = (out.surfaces[0].remeshed_to > 0 ? out.surfaces[0].remeshed_to
                                                          : mean_edge_length(organ.surface)) *
                        std::cbrt(n / target);
    say(o, fmt::format("{} tets, over the target {} even at the largest tets: the surface is too fine", n, target));
    remesh(organ, edge, o, out.surfaces[0]);
    out.surfaces[0].triangles_out = organ.surface.n_triangles();
  }
  return out;
}


std::string unit_warning(double max_extent, const std::string& unit) {
  constexpr double kSmallest = 5e-3, kLargest = 1.0;
  if (max_extent >= kSmallest && max_extent <= kLargest) return "";
  const double per_unit = parse_unit(unit);
  std::string likely;
  for (const char* u : {"mm", "cm", "m"}) {
    const double e = max_extent / per_unit * parse_unit(u);
    if (u != unit && e >= kSmallest && e <= kLargest) {
      likely = u;
      break;
    }
  }
  std::string msg = fmt::format("warning: the body is {:.4g} mm across (read in {}), {} for an organ (5 mm .. 1 m)",
                                1e3 * max_extent, unit, max_extent > kLargest ? "too large" : "too small");
  if (!likely.empty()) msg += fmt::format("; the file is likely in {}: use --unit {}", likely, likely);
  return msg;
}

}  // namespace tissue::io
