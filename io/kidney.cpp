#include "io/kidney.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <numbers>
#include <set>
#include <stdexcept>
#include <string>
#include <utility>

#include "core/device.hpp"
#include "core/model.hpp"
#include "core/tet.hpp"
#include "io/tetgen_mesher.hpp"

namespace tissue::io {
namespace {

Vec3<double> unit(Vec3<double> v) {
  return (1.0 / norm(v)) * v;
}

Vec3<double> vertex(const SurfaceMesh& s, index_t i) {
  return {s.vertices[3 * i], s.vertices[3 * i + 1], s.vertices[3 * i + 2]};
}

/// Unit icosahedron: 12 vertices, 20 outward triangles.
SurfaceMesh icosahedron() {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  const double v[12][3] = {{-1, t, 0},  {1, t, 0},  {-1, -t, 0}, {1, -t, 0}, {0, -1, t},  {0, 1, t},
                           {0, -1, -t}, {0, 1, -t}, {t, 0, -1},  {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
  SurfaceMesh s;
  for (const auto& p : v) {
    const Vec3<double> u = unit({p[0], p[1], p[2]});
    s.vertices.insert(s.vertices.end(), {u.x, u.y, u.z});
  }
  s.triangles = {0, 11, 5, 0, 5, 1, 0, 1, 7, 0, 7, 10, 0, 10, 11, 1, 5, 9, 5, 11, 4,  11, 10, 2,  10, 7, 6, 7, 1, 8,
                 3, 9,  4, 3, 4, 2, 3, 2, 6, 3, 6, 8,  3, 8,  9,  4, 9, 5, 2, 4,  11, 6,  2,  10, 8,  6, 7, 9, 8, 1};
  return s;
}

/// Geodesic sphere of the given frequency: every icosahedron face split
/// into frequency^2 triangles on a barycentric grid, the grid points
/// projected onto the unit sphere. Points on an icosahedron edge are computed
/// once from the edge's canonical (lower id first) end points, so the two
/// faces sharing the edge share them exactly.
SurfaceMesh geodesic_sphere(int frequency) {
  const SurfaceMesh ico = icosahedron();
  const int f = frequency;
  SurfaceMesh out;
  out.vertices = ico.vertices;
  std::map<std::array<index_t, 3>, index_t> edge_points;  // (lo corner, hi corner, steps from lo) -> id
  auto add = [&](Vec3<double> p) {
    const Vec3<double> u = unit(p);
    out.vertices.insert(out.vertices.end(), {u.x, u.y, u.z});
    return out.n_vertices() - 1;
  };
  for (index_t t = 0; t < ico.n_triangles(); ++t) {
    const index_t c[3] = {ico.triangles[3 * t], ico.triangles[3 * t + 1], ico.triangles[3 * t + 2]};
    // grid point (i, j): weights (f - i - j, i, j) on corners (c0, c1, c2)
    std::vector<index_t> grid((f + 1) * (f + 1), -1);
    auto at = [&](int i, int j) -> index_t& { return grid[i * (f + 1) + j]; };
    for (int i = 0; i <= f; ++i)
      for (int j = 0; i + j <= f; ++j) {
        const int w[3] = {f - i - j, i, j};
        int nonzero = 0, first = -1, second = -1;
        for (int k = 0; k < 3; ++k)
          if (w[k] > 0) {
            ++nonzero;
            (first < 0 ? first : second) = k;
          }
        if (nonzero == 1) {
          at(i, j) = c[first];
        } else if (nonzero == 2) {
          const bool swap = c[first] > c[second];
          const index_t lo = swap ? c[second] : c[first], hi = swap ? c[first] : c[second];
          const int steps = swap ? w[first] : w[second];  // weight on hi = steps from lo
          auto it = edge_points.find({lo, hi, steps});
          if (it == edge_points.end())
            it = edge_points
                     .emplace(std::array<index_t, 3>{lo, hi, steps},
                              add((double(f - steps) / f) * vertex(ico, lo) + (double(steps) / f) * vertex(ico, hi)))
                     .first;
          at(i, j) = it->second;
        } else {
          at(i, j) = add((double(w[0]) / f) * vertex(ico, c[0]) + (double(w[1]) / f) * vertex(ico, c[1]) +
                         (double(w[2]) / f) * vertex(ico, c[2]));
        }
      }
    for (int i = 0; i < f; ++i)
      for (int j = 0; i + j < f; ++j) {
        out.triangles.insert(out.triangles.end(), {at(i, j), at(i + 1, j), at(i, j + 1)});
        if (i + j < f - 1) out.triangles.insert(out.triangles.end(), {at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)});
      }
  }
  return out;
}

/// Nearest hit of the ray from the origin along dir with the surface:
/// (triangle, distance along the unit direction).
std::pair<index_t, double> ray_hit(const SurfaceMesh& s, Vec3<double> dir) {
  double reach = 0;
  for (double x : s.vertices) reach = std::max(reach, std::fabs(x));
  reach = 4 * reach + 1;
  const Vec3<double> A{0, 0, 0}, B = reach * unit(dir);
  index_t best = -1;
  double best_t = 2;
  for (index_t t = 0; t < s.n_triangles(); ++t) {
    double bary[2];
    const double h = segment_triangle(A, B, vertex(s, s.triangles[3 * t]), vertex(s, s.triangles[3 * t + 1]),
                                      vertex(s, s.triangles[3 * t + 2]), bary);
    if (h >= 0 && h < best_t) {
      best_t = h;
      best = t;
    }
  }
  if (best < 0)
    throw std::runtime_error(
        fmt::format("the ray from the origin along ({}, {}, {}) misses the surface", dir.x, dir.y, dir.z));
  return {best, best_t * reach};
}

/// Maps the unit-sphere point p onto the kidney: s(p) (a p_x, b p_y, c p_z).
Vec3<double> on_kidney(const KidneyShape& k, Vec3<double> p) {
  const double r = kidney_radial_scale(k, p);
  return {r * k.a * p.x, r * k.b * p.y, r * k.c * p.z};
}

}  // namespace

double kidney_radial_scale(const KidneyShape& k, Vec3<double> p) {
  const double medial = std::pow(0.5 * (1.0 - p.y), 4) * std::exp(-(p.x / k.bean_width) * (p.x / k.bean_width));
  const double dent = std::exp(-(1.0 + p.y) / k.hilum_width);
  return 1.0 - k.bean * medial - k.hilum * dent;
}

SurfaceMesh kidney_surface(int frequency, const KidneyShape& k) {
  return kidney_surface(frequency, k, SurfaceFocus{});
}

Vec3<double> kidney_sphere_direction(const KidneyShape& k, Vec3<double> x) {
  const Vec3<double> d{x.x / k.a, x.y / k.b, x.z / k.c};
  if (!(norm(d) > 0)) throw std::invalid_argument("kidney_sphere_direction: the point is the kidney's centre");
  return unit(d);
}

SurfaceMesh kidney_surface(int frequency, const KidneyShape& k, const SurfaceFocus& focus) {
  if (!(focus.scale > 0 && focus.scale <= 1))
    throw std::invalid_argument(fmt::format("kidney_surface: focus scale {} must be in (0, 1]", focus.scale));
  if (!(norm(focus.toward) > 0)) throw std::invalid_argument("kidney_surface: the focus direction is zero");
  if (frequency < 1 || frequency > 64)
    throw std::invalid_argument(fmt::format("kidney_surface: frequency {} must be in 1..64", frequency));
  if (!(k.a > 0 && k.b > 0 && k.c > 0 && k.bean_width > 0 && k.hilum_width > 0 && k.bean >= 0 && k.hilum >= 0 &&
        k.bean + k.hilum < 1))
    throw std::invalid_argument("kidney_surface: semi-axes and widths must be > 0, bean + hilum in [0, 1)");
  SurfaceMesh s = geodesic_sphere(frequency);
  const Vec3<double> e = unit(focus.toward);
  for (index_t i = 0; i < s.n_vertices(); ++i) {
    Vec3<double> p = vertex(s, i);
    if (focus.scale < 1 && 1 + dot(p, e) > 1e-12) {
      // stereographic projection from -e onto the plane through the centre normal to e, scaled, and back
      const Vec3<double> z = (focus.scale / (1 + dot(p, e))) * (p - dot(p, e) * e);
      const double z2 = dot(z, z);
      p = unit((1 / (1 + z2)) * (2.0 * z + (1 - z2) * e));
    }
    const Vec3<double> x = on_kidney(k, p);
    s.vertices[3 * i] = x.x;
    s.vertices[3 * i + 1] = x.y;
    s.vertices[3 * i + 2] = x.z;
  }
  // Star-shapedness of the polyhedron: every triangle faces away from the
  // origin (its cone from the origin is positively oriented).
  for (index_t t = 0; t < s.n_triangles(); ++t) {
    const Vec3<double> a = vertex(s, s.triangles[3 * t]), b = vertex(s, s.triangles[3 * t + 1]),
                       c = vertex(s, s.triangles[3 * t + 2]);
    if (!(dot(a, cross(b, c)) > 0))
      throw std::invalid_argument(
          fmt::format("kidney_surface: triangle {} faces the centre; the shape is too deep", t));
  }
  return s;
}

Vec3<double> surface_point_along(const SurfaceMesh& s, Vec3<double> dir) {
  return ray_hit(s, dir).second * unit(dir);
}

index_t surface_triangle_along(const SurfaceMesh& s, Vec3<double> dir) {
  return ray_hit(s, dir).first;
}

Vec3<double> kidney_hilum_centre() {
  return surface_point_along(kidney_surface(KidneyScene::frequency), {0, -1, 0});
}

namespace {

/// A Neo-Hookean material given as E (Pa), nu and rho (kg/m^3), and an
/// element set of that name holding every element of `body` (-1: of the
/// single-mesh form) made of it.
void add_material(scene::Scene& s, const std::string& name, double E, double nu, double rho, int body) {
  scene::Material m;
  m.name = name;
  m.form = scene::Material::Form::YoungPoisson;
  m.a = E;
  m.b = nu;
  m.rho = rho;
  s.materials.push_back(m);
  scene::ElementSet all;
  all.name = name;
  all.material = name;
  all.all = true;
  all.body = body;
  s.sets.push_back(all);
}

/// The default kidney scene; *max_volume (if given) receives the largest
/// tet volume TetGen was asked for (m^3).
scene::Scene kidney_scene(double* max_volume) {
  using K = KidneyScene;
  const SurfaceMesh surface = kidney_surface(K::frequency);
  MeshingOptions meshing;
  meshing.quality = K::quality;
  meshing.target_tets = K::target_tets;
  VolumeMesh mesh = tetrahedralize_surface(surface, meshing, "built-in kidney");
  if (max_volume) *max_volume = mesh.max_volume;

  scene::Scene s;
  s.source = "@kidney";
  s.nodes = std::move(mesh.nodes);
  s.tets = std::move(mesh.tets);
  // the organ's name; its numbers are brain tissue's (docs/kidney.md, "Material")
  add_material(s, "kidney", K::E, K::nu, K::rho, -1);

  // The hilum: nodes within fix_radius of the surface point along -y.
  const Vec3<double> hilum = surface_point_along(surface, {0, -1, 0});
  scene::Constraint fix;
  fix.kind = scene::Constraint::Kind::Nodes;
  for (index_t i = 0; i < static_cast<index_t>(s.nodes.size() / 3); ++i) {
    const Vec3<double> x{s.nodes[3 * i], s.nodes[3 * i + 1], s.nodes[3 * i + 2]};
    if (norm(x - hilum) <= K::fix_radius) fix.nodes.push_back(i);
  }
  s.constraints.push_back(std::move(fix));

  // The probe: a rod with a hemispherical tip, aimed at the lateral surface
  // point along +y along the inward normal of the input surface there. Both
  // come from the generated surface, not from the tet mesh, so every mesh
  // of the organ (tissue tradeoff's coarse and fine ones) is pressed at the
  // same point in the same direction. The path starts with the tool's
  // surface `approach` outside; the indentation is the tool's deepest point
  // below the undeformed surface.
  const Vec3<double> touch = surface_point_along(surface, {0, 1, 0});
  const index_t lateral = surface_triangle_along(surface, {0, 1, 0});
  const Vec3<double> c0 = vertex(surface, surface.triangles[3 * lateral]),
                     c1 = vertex(surface, surface.triangles[3 * lateral + 1]),
                     c2 = vertex(surface, surface.triangles[3 * lateral + 2]);
  const Vec3<double> outward = unit(cross(c1 - c0, c2 - c0));
  scene::Tool tool;
  tool.name = "probe";
  tool.radius = K::tool_radius;
  tool.shaft = K::tool_shaft;
  tool.direction = outward;
  tool.device = "scripted";
  tool.path = press_path(touch + K::tool_radius * outward, -1.0 * outward, K::press_depth, K::approach);
  s.tools.push_back(std::move(tool));

  s.solver.backend = "cpu";
  s.solver.precision = Precision::Float;
  s.solver.dt.reset();
  s.solver.dt_safety = 0.8;  // the scene default: a margin for large indentations (docs/reliability.md, "Soak")
  s.solver.mass_scaling = 0.025;
  s.solver.damping.reset();
  s.solver.depth = kDepthAuto;
  s.solver.tick = 1e-3;
  return s;
}

}  // namespace

scene::Scene default_kidney_scene() {
  return kidney_scene(nullptr);
}

namespace {

/// The fat layer's surface (kidney_fat_surface); its first n_outer
/// triangles are the outer side, and `rim` receives each rim edge's two
/// kidney vertices (a, b: the patch lies left of a -> b seen from outside).
SurfaceMesh fat_layer(index_t* n_outer, std::vector<std::pair<Vec3<double>, Vec3<double>>>* rim) {
  using F = KidneyFatScene;
  const SurfaceMesh sphere = geodesic_sphere(KidneyScene::frequency);
  const SurfaceMesh kidney = kidney_surface(KidneyScene::frequency);
  const double cos_cap = std::cos(F::cap_angle * std::numbers::pi / 180);
  std::vector<index_t> patch;
  for (index_t t = 0; t < sphere.n_triangles(); ++t)
    if (std::min({vertex(sphere, sphere.triangles[3 * t]).y, vertex(sphere, sphere.triangles[3 * t + 1]).y,
                  vertex(sphere, sphere.triangles[3 * t + 2]).y}) >= cos_cap)
      patch.push_back(t);
  SurfaceMesh out;
  std::map<index_t, std::pair<index_t, index_t>> ids;  // kidney vertex -> (inner, outer) vertex of the layer
  const auto add = [&](Vec3<double> x) {
    out.vertices.insert(out.vertices.end(), {x.x, x.y, x.z});
    return index_t(out.vertices.size() / 3 - 1);
  };
  for (index_t t : patch)
    for (int c = 0; c < 3; ++c) {
      const index_t v = kidney.triangles[3 * t + c];
      if (ids.count(v)) continue;
      const Vec3<double> x = vertex(kidney, v);
      const index_t inner = add(x);
      ids[v] = {inner, add((1 + F::thickness / norm(x)) * x)};
    }
  const auto tri = [&](index_t a, index_t b, index_t c) { out.triangles.insert(out.triangles.end(), {a, b, c}); };
  std::set<std::pair<index_t, index_t>> edges;  // the patch's directed edges
  for (index_t t : patch) {
    const index_t* v = &kidney.triangles[3 * t];
    tri(ids[v[0]].second, ids[v[1]].second, ids[v[2]].second);  // outer: outward as the kidney's
    for (int c = 0; c < 3; ++c) edges.insert({v[c], v[(c + 1) % 3]});
  }
  if (n_outer) *n_outer = out.n_triangles();
  for (index_t t : patch) {
    const index_t* v = &kidney.triangles[3 * t];
    tri(ids[v[0]].first, ids[v[2]].first, ids[v[1]].first);  // inner: reversed, facing the kidney
  }
  for (const auto& [a, b] : edges)
    if (!edges.count({b, a})) {  // a rim edge
      tri(ids[a].first, ids[b].first, ids[b].second);
      tri(ids[a].first, ids[b].second, ids[a].second);
      if (rim) rim->push_back({vertex(kidney, a), vertex(kidney, b)});
    }
  // A closed surface of a ball's topology: V - E + F = 2 with every edge in two triangles.
  const index_t n_edges = 3 * out.n_triangles() / 2;
  if (out.n_vertices() - n_edges + out.n_triangles() != 2)
    throw std::logic_error("kidney_fat_surface: the layer's surface is not closed with a ball's topology");
  return out;
}

}  // namespace

SurfaceMesh kidney_fat_surface() {
  return fat_layer(nullptr, nullptr);
}

scene::Scene kidney_fat_scene() {
  using K = KidneyScene;
  using F = KidneyFatScene;
  double kidney_volume = 0;
  scene::Scene s = kidney_scene(&kidney_volume);
  s.source = "@kidney-fat";
  const index_t kidney_nodes = index_t(s.nodes.size() / 3), kidney_elements = index_t(s.tets.size() / 4);
  s.bodies.push_back({"kidney", "", 0, 0, 0, kidney_nodes, 0, kidney_elements});
  for (scene::ElementSet& es : s.sets) es.body = 0;
  for (scene::Constraint& c : s.constraints) c.body = 0;

  index_t n_outer = 0;
  std::vector<std::pair<Vec3<double>, Vec3<double>>> rim;
  const SurfaceMesh surface = fat_layer(&n_outer, &rim);
  MeshingOptions meshing;
  meshing.quality = K::quality;
  meshing.max_volume = F::size_ratio * kidney_volume;
  const VolumeMesh fat = tetrahedralize_surface(surface, meshing, "built-in kidney's fat");
  s.nodes.insert(s.nodes.end(), fat.nodes.begin(), fat.nodes.end());
  for (index_t v : fat.tets) s.tets.push_back(v + kidney_nodes);
  s.bodies.push_back({"fat", "", 0, 0, kidney_nodes, fat.n_nodes(), kidney_elements, fat.n_tets()});

  add_material(s, "fat", F::E, F::nu, F::rho, 1);

  // The rim is held: every node of the layer on a wall, which lies in the
  // plane through the centre and a rim edge's kidney vertices, between their rays.
  scene::Constraint held;
  held.kind = scene::Constraint::Kind::Nodes;
  held.body = 1;
  for (index_t i = 0; i < fat.n_nodes(); ++i) {
    const Vec3<double> x = fat.node(i);
    for (const auto& [a, b] : rim) {
      const Vec3<double> n = unit(cross(a, b));
      if (std::fabs(dot(x, n)) < 1e-10 && dot(cross(a, x), n) >= -1e-12 && dot(cross(x, b), n) >= -1e-12) {
        held.nodes.push_back(i + kidney_nodes);
        break;
      }
    }
  }
  s.constraints.push_back(std::move(held));
  s.contacts.push_back({"kidney", "fat", 0, 0});

  // The probe presses through the layer: aimed at where the ray along +y
  // leaves the layer's outer side, along that triangle's inward normal.
  SurfaceMesh outer = surface;
  outer.triangles.resize(3 * std::size_t(n_outer));
  const Vec3<double> touch = surface_point_along(outer, {0, 1, 0});
  const index_t t = surface_triangle_along(outer, {0, 1, 0});
  const Vec3<double> c0 = vertex(outer, outer.triangles[3 * t]), c1 = vertex(outer, outer.triangles[3 * t + 1]),
                     c2 = vertex(outer, outer.triangles[3 * t + 2]);
  const Vec3<double> outward = unit(cross(c1 - c0, c2 - c0));
  for (scene::Tool& tool : s.tools) {
    tool.direction = outward;
    tool.path = press_path(touch + K::tool_radius * outward, -1.0 * outward, K::press_depth, K::approach);
  }
  return s;
}

scene::Scene viscoelastic_kidney_scene() {
  scene::Scene s = default_kidney_scene();
  s.source = "@kidney-visco";
  for (scene::Material& m : s.materials)
    for (int i = 0; i < 2; ++i) m.prony.push_back({kKidneyPronyG[i], kKidneyPronyTau[i], 0});
  for (scene::Tool& t : s.tools) {
    // press_path: start, touch, deep, deep (the hold's end), start: lengthen the hold
    std::vector<Waypoint>& w = t.path;
    if (w.size() != 5) continue;
    const double extra = kKidneyViscoHold - (w[3].t - w[2].t);
    w[3].t += extra;
    w[4].t += extra;
  }
  return s;
}

std::optional<scene::Scene> builtin_scene(const std::string& name) {
  if (name == "@kidney") return default_kidney_scene();
  if (name == "@kidney-visco") return viscoelastic_kidney_scene();
  if (name == "@kidney-fat") return kidney_fat_scene();
  return std::nullopt;
}

bool is_builtin_scene(const std::string& name) {
  return name == "@kidney" || name == "@kidney-visco" || name == "@kidney-fat";
}

}  // namespace tissue::io
