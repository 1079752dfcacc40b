#include "accuracy/palpation.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <stdexcept>

#include "accuracy/reference.hpp"
#include "core/model.hpp"
#include "io/kidney.hpp"
#include "io/organ_mesher.hpp"
#include "scene/scene.hpp"

namespace tissue::accuracy {
namespace {

/// The closed surface of the box [0, L]^2 x [0, H], outward triangles.
io::SurfaceMesh box_surface(double L, double H) {
  io::SurfaceMesh s;
  for (int k = 0; k < 8; ++k) s.vertices.insert(s.vertices.end(), {(k & 1) ? L : 0.0, (k & 2) ? L : 0.0, (k & 4) ? H : 0.0});
  // faces as quads (corners counter-clockwise seen from outside), four triangles each around the face's
  // centre (no diagonal through the block's symmetry lines)
  const int q[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& f : q) {
    const index_t c = s.n_vertices();
    for (int a = 0; a < 3; ++a)
      s.vertices.push_back(0.25 * (s.vertices[3 * f[0] + a] + s.vertices[3 * f[1] + a] + s.vertices[3 * f[2] + a] +
                                   s.vertices[3 * f[3] + a]));
    for (int k = 0; k < 4; ++k) s.triangles.insert(s.triangles.end(), {f[k], f[(k + 1) % 4], c});
  }
  return s;
}

/// mu and K from E and nu: the scene's own conversion.
MaterialParams material(double E, double nu, double rho) {
  return scene::Material{.name = "", .form = scene::Material::Form::YoungPoisson, .a = E, .b = nu, .rho = rho, .line = 0}
      .params();
}

}  // namespace

PalpationScan run_palpation(const PalpationOptions& o) {
  if (!(o.L > 0 && o.H > 0 && o.tumour_radius > 0 && o.tumour_depth > o.tumour_radius &&
        o.tumour_depth + o.tumour_radius < o.H && 2 * o.tumour_radius < o.L))
    throw std::invalid_argument(fmt::format(
        "palpation: the tumour (radius {:g} m, centre {:g} m deep) must lie inside the {:g} x {:g} x {:g} m block",
        o.tumour_radius, o.tumour_depth, o.L, o.L, o.H));
  if (!(o.positions >= 2 && o.scan > 0 && o.scan + 2 * o.tool_radius < o.L && o.tool_radius > 0 && o.press > 0 &&
        o.press < o.tumour_depth - o.tumour_radius))
    throw std::invalid_argument(fmt::format(
        "palpation: the scan ({:g} m) and the tool (radius {:g} m) must stay on the top, and the press ({:g} m) "
        "above the tumour's top ({:g} m deep)",
        o.scan, o.tool_radius, o.press, o.tumour_depth - o.tumour_radius));
  if (!(o.stiffness_ratio > 0 && std::isfinite(o.stiffness_ratio)))
    throw std::invalid_argument(fmt::format("palpation: stiffness ratio {} must be > 0", o.stiffness_ratio));
  io::OrganMeshOptions mo;
  mo.mesher = io::Mesher::TetGen;
  mo.meshing.target_tets = o.target_tets;
  mo.remesh_edge = -1;  // the box and the sphere are meshed as built (TetGen refines their faces)
  io::KidneyShape sphere;
  sphere.a = sphere.b = sphere.c = o.tumour_radius;
  sphere.bean = sphere.hilum = 0;
  io::SurfaceMesh t = io::kidney_surface(6, sphere);
  for (std::size_t k = 0; k < t.vertices.size(); k += 3) {
    t.vertices[k] += 0.5 * o.L;
    t.vertices[k + 1] += 0.5 * o.L;
    t.vertices[k + 2] += o.H - o.tumour_depth;
  }
  std::vector<io::NamedSurface> inclusions;
  inclusions.push_back({std::move(t), "tumour"});
  const io::OrganMesh om = io::mesh_organ({box_surface(o.L, o.H), "palpation block"}, std::move(inclusions), mo);
  ModelInput in;
  in.nodes = om.mesh.nodes;
  in.tets = om.mesh.tets;
  in.material_names = {"tissue", "tumour"};
  const std::size_t ne = in.tets.size() / 4;
  in.elem_material.assign(ne, 0);
  PalpationScan scan;
  for (std::size_t e = 0; e < ne; ++e)
    if (!om.mesh.tet_region.empty() && om.mesh.tet_region[e] > 0) {
      in.elem_material[e] = 1;
      ++scan.tumour_tets;
    }
  if (scan.tumour_tets == 0) throw std::runtime_error("palpation: the mesher gave the tumour no elements");
  in.fixed.assign(in.nodes.size() / 3, 0);
  for (std::size_t i = 0; i < in.fixed.size(); ++i) in.fixed[i] = in.nodes[3 * i + 2] == 0.0;
  in.dt_safety = 0.9;
  ReferenceOptions ro;
  ro.backend = o.backend;
  ro.relax.residual_tol = o.residual;
  ro.relax.kinetic_tol = 1e-3 * o.residual;
  for (int pass = 0; pass < 2; ++pass) {  // the tumour, then the baseline on the same mesh
    const double ratio = pass == 0 ? o.stiffness_ratio : 1.0;
    in.materials = {material(o.E, o.nu, o.rho), material(ratio * o.E, o.nu, o.rho)};
    in.source = fmt::format("palpation block, tumour E x {:g}", ratio);
    const TissueModel<double> m = build_model(in);
    scan.nodes = m.n_nodes;
    scan.tets = m.n_elems;
    std::vector<PalpationPoint>& points = pass == 0 ? scan.with : scan.without;
    for (int k = 0; k < o.positions; ++k) {
      const double x = -0.5 * o.scan + o.scan * k / (o.positions - 1);
      HeldTool tool;
      tool.shape = {"probe", o.tool_radius, 0.0};
      const Vec3<double> above{0.5 * o.L + x, 0.5 * o.L, o.H + o.tool_radius};
      tool.start = {above + Vec3<double>{0, 0, 0.5 * o.tool_radius}, {0, 0, 1}};
      tool.held = {above - Vec3<double>{0, 0, o.press}, {0, 0, 1}};
      points.push_back({x, reference_solution(m, {}, ro, &tool).tool_force});
    }
  }
  return scan;
}

}  // namespace tissue::accuracy
