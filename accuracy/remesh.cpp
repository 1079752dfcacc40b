#include "accuracy/remesh.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <stdexcept>

#include "accuracy/point_locator.hpp"
#include "io/kidney.hpp"
#include "io/tetgen_mesher.hpp"
#include "scene/validate.hpp"

namespace tissue::accuracy {
namespace {

/// The boundary surface of a model (its outward triangles), with compacted vertex ids.
io::SurfaceMesh boundary_surface(const TissueModel<double>& m) {
  io::SurfaceMesh s;
  std::map<index_t, index_t> id;
  for (index_t t = 0; t < m.n_tris; ++t)
    for (int v = 0; v < 3; ++v) {
      const index_t a = m.tris[v * m.n_tris + t];
      auto [it, fresh] = id.emplace(a, static_cast<index_t>(id.size()));
      if (fresh)
        for (int c = 0; c < 3; ++c) s.vertices.push_back(m.X[c * m.n_nodes + a]);
      s.triangles.push_back(it->second);
    }
  return s;
}

/// The kidney's hilum rule on a new mesh (io/kidney.cpp's construction).
std::vector<index_t> kidney_fixed_nodes(const std::vector<double>& nodes) {
  const Vec3<double> hilum = io::kidney_hilum_centre();
  std::vector<index_t> fixed;
  for (index_t i = 0; i < static_cast<index_t>(nodes.size() / 3); ++i) {
    const Vec3<double> x{nodes[3 * i], nodes[3 * i + 1], nodes[3 * i + 2]};
    if (norm(x - hilum) <= io::KidneyScene::fix_radius) fixed.push_back(i);
  }
  return fixed;
}

/// Moves id-based constraints and element sets from the old model onto the new mesh (see remesh.hpp).
void transfer_ids(const scene::Scene& old_scene, const TissueModel<double>& old_model, scene::Scene& s) {
  const PointLocator loc(old_model);
  const index_t n_new = static_cast<index_t>(s.nodes.size() / 3), ne_new = static_cast<index_t>(s.tets.size() / 4);
  const index_t ne_old = old_model.n_elems;
  auto old_nearest = [&](Vec3<double> p) {
    const Location l = loc.locate(p);
    if (l.elem < 0) throw std::runtime_error(fmt::format("{}: re-meshed node lies outside the old mesh", s.source));
    int best = 0;
    for (int a = 1; a < 4; ++a)
      if (l.bary[a] > l.bary[best]) best = a;
    return old_model.elem_nodes[best * ne_old + l.elem];
  };
  for (std::size_t k = 0; k < s.constraints.size(); ++k) {
    scene::Constraint& c = s.constraints[k];
    if (c.kind != scene::Constraint::Kind::Nodes) continue;
    std::vector<std::uint8_t> was(old_model.n_nodes, 0);
    for (index_t a : old_scene.constraints[k].nodes) was[a] = 1;
    c.nodes.clear();
    for (index_t i = 0; i < n_new; ++i)
      if (was[old_nearest({s.nodes[3 * i], s.nodes[3 * i + 1], s.nodes[3 * i + 2]})]) c.nodes.push_back(i);
  }
  std::vector<int> set_of(ne_old, -1);
  bool listed = false;
  for (std::size_t k = 0; k < s.sets.size(); ++k)
    if (!s.sets[k].all) {
      listed = true;
      for (index_t e : old_scene.sets[k].elements) set_of[e] = static_cast<int>(k);
      s.sets[k].elements.clear();
    }
  if (!listed) return;
  for (index_t e = 0; e < ne_new; ++e) {
    Vec3<double> c{0, 0, 0};
    for (int a = 0; a < 4; ++a) {
      const index_t i = s.tets[4 * e + a];
      c = c + 0.25 * Vec3<double>{s.nodes[3 * i], s.nodes[3 * i + 1], s.nodes[3 * i + 2]};
    }
    const Location l = loc.locate(c);
    const int k = l.elem >= 0 ? set_of[l.elem] : -1;
    if (k >= 0) s.sets[k].elements.push_back(e);
  }
}

}  // namespace

int kidney_frequency(int target_tets) {
  const double f = io::KidneyScene::frequency * std::cbrt(double(target_tets) / io::KidneyScene::target_tets);
  return std::clamp(static_cast<int>(std::lround(f)), 2, 64);
}

scene::Scene remesh_scene(const scene::Scene& scene, int target_tets) {
  return remesh_scene(scene, target_tets, KidneySurfacing{});
}

scene::Scene remesh_scene(const scene::Scene& scene, int target_tets, const KidneySurfacing& surfacing) {
  if (target_tets < 1) throw std::invalid_argument(fmt::format("remesh: target tet count {} must be >= 1", target_tets));
  if (!scene.bodies.empty())
    throw std::invalid_argument(fmt::format("remesh: {}: a scene of {} bodies; re-meshing takes a scene of one mesh "
                                            "(converge each body in a scene of its own)",
                                            scene.source, scene.bodies.size()));
  const bool custom = surfacing.frequency != 0 || surfacing.focus != 1.0;
  if (custom && scene.source != "@kidney")
    throw std::invalid_argument(fmt::format("remesh: {}: a surface frequency or focus applies to @kidney only",
                                            scene.source));
  scene::Scene s = scene;
  io::MeshingOptions opt;
  opt.target_tets = target_tets;
  if (scene.source == "@kidney") {
    opt.quality = io::KidneyScene::quality;
    io::SurfaceFocus focus;
    focus.scale = surfacing.focus;
    if (surfacing.focus != 1.0) {
      if (scene.tools.empty() || scene.tools.front().path.empty())
        throw std::invalid_argument("remesh: a focused kidney needs a scripted tool to focus on");
      const auto& path = scene.tools.front().path;
      const auto deepest = std::min_element(path.begin(), path.end(),
                                            [](const Waypoint& a, const Waypoint& b) { return norm(a.p) < norm(b.p); });
      focus.toward = io::kidney_sphere_direction(io::KidneyShape{}, deepest->p);
    }
    const int frequency = surfacing.frequency > 0 ? surfacing.frequency : kidney_frequency(target_tets);
    io::VolumeMesh mesh = io::tetrahedralize_surface(io::kidney_surface(frequency, io::KidneyShape{}, focus), opt,
                                                     "built-in kidney");
    s.nodes = std::move(mesh.nodes);
    s.tets = std::move(mesh.tets);
    for (scene::Constraint& c : s.constraints)
      if (c.kind == scene::Constraint::Kind::Nodes) c.nodes = kidney_fixed_nodes(s.nodes);
    return s;
  }
  const TissueModel<double> old_model = scene::load_model(scene);
  io::VolumeMesh mesh = io::tetrahedralize_surface(boundary_surface(old_model), opt, scene.source);
  s.nodes = std::move(mesh.nodes);
  s.tets = std::move(mesh.tets);
  s.mesh_file.clear();
  transfer_ids(scene, old_model, s);
  return s;
}

}  // namespace tissue::accuracy
