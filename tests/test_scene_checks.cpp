// The checks of a valid scene that may not do what its author meant
// (scene/checks.hpp): no support, every node fixed, an unsupported piece of
// the mesh, a load on fixed nodes only, damping far above the lowest mode, a
// tick longer than the tool path or far from 1 ms, many steps per tick with
// their cause, a material more incompressible than the precision resolves,
// reoriented tets, and the work estimate; and the mesh box that tool reach is
// measured in (scene/validate.hpp).
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "core/box_mesh.hpp"
#include "scene/checks.hpp"
#include "scene/validate.hpp"

namespace tissue::scene {
namespace {

/// A 2 x 1 x 1 cm box of brain-like tissue, its bottom fixed, pressed by a
/// probe over 0.1 s.
Scene box_scene() {
  Scene s;
  s.source = "box.xml";
  ModelInput in;
  box_mesh(in, 2, 1, 1, 0.02, 0.01, 0.01);
  s.nodes = in.nodes;
  s.tets = in.tets;
  s.materials.push_back({.name = "brain", .form = Material::Form::YoungPoisson, .a = 3000, .b = 0.45, .rho = 1000});
  s.sets.push_back({.name = "all", .material = "brain", .all = true, .elements = {}, .line = 0});
  Constraint base;
  base.kind = Constraint::Kind::Box;
  base.lo[0] = base.lo[1] = base.lo[2] = -1;
  base.hi[0] = base.hi[1] = 1;
  base.hi[2] = 0;
  s.constraints.push_back(base);
  Tool t;
  t.path = {{0, {0.01, 0.005, 0.02}}, {0.1, {0.01, 0.005, 0.008}}};
  s.tools.push_back(t);
  return s;
}

/// The warnings of a scene, with a check that each starts with the scene
/// file ("box.xml: ", or "box.xml:21: " for a warning about one element).
std::vector<std::string> warnings(const Scene& s) {
  const std::vector<std::string> w = scene_warnings(s, load_model(s));
  for (const std::string& m : w) EXPECT_EQ(m.rfind(s.source + ":", 0), 0u) << m;
  return w;
}

/// Success when exactly one warning contains every part.
testing::AssertionResult one_warning(const std::vector<std::string>& w, std::initializer_list<std::string> parts) {
  int hits = 0;
  for (const std::string& m : w) {
    bool all = true;
    for (const std::string& p : parts) all = all && m.find(p) != std::string::npos;
    hits += all;
  }
  if (hits == 1) return testing::AssertionSuccess();
  auto f = testing::AssertionFailure() << hits << " warnings match; the warnings are:";
  for (const std::string& m : w) f << "\n  " << m;
  return f;
}

TEST(SceneChecks, AnOrdinaryScenePassesSilently) {
  EXPECT_TRUE(warnings(box_scene()).empty());
}

TEST(SceneChecks, NoSupportAndEverythingFixed) {
  Scene s = box_scene();
  s.constraints.clear();
  const auto w = warnings(s);
  EXPECT_TRUE(one_warning(w, {"no node is fixed", "rigid body", "<fixed>"}));
  s = box_scene();
  s.constraints.front().hi[2] = 1;  // the box now holds every node
  EXPECT_TRUE(one_warning(warnings(s), {"every node (12) is fixed", "nothing can move"}));
}

TEST(SceneChecks, TickLongerThanThePathOrFarFromOneMillisecond) {
  Scene s = box_scene();
  s.solver.tick = 0.5;
  const auto w = warnings(s);
  EXPECT_TRUE(one_warning(w, {"tick 0.5 s is longer than the whole tool path (0.1 s)", "in one tick"}));
  EXPECT_TRUE(one_warning(w, {"tick 0.5 s is far from a haptic device's period"}));
  s.solver.tick = 1e-7;
  EXPECT_TRUE(one_warning(warnings(s), {"tick 1e-07 s is far from"}));
}

// Every scripted tool's path is checked against the tick, not only the first's.
TEST(SceneChecks, TickLongerThanTheSecondToolsPath) {
  Scene s = box_scene();
  s.tools.front().name = "probe";
  Tool grasper;
  grasper.name = "grasper";
  grasper.path = {{0, {0.005, 0.005, 0.02}}, {0.002, {0.005, 0.005, 0.015}}};
  s.tools.push_back(grasper);
  s.solver.tick = 0.005;
  const auto w = warnings(s);
  EXPECT_TRUE(one_warning(w, {"tick 0.005 s is longer than the whole tool path (0.002 s) of tool 'grasper'"}));
  EXPECT_TRUE(one_warning(w, {"longer than the whole tool path"}));  // not the probe's 0.1 s path
}

TEST(SceneChecks, ManyStepsPerTickNameTheirCause) {
  Scene s = box_scene();
  s.materials.front().a = 1e12;  // a unit slip: E in Pa x 1e9
  s.solver.mass_scaling = 0;
  const TissueModel<double> m = load_model(s);
  const double steps = std::round(s.solver.tick / m.dt);
  EXPECT_GT(steps, kManyStepsPerTick);
  EXPECT_TRUE(one_warning(warnings(s), {fmt::format("{:.0f} TLED steps per 0.001 s tick", steps),
                                        "material 'brain' (E = 1000000000000 Pa", "wave speed", "dt_crit"}));
  const WorkEstimate w = estimate_work(m, s.solver.tick, 300);
  EXPECT_EQ(w.steps_per_tick, steps);
  EXPECT_EQ(w.steps, 300 * steps);
  EXPECT_EQ(w.element_steps, 300 * steps * m.n_elems);
  // its time at the backend's nominal rates
  const StepCost cpu = nominal_step_cost("cpu");
  EXPECT_DOUBLE_EQ(w.seconds, w.steps * cpu.per_step + w.element_steps * cpu.per_element);
  const StepCost gpu = nominal_step_cost("cuda");  // more a step (launches), less an element
  EXPECT_GT(gpu.per_step, cpu.per_step);
  EXPECT_LT(gpu.per_element, cpu.per_element);
  EXPECT_DOUBLE_EQ(estimate_work(m, s.solver.tick, 300, "cuda").seconds,
                   w.steps * gpu.per_step + w.element_steps * gpu.per_element);
}

// The step's cause prints the moduli its wave speed follows from, the
// fibre's share included (it printed E, nu and rho and a speed that had the
// fibre in it).
TEST(SceneChecks, StepCausePrintsTheModuliOfItsSpeed) {
  Scene s = box_scene();
  s.materials.front().fibre_eta = 1e13;
  s.materials.front().fibre_line = 0;
  s.solver.mass_scaling = 0;
  const TissueModel<double> m = load_model(s);
  const std::string cause = step_cause(s, m);
  const MaterialParams p = s.materials.front().params();
  const double c = std::sqrt((p.K + 4 * p.mu / 3 + 4 * 1e13) / 1000);
  EXPECT_NE(cause.find("fibre stiffness eta = 10000000000000 Pa"), std::string::npos) << cause;
  EXPECT_NE(cause.find(fmt::format("c = sqrt((K + 4 mu / 3 + 4 eta) / rho) = sqrt(({:.4g} Pa + 4 x {:.4g} Pa / 3 + "
                                   "4 x 1e+13 Pa) / 1000 kg/m^3) = {:.4g} m/s",
                                   p.K, p.mu, c)),
            std::string::npos)
      << cause;
}

// A run that stops (NaN, an inverted element) names the values most likely
// to blame, each against the range or limit it broke; it blamed the tool's
// indentation whatever the scene held.
TEST(SceneChecks, StopCausesNameTheParameter) {
  Scene s = box_scene();
  EXPECT_TRUE(stop_causes(s, load_model(s)).empty());  // brain-like tissue, supported, no load
  const auto one = [](const std::vector<std::string>& causes, std::initializer_list<std::string> parts) {
    return one_warning(causes, parts);
  };
  Scene e = box_scene();
  e.materials.front().a = 1e15;
  EXPECT_TRUE(one(stop_causes(e, load_model(e)), {"material 'brain'", "E = 1e+15 Pa", "far outside soft tissue's"}));
  Scene u = box_scene();  // E from mu and K without their product, which underflows
  u.materials.front().a = 1e-300;
  EXPECT_TRUE(one(stop_causes(u, load_model(u)), {"material 'brain'", "E = 1e-300 Pa", "far outside soft tissue's"}));
  Scene r = box_scene();
  r.materials.front().rho = 1e-12;
  EXPECT_TRUE(one(stop_causes(r, load_model(r)), {"material 'brain'", "density rho = 1e-12 kg/m^3", "kg/m^3)"}));
  Scene t = box_scene();
  t.materials.front().prony = {{0.5, 1e-12, 0}};
  const TissueModel<double> tm = load_model(t);
  EXPECT_TRUE(one(stop_causes(t, tm), {"material 'brain': Prony term 1: tau = 1e-12 s is shorter than the step dt = "
                                       + fmt::format("{:.4g} s", tm.dt)}));
  Scene l = box_scene();
  Load load;
  load.where.kind = Constraint::Kind::Box;
  load.where.lo[0] = load.where.lo[1] = -1;
  load.where.lo[2] = 0.01;
  load.where.hi[0] = load.where.hi[1] = load.where.hi[2] = 1;
  load.force[2] = -1e6;
  l.loads.push_back(load);
  EXPECT_TRUE(one(stop_causes(l, load_model(l)),
                  {"load box", "total force 1e+06 N over the body's extent L = 0.02 m squared is a nominal stress "
                               "F / L^2 = 2.5e+09 Pa", "check the force (N)"}));
  l.loads.front().force[2] = -0.05;  // 125 Pa: a load tissue takes
  EXPECT_TRUE(stop_causes(l, load_model(l)).empty());
}

TEST(SceneChecks, IncompressibilityBeyondThePrecision) {
  Scene s = box_scene();
  s.materials.front().b = 0.4999999;  // K / mu = 5e6
  const auto w = warnings(s);
  EXPECT_TRUE(one_warning(w, {"material 'brain'", "nearly incompressible", "float precision", "or precision double"}));
  s.solver.precision = Precision::Double;  // eps 2.2e-16: resolved
  EXPECT_TRUE(incompressibility_findings(s).empty());
  s.materials.front().b = 0.49;
  s.solver.precision = Precision::Float;
  EXPECT_TRUE(incompressibility_findings(s).empty());
}

TEST(SceneChecks, ReorientedTetsAreCounted) {
  Scene s = box_scene();
  std::swap(s.tets[4 * 3 + 0], s.tets[4 * 3 + 1]);  // elements 3 and 5 inverted
  std::swap(s.tets[4 * 5 + 0], s.tets[4 * 5 + 1]);
  EXPECT_TRUE(one_warning(warnings(s), {"2 of 12 tetrahedra had a negative volume", "reoriented"}));
}

TEST(SceneChecks, MeshBoxMeasuresTheToolReach) {
  const std::vector<double> nodes = {0, 0, 0, 3, 4, 0, 1, 1, 12};
  const MeshBox b = mesh_box(nodes);
  EXPECT_EQ(b.size, 13);
  EXPECT_EQ(b.distance({1, 1, 1}), 0);
  EXPECT_EQ(b.distance({-3, 8, 6}), 5);  // 3 below x, 4 beyond y
}

// A <load> on the fixed bottom face was accepted silently: its whole force
// went into the support.
TEST(SceneChecks, LoadOnlyOnFixedNodes) {
  Scene s = box_scene();
  Load l;
  l.where.kind = Constraint::Kind::Box;
  l.where.lo[0] = l.where.lo[1] = l.where.lo[2] = -1;
  l.where.hi[0] = l.where.hi[1] = 1;
  l.where.hi[2] = 0;  // the bottom face, which the <fixed> box holds
  l.where.line = 21;
  l.force[2] = -0.1;
  s.loads.push_back(l);
  EXPECT_TRUE(one_warning(warnings(s), {"box.xml:21: load box min (-1, -1, -1) max (1, 1, 0)",
                                        "acts only on fixed nodes (6 node(s)", "does not feel it"}));
  s.loads.front().each = true;  // a force on each node: the same nodes
  EXPECT_TRUE(one_warning(warnings(s), {"box.xml:21: ", "acts only on fixed nodes"}));
  s.loads.front().where.lo[2] = 0.005;  // the top face instead
  s.loads.front().where.hi[2] = 1;
  EXPECT_TRUE(warnings(s).empty());
}

// A second, floating box beside a supported one was accepted silently: the
// "no node is fixed" check looked at the mesh as a whole.
TEST(SceneChecks, DisconnectedPieceWithoutSupport) {
  Scene s = box_scene();
  ModelInput in;
  box_mesh(in, 1, 1, 1, 0.01, 0.01, 0.01);
  const index_t first_node = index_t(s.nodes.size() / 3), first_elem = index_t(s.tets.size() / 4);
  for (size_t k = 0; k < in.nodes.size(); ++k) s.nodes.push_back(in.nodes[k] + (k % 3 == 2 ? 0.05 : 0.0));
  for (index_t a : in.tets) s.tets.push_back(a + first_node);
  const auto w = warnings(s);
  EXPECT_TRUE(one_warning(w, {"piece 2 of the 2 disconnected pieces of the mesh",
                              fmt::format("({} element(s) from element {}", in.tets.size() / 4, first_elem),
                              "(0, 0, 0.05) .. (0.01, 0.01, 0.06) m", "has no fixed node", "rigid body"}));
  EXPECT_EQ(w.size(), 1u);
  s.constraints.front().hi[2] = 0.05;  // now holds the second box's bottom too
  EXPECT_TRUE(warnings(s).empty());
}

// damping="1e12" was accepted silently: the body crept for years instead of
// following the tool.
TEST(SceneChecks, DampingFarAboveTheLowestMode) {
  Scene s = box_scene();
  s.solver.line = 30;
  s.solver.damping = 1e12;
  const double omega = lowest_mode_estimate(load_model(s));
  EXPECT_TRUE(one_warning(warnings(s), {"box.xml:30: solver: damping = 1e+12 1/s",
                                        fmt::format("the lowest mode's {:.4g} rad/s (more than 100)", omega),
                                        "overdamped", "use \"auto\""}));
  s.solver.damping = 10 * omega;  // five times critical: still responds
  EXPECT_TRUE(warnings(s).empty());
}

// A body 100 km across (a mesh in other units) and a Prony term relaxing within one step ran without a word.
TEST(SceneChecks, ABodyFarFromAnOrgansSizeAndAPronyTermBelowTheStepAreWarned) {
  Scene big = box_scene();
  for (double& x : big.nodes) x *= 5e3;  // 0.02 m -> 100 m (a mesh in mm read as m)
  EXPECT_TRUE(one_warning(warnings(big), {"box.xml: the body is 100 m across", "check the mesh's units"}));
  Scene tiny = box_scene();
  for (double& x : tiny.nodes) x *= 1e-3;  // 0.02 m -> 20 um (a mesh in um read as mm), the tool with it
  for (Tool& tool : tiny.tools) {
    tool.radius *= 1e-3;
    for (Waypoint& w : tool.path) w.p = 1e-3 * w.p;
  }
  EXPECT_TRUE(one_warning(warnings(tiny), {"the body is 2e-05 m across"}));
  Scene t = box_scene();
  t.materials.front().prony = {{0.3, 1e-9, 0}};
  const TissueModel<double> tm = load_model(t);
  EXPECT_TRUE(one_warning(warnings(t), {"material 'brain': Prony term 1: tau = 1e-09 s is shorter than the step dt = " +
                                           fmt::format("{:.4g} s", tm.dt),
                                       "acts as if it were not there"}));
  t.materials.front().prony = {{0.3, 1.0, 0}};  // a tau of many steps: no warning
  EXPECT_TRUE(warnings(t).empty());
}

}  // namespace
}  // namespace tissue::scene
