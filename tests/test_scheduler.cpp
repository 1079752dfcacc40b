// The Scheduler (core/scheduler.hpp) driving the cpu backend through a
// whole haptic interaction: a 40 x 40 x 20 mm box of brain-like tissue with
// its bottom face fixed, pressed 3 mm into its top face by a ScriptedDevice
// following press_path (approach 0.1 s, press 0.2 s, hold 0.5 s, retract),
// then left alone, by the default tool (a 2 mm sphere, smaller than the 10
// mm cells: face contact carries it). Checks: the force on the tool opposes
// the indentation and grows with depth; under the held indentation the
// free-node residual falls and the equilibrium flag is reached; contact
// ends after retraction and the tissue relaxes back toward u = 0; a limited
// region is seeded by the contact candidates; bad tool settings are named.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "core/box_mesh.hpp"
#include "core/device.hpp"
#include "core/scheduler.hpp"
#include "cpu/cpu_backend.hpp"

namespace tissue {
namespace {

constexpr double kLx = 0.04, kLz = 0.02;        // box (m)
constexpr double kRadius = 0.002;                          // the default tool
const Vec3<double> kTarget{0.013, 0.016, kLz + kRadius};  // the sphere touching the top inside a triangle
const Vec3<double> kDown{0, 0, -1};
constexpr double kDepth = 0.003, kApproach = 0.005;                                                   // m
constexpr double kPressStart = 0.1, kPressEnd = 0.3, kHoldEnd = 0.8, kRetractEnd = 0.82, kEnd = 1.2;  // s

TissueModel<double> pressed_box() {
  ModelInput in;
  box_mesh(in, 4, 4, 2, kLx, kLx, kLz);
  const double E = 3000, nu = 0.45;  // brain-like tissue (the default scene's material)
  in.materials = {{E / (2 * (1 + nu)), E / (3 * (1 - 2 * nu)), 1000}};
  in.fixed.assign(in.nodes.size() / 3, 0);
  for (size_t i = 0; i < in.fixed.size(); ++i) in.fixed[i] = in.nodes[3 * i + 2] == 0.0;
  in.source = "pressed box";
  return build_model(in);
}

/// Runs the press-hold-retract script (fast retraction, so the tissue is
/// still deformed when the tool lets go) and returns one report per tick.
std::vector<TickReport> run_press(Precision p, int depth, const TissueModel<double>& m) {
  auto backend = make_cpu_backend(p);
  backend->upload(m);
  SchedulerSettings settings;
  settings.depth = depth;
  Scheduler sched(*backend, m, settings);
  ScriptedDevice tool(press_path(kTarget, kDown, kDepth, kApproach, kPressStart, kPressEnd - kPressStart,
                                 kHoldEnd - kPressEnd, kRetractEnd - kHoldEnd));
  std::vector<TickReport> out;
  while (sched.time() < kEnd - 1e-9) out.push_back(sched.tick(tool));
  EXPECT_EQ(tool.forces_sent(), long(out.size()));
  EXPECT_EQ(tool.last_force().z, out.back().force.z);
  return out;
}

const TickReport& at(const std::vector<TickReport>& r, double t) {
  return r.at(size_t(std::lround(t / 1e-3)) - 1);
}

class PressedBox : public ::testing::TestWithParam<std::pair<Precision, int>> {
 protected:
  static void SetUpTestSuite() { model_ = new TissueModel<double>(pressed_box()); }
  static void TearDownTestSuite() { delete model_; }
  static TissueModel<double>* model_;
};
TissueModel<double>* PressedBox::model_ = nullptr;

INSTANTIATE_TEST_SUITE_P(Runs, PressedBox,
                         ::testing::Values(std::pair{Precision::Double, kDepthAll},
                                           std::pair{Precision::Float, kDepthAll}, std::pair{Precision::Double, 1}),
                         [](const auto& info) {
                           return std::string(to_string(info.param.first)) + "_depth_" +
                                  (info.param.second == kDepthAll ? std::string("all")
                                                                  : std::to_string(info.param.second));
                         });

TEST_P(PressedBox, ForceOpposesIndentationAndGrowsWithDepth) {
  const auto r = run_press(GetParam().first, GetParam().second, *model_);
  // no contact before the tool reaches the surface, contact from then on
  EXPECT_EQ(at(r, 0.09).contact_nodes, 0);
  EXPECT_EQ(at(r, 0.09).force.z, 0.0);
  for (double t = 0.11; t < kHoldEnd; t += 0.01) ASSERT_GT(at(r, t).contact_nodes, 0) << "t = " << t;
  // the force on the tool points out of the tissue (+z) and grows with depth
  double prev = 0;
  for (double t : {0.125, 0.15, 0.2, 0.25, 0.3}) {
    const Vec3<double> f = at(r, t).force;
    EXPECT_GT(f.z, prev) << "t = " << t;
    // mostly along the press (the 10 mm triangles under the 2 mm tool are
    // not symmetric about it, so some lateral force is expected)
    EXPECT_LT(std::hypot(f.x, f.y), 0.35 * f.z) << "t = " << t;
    prev = f.z;
  }
  // magnitude sanity: of the order of E * contact scale * strain (mN, not N or uN)
  EXPECT_GT(prev, 1e-4);
  EXPECT_LT(prev, 1.0);
}

TEST_P(PressedBox, HeldIndentationConverges) {
  const auto r = run_press(GetParam().first, GetParam().second, *model_);
  // the residual at the start of the hold: its largest over the first 10
  // ticks (one tick's value can dip as the tissue rings)
  double start_residual = 0;
  for (double t = kPressEnd + 1e-3; t <= kPressEnd + 0.0105; t += 1e-3)
    start_residual = std::max(start_residual, at(r, t).residual);
  const TickReport& start = at(r, kPressEnd + 0.002);
  const TickReport& end = at(r, kHoldEnd);
  EXPECT_LT(end.residual, 1e-2 * start_residual);  // the free-node residual falls
  EXPECT_LT(end.kinetic, 1e-3 * start.kinetic);
  EXPECT_TRUE(end.equilibrium);
  double first_eq = -1;
  for (double t = kPressEnd; t <= kHoldEnd; t += 1e-3)
    if (at(r, t).equilibrium) {
      first_eq = t;
      break;
    }
  EXPECT_GT(first_eq, kPressEnd);
  EXPECT_LT(first_eq, kHoldEnd - 0.1);  // reached well inside the hold
  // the force settles: the last 0.1 s of the hold changes it by < 0.1%
  EXPECT_NEAR(at(r, kHoldEnd - 0.1).force.z, end.force.z, 1e-3 * end.force.z);
  // Over the whole mesh the internal forces sum to ~0 (each element's nodal
  // forces do); a limited region's sum is instead minus the halo's support,
  // so there it is no equilibrium measure (the residual above is).
  if (GetParam().second == kDepthAll) {
    EXPECT_LT(norm(end.internal), 1e-6 * norm(end.force));
  }
}

TEST_P(PressedBox, ContactEndsAndTissueRelaxes) {
  const auto r = run_press(GetParam().first, GetParam().second, *model_);
  const double peak = at(r, kHoldEnd).max_disp;
  EXPECT_NEAR(peak, kDepth, 0.5 * kDepth);  // the surface under the tool went down about 3 mm
  double released = -1;
  for (double t = kHoldEnd; t <= kEnd; t += 1e-3)
    if (at(r, t).contact_nodes == 0) {
      released = t;
      break;
    }
  EXPECT_GT(released, kHoldEnd);
  EXPECT_LE(released, kRetractEnd + 1e-9);
  for (double t = released; t <= kEnd; t += 0.05) EXPECT_EQ(at(r, t).force.z, 0.0);
  // relaxes back toward u = 0 with the kinetic energy dying out
  const TickReport& last = r.back();
  EXPECT_LT(last.max_disp, 1e-2 * peak);
  EXPECT_LT(at(r, released + 0.1).max_disp, at(r, released + 0.01).max_disp);
  EXPECT_LT(last.kinetic, 1e-6 * at(r, kHoldEnd).kinetic + 1e-15);
  EXPECT_EQ(last.contact_nodes, 0);
}

TEST(SchedulerRegion, LimitedRegionIsSmallerAndSeededByTheContactCandidates) {
  const auto m = pressed_box();
  auto backend = make_cpu_backend(Precision::Double);
  backend->upload(m);
  SchedulerSettings settings;
  settings.depth = 1;
  Scheduler sched(*backend, m, settings);
  ScriptedDevice tool(press_path(kTarget, kDown, kDepth, kApproach));
  TickReport rep;
  while (!sched.in_contact()) rep = sched.tick(tool);
  ASSERT_GT(rep.contact_nodes, 0);
  // every node in contact is a seed, and the region is the seeds' 1-ring
  for (const ContactNode& c : backend->contacts())
    EXPECT_TRUE(std::binary_search(sched.seeds().begin(), sched.seeds().end(), c.node)) << "node " << c.node;
  const Region want = flood_fill(m, std::span<const index_t>(sched.seeds()), 1);
  EXPECT_EQ(rep.region_nodes, index_t(want.nodes.size()));
  EXPECT_EQ(rep.region_elems, index_t(want.elems.size()));
  EXPECT_LT(rep.region_elems, m.n_elems);
  EXPECT_EQ(backend->region().nodes, want.nodes);
  for (index_t a : sched.seeds()) EXPECT_TRUE(m.node_flags[a] & kSurface);
}

TEST(SchedulerRegion, LoadedNodesSeedTheRegionAndMove) {
  const auto m = pressed_box();
  auto backend = make_cpu_backend(Precision::Double);
  backend->upload(m);
  SchedulerSettings settings;
  settings.depth = 1;
  Scheduler sched(*backend, m, settings);
  // a top node far from the tool's path, pulled up by 1 mN
  const index_t a = box_node(4, 4, 1, 3, 2);
  ASSERT_TRUE(m.node_flags[a] & kSurface);
  const std::vector<index_t> nodes = {a};
  const std::vector<double> force = {0.0, 0.0, 1e-3};
  sched.set_loads(nodes, force);
  EXPECT_EQ(sched.seeds(), nodes);
  EXPECT_EQ(backend->loaded_nodes(), nodes);
  const Region want = flood_fill(m, std::span<const index_t>(nodes), 1);
  EXPECT_EQ(backend->region().nodes, want.nodes);
  // the tool waits above the box until kPressStart: only the load acts
  ScriptedDevice tool(press_path(kTarget, kDown, kDepth, kApproach, kPressStart, kPressEnd - kPressStart,
                                 kHoldEnd - kPressEnd, kRetractEnd - kHoldEnd));
  TickReport rep;
  for (int k = 0; k < 50; ++k) rep = sched.tick(tool);
  EXPECT_FALSE(sched.in_contact());
  const Fields f = backend->download();
  const index_t n = m.n_nodes;
  EXPECT_GT(f.u[2 * n + a], 1e-6);  // lifted (m)
  for (index_t b = 0; b < n; ++b) {  // nothing outside the region moved
    if (!std::binary_search(want.nodes.begin(), want.nodes.end(), b)) {
      EXPECT_EQ(f.u[2 * n + b], 0.0) << "node " << b;
    }
  }
  // clearing the loads keeps the region, and the node springs back
  sched.set_loads({}, {});
  EXPECT_TRUE(backend->loaded_nodes().empty());
  for (int k = 0; k < 50; ++k) sched.tick(tool);
  EXPECT_LT(std::abs(backend->download().u[2 * n + a]), 0.05 * f.u[2 * n + a]);
}

/// The message of the std::invalid_argument f throws ("" when none).
template <class F>
std::string refusal(F&& f) {
  try {
    f();
  } catch (const std::invalid_argument& e) {
    return e.what();
  }
  return "";
}

TEST(SchedulerTools, BadToolSettingsAreRefusedByName) {
  const auto m = pressed_box();
  auto backend = make_cpu_backend(Precision::Double);
  backend->upload(m);
  auto with = [&](ToolSetting t) {
    SchedulerSettings s;
    s.tools = {t};
    return refusal([&] { Scheduler sched(*backend, m, s); });
  };
  EXPECT_NE(with({{"probe", 0.0, 0}, {0, 0, 1}}).find("tool 'probe': radius = 0 m must be finite and > 0"), std::string::npos);
  EXPECT_NE(with({{"probe", -1e-3, 0}, {0, 0, 1}}).find("must be finite and > 0"), std::string::npos);
  EXPECT_NE(with({{"big", 0.05, 0}, {0, 0, 1}}).find("tool 'big': radius = 0.05 m is larger than the body (its largest "
                                                      "extent is 0.04 m)"),
            std::string::npos);
  EXPECT_NE(with({{"probe", 1e-3, -0.01}, {0, 0, 1}}).find("shaft-length = -0.01 m must be finite and >= 0"), std::string::npos);
  EXPECT_NE(with({{"probe", 1e-3, 0}, {0, 0, 0}}).find("direction (0, 0, 0) must be a non-zero vector"),
            std::string::npos);
  SchedulerSettings five;
  five.tools.assign(5, ToolSetting{});
  EXPECT_NE(refusal([&] { Scheduler sched(*backend, m, five); }).find("5 tools: a scene holds at most 4"),
            std::string::npos);
  // one device per tool
  SchedulerSettings two;
  two.tools = {ToolSetting{}, ToolSetting{}};
  Scheduler sched(*backend, m, two);
  ScriptedDevice d(press_path(kTarget, kDown, kDepth, kApproach));
  EXPECT_NE(refusal([&] { sched.tick(d); }).find("1 devices for 2 tools"), std::string::npos);
}

TEST(SchedulerTools, AToolStartingInsideTheBodyAwayFromItsSurfaceIsNoted) {
  const auto m = pressed_box();
  auto backend = make_cpu_backend(Precision::Double);
  backend->upload(m);
  SchedulerSettings settings;
  settings.depth = kDepthAll;
  Scheduler sched(*backend, m, settings);
  ScriptedDevice tool(std::vector<Waypoint>{{0.0, {0.02, 0.02, 0.01}}});  // the middle of the box
  const TickReport rep = sched.tick(tool);
  EXPECT_EQ(rep.contact_nodes, 0);
  const std::vector<std::string> notes = sched.take_notes();
  ASSERT_EQ(notes.size(), 1u);
  EXPECT_NE(notes[0].find("tool 'probe' starts inside the body"), std::string::npos) << notes[0];
  EXPECT_TRUE(inside_reference_surface(m, {0.02, 0.02, 0.01}));
  EXPECT_FALSE(inside_reference_surface(m, {0.02, 0.02, 0.03}));
  EXPECT_FALSE(inside_reference_surface(m, {-0.01, 0.02, 0.01}));
}

}  // namespace
}  // namespace tissue
