// The step guard (core/step_guard.hpp): an element's deformed altitude
// against its closed form, the density a crushed element gets, and the
// focused kidney pressed by its probe, whose crushed elements rang until
// one inverted without it. The backends' part (set_masses,
// deformed_altitudes) is in the backend contract.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>

#include "accuracy/convergence.hpp"
#include "accuracy/reference.hpp"
#include "accuracy/remesh.hpp"
#include "core/device.hpp"
#include "core/model.hpp"
#include "core/step_guard.hpp"
#include "io/kidney.hpp"
#include "scene/validate.hpp"
#include "session/engine.hpp"

using namespace tissue;

namespace {

constexpr double kA = 0.004, kH = 0.002;  // legs of the corner tet (m)

/// One corner tet (0,0,0), (a,0,0), (0,a,0), (0,0,h): its smallest
/// altitude is the one to its slanted face, a h / sqrt(2 h^2 + a^2).
ModelInput corner_tet() {
  ModelInput in;
  in.nodes = {0, 0, 0, kA, 0, 0, 0, kA, 0, 0, 0, kH};
  in.tets = {0, 1, 2, 3};
  const double E = 3000, nu = 0.45;
  in.materials = {{E / (2 * (1 + nu)), E / (3 * (1 - 2 * nu)), 1000}};
  in.fixed = {1, 1, 1, 0};
  in.source = "corner tet";
  return in;
}

double corner_altitude(double h) { return kA * h / std::sqrt(2 * h * h + kA * kA); }

/// The apex lowered to lambda h.
std::vector<double> crushed(double lambda) {
  std::vector<double> u(12, 0.0);
  u[2 * 4 + 3] = (lambda - 1) * kH;  // z of node 3
  return u;
}

}  // namespace

TEST(StepGuard, TheDeformedAltitudeIsTheClosedForms) {
  const TissueModel<double> m = build_model(corner_tet());
  for (const double lambda : {1.0, 0.5, 0.2})
    EXPECT_NEAR(deformed_altitude(m, std::span<const double>(crushed(lambda)), 0), corner_altitude(lambda * kH),
                1e-15);
  EXPECT_EQ(deformed_altitude(m, std::span<const double>(crushed(-0.1)), 0), 0.0);  // inverted
}

// The element's step at rest, its step crushed (the altitude's share), and
// the density that brings it back to target x dt: (target dt / step)^2,
// its mass spread over its corners.
TEST(StepGuard, ACrushedElementGetsTheDensityThatRestoresItsStep) {
  TissueModel<double> m = build_model(corner_tet());
  ASSERT_EQ(m.elem_step.size(), 1u);
  EXPECT_NEAR(m.elem_step[0], m.dt_crit, 1e-18);  // one element: it sets dt_crit
  EXPECT_NEAR(m.elem_mass[0], 1000 * kA * kA * kH / 6, 1e-15);
  StepGuardSettings s;
  EXPECT_FALSE(StepGuard(m, s).watching()) << "no mass scaling: nothing watched";
  // as if mass scaling had raised it, in a mesh of 10,000 times its mass (the budget is a share of the whole)
  m.scaled_elems = 1;
  m.total_mass *= 10000;
  const StepGuard watched(m, s);  // dt = 0.5 dt_crit: the element's step is 2 dt, within watch = 4 dt
  EXPECT_TRUE(watched.watching());
  s.watch = 1.5;
  EXPECT_FALSE(StepGuard(m, s).watching());
  s.watch = 4;
  StepGuard guard(m, s);
  std::vector<double> mass = m.mass;
  const std::vector<double> mass0 = m.mass;
  const index_t e = 0;
  // crushed to 0.4 of its height: its step is 2 dt x alt(0.4 h) / alt(h) = 0.94 dt, above the trigger (0.7)
  const double mild = 2 * corner_altitude(0.4 * kH) / corner_altitude(kH);
  ASSERT_GT(mild, s.trigger);
  const double a_mild = corner_altitude(0.4 * kH);
  StepGuardLift l = guard.lift(m, mass, std::span<const index_t>(&e, 1), std::span<const double>(&a_mild, 1));
  EXPECT_EQ(l.elements, 0);
  EXPECT_NEAR(l.worst, mild, 1e-12);
  EXPECT_EQ(mass, mass0);
  // to 0.1: its step falls to 0.24 dt, and it gets (1.25 dt / step)^2 its density
  const double a = corner_altitude(0.1 * kH), step = 2 * a / corner_altitude(kH);
  ASSERT_LT(step, s.trigger);
  l = guard.lift(m, mass, std::span<const index_t>(&e, 1), std::span<const double>(&a, 1));
  EXPECT_EQ(l.elements, 1);
  const double g = (s.target / step) * (s.target / step), extra = (g - 1) * 1000 * kA * kA * kH / 6;
  EXPECT_NEAR(l.added_mass, extra, 1e-12 * extra);
  for (int k = 0; k < 4; ++k) EXPECT_NEAR(mass[k], mass0[k] + extra / 4, 1e-12 * mass[k]);
  // the same shape again: its step is 1.25 dt now, the target, and it is left as it is
  l = guard.lift(m, mass, std::span<const index_t>(&e, 1), std::span<const double>(&a, 1));
  EXPECT_EQ(l.elements, 0);
  EXPECT_NEAR(l.worst, s.target, 1e-12);
  EXPECT_NEAR(guard.added_mass(), extra, 1e-12 * extra);
  // near a tool: its ball within reach of the capsule (the corner tet's centroid at (1, 1, 0.5) mm, 3.2 mm to
  // its farthest corner)
  const ToolShape probe{"probe", 1e-3, 0, 0};
  const ToolPose close{{0.001, 0.001, 0.004}, {0, 0, 1}}, far{{0.001, 0.001, 0.0052}, {0, 0, 1}};
  EXPECT_EQ(guard.near(std::span<const ToolShape>(&probe, 1), std::span<const ToolPose>(&close, 1), 0).size(), 1u);
  EXPECT_TRUE(guard.near(std::span<const ToolShape>(&probe, 1), std::span<const ToolPose>(&far, 1), 0).empty());
  EXPECT_EQ(guard.near(std::span<const ToolShape>(&probe, 1), std::span<const ToolPose>(&far, 1), 1e-3).size(), 1u);
  // beyond the budget: refused, no mass given (0.01 % of the mesh is 1 element's mass; it needs 25)
  s.budget = 0.0001;
  StepGuard poor(m, s);
  std::vector<double> poor_mass = mass0;
  l = poor.lift(m, poor_mass, std::span<const index_t>(&e, 1), std::span<const double>(&a, 1));
  EXPECT_EQ(l.elements, 0);
  EXPECT_EQ(l.refused, 1);
  EXPECT_EQ(poor_mass, mass0);
  s.budget = 0.025;
  // bad settings and an unwatched element are refused
  StepGuardSettings bad;
  bad.target = 0.6;
  EXPECT_THROW(StepGuard(m, bad), std::invalid_argument);
  bad = {};
  bad.interval = 0;
  EXPECT_THROW(StepGuard(m, bad), std::invalid_argument);
  bad = {};
  bad.budget = 1;
  EXPECT_THROW(StepGuard(m, bad), std::invalid_argument);
  const index_t other = 1;
  EXPECT_THROW(guard.lift(m, mass, std::span<const index_t>(&other, 1), std::span<const double>(&a, 1)),
               std::invalid_argument);
}

