// The one translation unit that includes CGAL Mesh_3 (header-heavy).
#include "io/cgal_mesher.hpp"

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Mesh_complex_3_in_triangulation_3.h>
#include <CGAL/Mesh_criteria_3.h>
#include <CGAL/Mesh_triangulation_3.h>
#include <CGAL/Polyhedral_mesh_domain_3.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/make_mesh_3.h>
#include <fmt/format.h>

#include <chrono>
#include <cmath>
#include <map>

#include "core/tet.hpp"

namespace tissue::io {
namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = Kernel::Point_3;
using Polyhedron = CGAL::Surface_mesh<Point>;
using Domain = CGAL::Polyhedral_mesh_domain_3<Polyhedron, Kernel>;
using Tr = CGAL::Mesh_triangulation_3<Domain, CGAL::Default, CGAL::Sequential_tag>::type;
using C3t3 = CGAL::Mesh_complex_3_in_triangulation_3<Tr>;
using Criteria = CGAL::Mesh_criteria_3<Tr>;

Polyhedron to_polyhedron(const SurfaceMesh& s) {
  Polyhedron p;
  std::vector<Polyhedron::Vertex_index> v;
  for (index_t i = 0; i < s.n_vertices(); ++i)
    v.push_back(p.add_vertex(Point(s.vertices[3 * i], s.vertices[3 * i + 1], s.vertices[3 * i + 2])));
  for (index_t t = 0; t < s.n_triangles(); ++t)
    p.add_face(v[s.triangles[3 * t]], v[s.triangles[3 * t + 1]], v[s.triangles[3 * t + 2]]);
  return p;
}

VolumeMesh run(const Polyhedron& poly, double cell, const Mesh3Options& o, const std::string& source) {
  namespace params = CGAL::parameters;
  Domain domain(poly);
  // no facet_distance: at 0.1 cell it refined the rims of thin lobes to
  // edges of 0.2-0.4 of the target (docs/meshing.md)
  Criteria criteria(params::facet_angle = 25, params::facet_size = cell, params::cell_radius_edge_ratio = 2,
                    params::cell_size = cell);
  const C3t3 c3t3 = CGAL::make_mesh_3<C3t3>(
      domain, criteria, params::no_lloyd(), params::no_odt(),
      params::perturb(params::time_limit = o.time_limit, params::sliver_bound = o.sliver_bound),
      params::exude(params::time_limit = o.time_limit, params::sliver_bound = o.sliver_bound));
  VolumeMesh m;
  std::map<Tr::Vertex_handle, index_t> ids;
  for (auto c = c3t3.cells_in_complex_begin(); c != c3t3.cells_in_complex_end(); ++c) {
    index_t n[4];
    Vec3<double> X[4];
    for (int a = 0; a < 4; ++a) {
      const Tr::Vertex_handle v = c->vertex(a);
      auto [it, fresh] = ids.emplace(v, m.n_nodes());
      const auto p = c3t3.triangulation().point(c, a);
      if (fresh) m.nodes.insert(m.nodes.end(), {p.x(), p.y(), p.z()});
      n[a] = it->second;
      X[a] = {p.x(), p.y(), p.z()};
    }
    double dN[12];
    const double V = tet_shape_gradients(X, dN);
    if (V == 0) throw MeshError(fmt::format("{}: Mesh_3 returned a zero-volume tet", source));
    if (V < 0) std::swap(n[1], n[2]);
    m.tets.insert(m.tets.end(), n, n + 4);
  }
  if (m.tets.empty()) throw MeshError(source + ": Mesh_3 produced no tetrahedra (is the surface closed and outward?)");
  m.runs = 1;
  return m;
}

}  // namespace

VolumeMesh mesh3_surface(const SurfaceMesh& surface, const Mesh3Options& o, const std::string& source) {
  check_closed(surface, source);
  if (o.target_tets < 0 || (o.target_tets == 0 && !(o.cell_size > 0)) || !std::isfinite(o.cell_size))
    throw MeshError(fmt::format("{}: Mesh_3 needs a cell size > 0 m or a target tet count > 0 (got {} m, {})", source,
                                o.cell_size, o.target_tets));
  if (!(o.sliver_bound >= 0 && o.sliver_bound < 60) || !(o.time_limit > 0))
    throw MeshError(fmt::format("{}: sliver bound {} must be in [0, 60) degrees and the time limit {} s > 0", source,
                                o.sliver_bound, o.time_limit));
  const double volume = std::fabs(enclosed_volume(surface));
  check_tet_memory(o.target_tets > 0 ? o.target_tets : volume / (std::pow(4 / std::sqrt(6.0) * o.cell_size, 3) / (6 * std::sqrt(2.0))),
                   kMesh3BytesPerTet,
                   o.target_tets > 0 ? fmt::format("a target of {} tets", o.target_tets)
                     : o.cell_size_from.empty() ? fmt::format("a cell size of {:.3g} m", o.cell_size)
                                                : fmt::format("{} (a cell size of {:.3g} m)", o.cell_size_from, o.cell_size),
                   source);
  const Polyhedron poly = to_polyhedron(surface);
  // circumradius of the regular tet of the mean volume: edge a = (6 sqrt(2) v)^(1/3), R = a sqrt(6) / 4
  double cell = o.cell_size > 0 ? o.cell_size
                                : std::sqrt(6.0) / 4 *
                                      std::cbrt(6 * std::sqrt(2.0) * std::fabs(enclosed_volume(surface)) / o.target_tets);
  VolumeMesh best;
  const int rounds = o.target_tets > 0 ? kMesh3Rounds : 1;
  for (int round = 0; round < rounds; ++round) {
    const auto start = std::chrono::steady_clock::now();
    VolumeMesh m = run(poly, cell, o, source);
    if (o.progress)
      o.progress(fmt::format("mesh_3 run {}: cell size {:.3g} mm -> {} tets, {:.1f} s", round + 1, 1e3 * cell,
                             m.n_tets(),
                             std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count()));
    const double n = m.n_tets();
    m.runs = round + 1;
    if (best.tets.empty() || std::fabs(n - o.target_tets) < std::fabs(best.n_tets() - double(o.target_tets)))
      best = std::move(m);
    if (o.target_tets == 0 || std::fabs(n - o.target_tets) <= kTargetTolerance * o.target_tets) break;
    cell *= std::cbrt(n / o.target_tets);
  }
  sort_for_locality(best);
  return best;
}

}  // namespace tissue::io
