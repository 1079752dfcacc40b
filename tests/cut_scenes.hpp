// The blocks the cutting tests share (tests/test_live_cut.cpp, the viewer's
// scalpel in tests/test_viewer_session.cpp, `tissue run` in
// tests/test_app.cpp): a soft block held at its base, with a probe parked
// above it or a blade pushed down through it.
#pragma once

#include "core/box_mesh.hpp"
#include "scene/scene.hpp"

namespace tissue::test {

/// A 20 x 20 x 10 mm block of 4 x 4 x 2 cells (5 mm), E 3 kPa, nu 0.4, its
/// base held; no mass scaling (the mass is then the volume's, exactly); a
/// probe parked far above; the whole mesh, in double.
inline scene::Scene block_scene(int cells = 4) {
  scene::Scene s;
  ModelInput in;
  box_mesh(in, cells, cells, cells / 2, 0.02, 0.02, 0.01);
  s.source = "block";
  s.nodes = in.nodes;
  s.tets = in.tets;
  s.materials.push_back({.name = "soft", .form = scene::Material::Form::YoungPoisson, .a = 3000, .b = 0.4, .rho = 1000});
  s.sets.push_back({.name = "soft", .material = "soft", .all = true, .elements = {}});
  scene::Constraint base;
  base.kind = scene::Constraint::Kind::Box;
  base.lo[0] = base.lo[1] = base.lo[2] = -1;
  base.hi[0] = base.hi[1] = 1;
  base.hi[2] = 1e-4;
  s.constraints = {base};
  scene::Tool probe;
  probe.radius = 2e-3;
  probe.path = {{0, {0.01, 0.01, 0.05}}, {1, {0.01, 0.01, 0.05}}};
  s.tools = {probe};
  s.solver.precision = Precision::Double;
  s.solver.depth = kDepthAll;
  s.solver.mass_scaling = 0;
  return s;
}

/// The 8 x 8 x 4 block (2.5 mm cells) with a blade above it: a 30 mm edge
/// along y across the whole block at x = 11.2 mm (between the nodes),
/// 1 mm thick, moved straight down at 9.5 mm/s from 1.5 mm above the top to
/// `to_z`, its button (cutting) held or not. No mass scaling, dt 0.5 dt_crit.
inline scene::Scene blade_scene(bool cutting, double resistance, double to_z = 0.002, double delay = 0) {
  scene::Scene sc = block_scene(8);
  scene::Tool blade;
  blade.kind = scene::Tool::Kind::Blade;
  blade.name = "scalpel";
  blade.radius = 5e-4;
  blade.shaft = 0.03;
  blade.cut_resistance = resistance;
  blade.cut_delay = delay;
  blade.direction = {0, 1, 0};
  const double x = 0.0112, y = -0.005, t1 = (0.0115 - to_z) / 0.0095;
  blade.path = {{0, {x, y, 0.0115}, cutting}, {t1, {x, y, to_z}, cutting}};
  sc.tools = {blade};
  sc.solver.dt_safety = 0.5;
  return sc;
}

}  // namespace tissue::test