namespace {

/// The kidney focused to 1/2 under its probe (tissue converge's level:
/// 0.8 mm faces there, 6 steps a tick with 9,099 elements mass-scaled) pressed
/// at 2 mm/s to its 5 mm, as accuracy::slow_press presses it, with the step
/// guard on or off. Returns the last force (N), or throws SimulationError.
struct Press {
  double force = 0;
  index_t lifts = 0;
  double added = 0;
};
Press press_focused_kidney(const scene::Scene& s, std::shared_ptr<const TissueModel<double>> model, bool guard) {
  const auto& path = s.tools.front().path;
  scene::Scene p = s;
  p.solver.step_guard = guard;  // <solver step-guard>
  const SchedulerSettings settings = scene::scheduler_settings(p);
  EXPECT_EQ(settings.step_guard.on, guard);
  const accuracy::HeldTool held =
      accuracy::held_tool(*model, settings.tools.front(), path, s.solver.tick, accuracy::hold_start(path));
  const double T = norm(held.held.tip - held.start.tip) / accuracy::kCurveSpeed;
  p.tools.front().path = {{0.0, held.start.tip, false, held.start.axis}, {T, held.held.tip, false, held.held.axis}};
  Engine e = build_engine(p, std::nullopt, model);
  ScriptedDevice device(p.tools.front().path);
  Press out;
  for (TickReport rep; rep.time < T - 1e-9;) {
    rep = e.scheduler->tick(device);
    out.force = norm(rep.force);
  }
  out.lifts = e.scheduler->guard_lifts();
  out.added = e.scheduler->guard_added_mass();
  return out;
}

}  // namespace

// Without the guard an element under the probe, crushed to a third of its
// volume at 4.9 mm, rings until it inverts (docs/accuracy.md, "The step
// guard"); with it the press reaches its depth, and its force is that of
// the same press stepped 10 times finer without mass scaling (0.0770 N at
// the same depth, measured), within 2 %.
TEST(StepGuard, TheFocusedKidneyPressesToItsDepth) {
  const scene::Scene s =
      accuracy::remesh_scene(io::default_kidney_scene(), io::KidneyScene::target_tets, {2 * io::KidneyScene::frequency, 0.5});
  const auto model = std::make_shared<const TissueModel<double>>(scene::load_model(s));
  ASSERT_GT(model->scaled_elems, 5000);
  EXPECT_THROW(press_focused_kidney(s, model, false), SimulationError);
  const Press on = press_focused_kidney(s, model, true);
  EXPECT_GT(on.lifts, 0);
  EXPECT_LT(on.added, 0.01 * model->total_mass);
  EXPECT_NEAR(on.force, 0.0770, 0.02 * 0.0770);
}
