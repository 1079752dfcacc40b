// tissue mesh: surface file -> TetGen volume mesh -> scene XML with one
// material, a fixed base and a scripted tool pressing on the top.
//
// Defaults chosen for a first run of an unknown organ (document in README):
// - the nodes in the lowest 5% of the height (z) are fixed (the organ rests
//   on its support);
// - one scripted probe approaches the topmost surface point under the centre
//   of the bounding box from 1 cm above, presses min(5 mm, 10% of the
//   height), holds, and retracts.
#include <fmt/format.h>

#include <algorithm>
#include <memory>

#include "apps/commands.hpp"
#include "core/tet.hpp"
#include "io/kidney.hpp"
#include "io/scene_xml.hpp"
#include "io/surface_import.hpp"
#include "io/tetgen_mesher.hpp"

namespace tissue::app {
namespace {

struct MeshOptions {
  std::string surface, out, unit = "m";
  io::MeshingOptions meshing;
  double E = 3000, nu = 0.45, rho = 1000;
  double fix_fraction = 0.05;
};

/// Topmost surface point straight above or below (cx, cy), by a vertical
/// segment through the whole surface; throws if the vertical misses.
Vec3<double> top_point(const io::SurfaceMesh& s, double cx, double cy, double zlo, double zhi) {
  const Vec3<double> a{cx, cy, zhi + 1.0}, b{cx, cy, zlo - 1.0};
  double best = 2.0;
  for (size_t t = 0; t < s.triangles.size() / 3; ++t) {
    Vec3<double> p[3];
    for (int k = 0; k < 3; ++k) {
      const index_t v = s.triangles[3 * t + k];
      p[k] = {s.vertices[3 * v], s.vertices[3 * v + 1], s.vertices[3 * v + 2]};
    }
    double bary[2];
    const double hit = segment_triangle(a, b, p[0], p[1], p[2], bary);
    if (hit >= 0 && hit < best) best = hit;
  }
  if (best > 1.0) throw std::runtime_error("the vertical through the bounding-box centre misses the surface");
  return a + best * (b - a);
}

scene::Scene make_scene(const MeshOptions& o) {
  const double unit = io::parse_unit(o.unit);
  fmt::print("reading {} (unit: {}, {} m per file unit)\n", o.surface, o.unit, unit);
  io::SurfaceMesh surf = io::load_surface(o.surface, unit);
  io::VolumeMesh vol = io::tetrahedralize_surface(surf, o.meshing, o.surface);
  scene::Scene s;
  s.source = o.out;
  s.nodes = vol.nodes;
  s.tets = vol.tets;
  s.materials.push_back({.name = "tissue", .form = scene::Material::Form::YoungPoisson, .a = o.E, .b = o.nu, .rho = o.rho});
  scene::ElementSet all;
  all.name = "all";
  all.material = "tissue";
  all.all = true;
  s.sets.push_back(all);
  double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
  for (size_t i = 0; i < s.nodes.size(); ++i) {
    lo[i % 3] = std::min(lo[i % 3], s.nodes[i]);
    hi[i % 3] = std::max(hi[i % 3], s.nodes[i]);
  }
  scene::Constraint base;
  base.kind = scene::Constraint::Kind::Plane;
  base.point[2] = lo[2] + o.fix_fraction * (hi[2] - lo[2]);
  base.normal[2] = -1;  // fixes (x - point) . normal >= 0: the nodes below the plane
  s.constraints.push_back(base);
  const double height = hi[2] - lo[2];
  const Vec3<double> target = top_point(surf, 0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), lo[2], hi[2]);
  scene::Tool tool;
  tool.radius = 2e-3;
  tool.path = press_path(target, {0, 0, -1}, std::min(5e-3, 0.1 * height), 1e-2);
  s.tools.push_back(tool);
  fmt::print("meshed: {} nodes, {} tets; fixed base below z = {:.4g} m; tool presses at ({:.4g}, {:.4g}, {:.4g}) m\n",
             s.nodes.size() / 3, s.tets.size() / 4, base.point[2], target.x, target.y, target.z);
  return s;
}

}  // namespace

void add_mesh_command(CLI::App& app, int& rc) {
  auto* cmd = app.add_subcommand("mesh", "Tetrahedralise a closed surface (OBJ, STL, PLY, OFF, 3DS, ...) into a scene");
  auto o = std::make_shared<MeshOptions>();
  cmd->add_option("surface", o->surface, "Surface file, or @kidney to write the built-in kidney scene")->required();
  cmd->add_option("-o,--output", o->out, "Scene XML to write")->required();
  cmd->add_option("--unit", o->unit, "Length unit of the surface file: m, cm or mm")->default_val("m");
  cmd->add_option("--quality", o->meshing.quality, "TetGen radius-edge ratio bound (q)")->default_val(1.414);
  cmd->add_option("--max-volume", o->meshing.max_volume, "Largest tet volume (m^3; 0 = no bound)")->default_val(0);
  cmd->add_option("--target-tets", o->meshing.target_tets, "Aim at about this many tets (0 = off)")->default_val(0);
  cmd->add_option("--E", o->E, "Young's modulus (Pa)")->default_val(3000);
  cmd->add_option("--nu", o->nu, "Poisson's ratio")->default_val(0.45);
  cmd->add_option("--rho", o->rho, "Density (kg/m^3)")->default_val(1000);
  cmd->callback([o, &rc] {
    scene::Scene s = o->surface == "@kidney" ? io::default_kidney_scene() : make_scene(*o);
    io::write_scene(s, o->out, true);
    fmt::print("wrote {} ({} tets)\n", o->out, s.tets.size() / 4);
    rc = 0;
  });
}

}  // namespace tissue::app
