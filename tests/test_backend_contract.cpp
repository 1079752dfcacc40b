// The Backend contract (core/backend.hpp), one suite over every backend and
// precision (cpu and cuda, float and double; a backend not built or with no
// device here skips, naming why): the IANP passes against a serial
// reference, zero force at rest and under rigid motion, the region, the
// inverted-element flag, the reductions, identical errors for bad input (the
// checks live once, in Backend), and the tool contact of core/contact.hpp:
// no penetration, a reaction that never pulls, Coulomb friction (stick,
// slide), the equilibrium
// balance of tool and supports, grasping, several tools, small tools caught
// by faces, fast tools sub-stepped, rigid supports reported, the region
// seeded by contact candidates, a tool that starts in contact (brought in)
// and a deep press from a start inside a nearly incompressible block.
// The cuda backend's own stage-by-stage comparison with the cpu is
// tests/cuda/test_cuda_stages.cpp.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include "backends/registry.hpp"
#include "core/scheduler.hpp"
#include "tests/backend_test_support.hpp"

namespace tissue {
namespace {

using namespace tissue::test;

class Contract : public ::testing::TestWithParam<test::BackendKind> {
 protected:
  void SetUp() override { SKIP_UNLESS_USABLE(GetParam().backend); }
  bool is_float() const { return GetParam().precision == Precision::Float; }
  std::unique_ptr<Backend> make() const { return create_backend(GetParam().backend, GetParam().precision); }
  std::unique_ptr<Backend> make(const TissueModel<double>& m) const {
    auto b = make();
    b->upload(m);
    return b;
  }
  /// Relative rounding scale of the backend's scalar.
  double eps() const { return is_float() ? 1.2e-7 : 2.2e-16; }
  /// Two runs from one motion (set_motion clears float's carried low bits):
  /// bit for bit in double, within 1e-6 of max |u| in float.
  void expect_same_run(const std::vector<double>& ua, const std::vector<double>& ub) const {
    if (is_float()) {
      double most = 0;
      for (std::size_t k = 0; k < ua.size(); ++k) most = std::max(most, std::fabs(ua[k] - ub[k]));
      EXPECT_LT(most, 1e-6 * max_abs(ua));
    } else {
      EXPECT_EQ(ub, ua);
    }
  }
};

INSTANTIATE_TEST_SUITE_P(Backends, Contract,
                         ::testing::ValuesIn(test::all_backend_kinds()), test::backend_kind_name);

TEST_P(Contract, IdentifiesItself) {
  auto b = make();
  EXPECT_EQ(b->name(), GetParam().backend);
  EXPECT_EQ(b->precision(), GetParam().precision);
  EXPECT_FALSE(b->device_name().empty());
  EXPECT_EQ(b->positions_on_device(), GetParam().backend == "cuda");
}

TEST_P(Contract, ZeroForceAtRest) {
  const auto m = box_model(3, true);
  auto b = make(m);
  b->advance(3);
  const Fields f = b->download();
  EXPECT_EQ(max_abs(f.u), 0.0);
  EXPECT_EQ(max_abs(f.f), 0.0);
  EXPECT_EQ(max_abs(f.node_p), 0.0);
  for (double J : f.elem_J) EXPECT_EQ(J, 1.0);
  const Reductions r = b->reduce();
  EXPECT_EQ(r.free_force2 + r.held_force2 + r.kinetic + r.max_disp, 0.0);
  EXPECT_EQ(r.bad_elem, -1);
  EXPECT_TRUE(r.finite);
  for (const ToolReduction& t : r.tools) EXPECT_EQ(t.contact, 0);
}

/// Max |f| after one step from a 5% uniaxial stretch: the force scale the
/// rigid-motion tolerances are relative to.
double stretch_force(Backend& b, const TissueModel<double>& m) {
  b.set_displacements(field(m, [](Vec3<double> X) { return Vec3<double>{0.05 * X.x, 0, 0}; }));
  b.advance(1);
  return max_abs(b.download().f);
}

TEST_P(Contract, RigidMotionGivesNoInternalForce) {
  const auto m = box_model(4);
  auto b = make(m);
  const double scale = stretch_force(*b, m);
  ASSERT_GT(scale, 1e-6);
  // tolerance: rounding of F = I + sum u_a dN_a^T, relative to the stretch case
  const double tol = (is_float() ? 1e-4 : 1e-11) * scale;
  const auto shift = field(m, [](Vec3<double>) { return Vec3<double>{0.003, -0.002, 0.001}; });
  b->set_displacements(shift);
  b->advance(1);
  EXPECT_LT(max_abs(b->download().f), tol);
  // 30 degrees about the axis (1, 2, 3) / |.| through the box centre (Rodrigues)
  const Vec3<double> k = (1.0 / std::sqrt(14.0)) * Vec3<double>{1, 2, 3}, c{kL / 2, kL / 2, kL / 2};
  const double th = M_PI / 6;
  b->set_displacements(field(m, [&](Vec3<double> X) {
    const Vec3<double> r = X - c;
    return std::cos(th) * r + std::sin(th) * cross(k, r) + ((1 - std::cos(th)) * dot(k, r)) * k - r;
  }));
  b->advance(1);
  EXPECT_LT(max_abs(b->download().f), tol);
}

TEST_P(Contract, PassesMatchASerialReference) {
  for (bool ianp : {true, false}) {
    const auto m = box_model(3, true, ianp);
    auto b = make(m);
    std::vector<double> u = field(m, [](Vec3<double> X) {
      return Vec3<double>{0.04 * X.x * X.z / kL, -0.03 * X.y, 0.02 * X.x - 0.05 * X.z * X.z / kL};
    });
    for (index_t a = 0; a < m.n_nodes; ++a)
      if (m.node_flags[a] & kFixed)
        for (int c = 0; c < 3; ++c) u[c * m.n_nodes + a] = 0;
    b->set_displacements(u);
    std::vector<double> u_prev = u, u_held(u.size(), 0.0), f;
    std::vector<std::uint8_t> held(m.n_nodes);
    for (index_t a = 0; a < m.n_nodes; ++a) held[a] = (m.node_flags[a] & kFixed) ? 1 : 0;
    for (int s = 0; s < 5; ++s) f = reference_step(m, u, u_prev, held, u_held);
    b->advance(5);
    const Fields got = b->download();
    // float: a few ulp per step of the stress's cancellations (measured 2e-6 on the cpu)
    EXPECT_LT(max_diff(got.f, f), (is_float() ? 1e-4 : 1e-12) * max_abs(f)) << "ianp " << ianp;
    EXPECT_LT(max_diff(got.u, u), (is_float() ? 1e-5 : 1e-14) * max_abs(u)) << "ianp " << ianp;
  }
}

/// Pass 4 gathers the forces of the pass 3 called before it; a step's own
/// passes 3 need not leave theirs (the cuda backend's fused passes keep them
/// on chip), so a pass 4 without its pass 3 is refused on every backend,
/// with the same message, instead of reading forces of some earlier pass.
TEST_P(Contract, APass4WithoutItsPass3IsRefused) {
  const auto m = box_model(3, true);
  auto b = make(m);
  b->set_displacements(field(m, [](Vec3<double> X) { return Vec3<double>{0.02 * X.x, 0, -0.01 * X.z}; }));
  const auto refused = [&](const char* after) {
    SCOPED_TRACE(after);
    try {
      b->node_update();
      ADD_FAILURE() << "node_update() without element_forces() was not refused";
    } catch (const std::logic_error& e) {
      EXPECT_NE(std::string(e.what()).find("node_update() (pass 4) needs the element forces of a pass 3"),
                std::string::npos)
          << e.what();
    }
  };
  refused("upload");
  const std::vector<double> u0 = b->download().u;
  EXPECT_EQ(b->download().u, u0);  // the refused call moved nothing
  b->element_pressure();
  b->nodal_pressure();
  b->element_forces();
  EXPECT_NO_THROW(b->node_update());
  EXPECT_NE(b->download().u, u0);
  refused("a pass 4");
  b->element_forces();
  b->advance(0);  // no step taken: the pass 3's forces still stand
  EXPECT_NO_THROW(b->node_update());
  b->element_forces();
  b->advance(2);
  refused("a step");
  b->element_forces();
  b->advance_reduce(1);
  refused("a step and its reductions");
}

TEST_P(Contract, RegionRunMovesOnlyRegionNodes) {
  const auto m = box_model(6, true);
  auto b = make(m);
  const auto seeds = top_triangle(m);
  const RegionSizes sz = b->build_region(seeds, 1);
  const Region want = flood_fill(m, std::span<const index_t>(seeds), 1);
  EXPECT_EQ(sz.n_inner, want.n_inner);
  EXPECT_EQ(sz.n_halo, want.n_halo);
  EXPECT_EQ(sz.n_elems, index_t(want.elems.size()));
  const Region got = b->region();
  EXPECT_EQ(got.nodes, want.nodes);
  EXPECT_EQ(got.elems, want.elems);
  EXPECT_EQ(got.role, want.role);
  const double push[] = {0, 0, -0.001, 0, 0, -0.001, 0, 0, -0.001};
  b->set_driven(seeds, push);
  b->advance(30);
  const Fields f = b->download();
  const index_t n = m.n_nodes;
  int moved = 0;
  for (index_t a = 0; a < n; ++a) {
    const Vec3<double> u = node_u(f.u, n, a);
    if (std::count(seeds.begin(), seeds.end(), a)) {
      EXPECT_NEAR(u.z, -0.001, is_float() ? 1e-10 : 1e-15) << "driven node " << a;
    } else if (want.role[a] == kInner) {
      moved += norm(u) > 1e-6;
    } else {  // outside and halo nodes stay exactly where they were (at 0)
      EXPECT_EQ(norm(u), 0.0) << "node " << a << " role " << int(want.role[a]);
    }
  }
  EXPECT_GT(moved, 0);
  // the reductions agree with the downloaded fields
  const Reductions r = b->reduce();
  double fz = 0, max_u = 0;
  Vec3<double> internal{0, 0, 0};
  for (index_t a : seeds) fz += f.f[2 * n + a];
  for (index_t a : want.nodes) {
    max_u = std::max(max_u, norm(node_u(f.u, n, a)));
    if (want.role[a] == kInner) internal = internal + node_u(f.f, n, a);
  }
  EXPECT_LT(r.reaction.z, 0);
  EXPECT_NEAR(r.reaction.z, fz, 1e-12 * std::fabs(fz) + 1e-15);
  EXPECT_NEAR(r.internal.z, internal.z, 1e-9 * std::fabs(fz));
  EXPECT_DOUBLE_EQ(r.max_disp, max_u);
}

TEST_P(Contract, InvertedElementIsReportedOnceThenClearedAndStopsTheScheduler) {
  for (bool ianp : {true, false}) {
    const auto m = box_model(2, false, ianp);
    auto b = make(m);
    const auto u = flip(m, 29, 3, 1.3);
    const auto [e, J] = lowest_inverted(m, u);
    ASSERT_GE(e, 0);
    b->set_displacements(u);
    b->advance(1);
    const Reductions r = b->reduce();
    EXPECT_EQ(r.bad_elem, e) << "ianp " << ianp;
    EXPECT_NEAR(r.bad_J, J, 1e-6 * std::fabs(J) + 1e-6);  // recorded as float
    EXPECT_EQ(b->reduce().bad_elem, -1);                  // reduce() cleared the flag
    if (!ianp) continue;
    b->set_displacements(u);
    SchedulerSettings settings;
    settings.depth = kDepthAll;
    settings.tools.front().shape.radius = 0.004;
    Scheduler sched(*b, m, settings);
    ScriptedDevice far(std::vector<Waypoint>{{0.0, {1.0, 1.0, 1.0}}});  // never touches the box
    try {
      sched.tick(far);
      ADD_FAILURE() << "an inverted element did not stop the run";
    } catch (const SimulationError& err) {
      EXPECT_NE(std::string(err.what()).find(fmt::format("element {} ", e)), std::string::npos) << err.what();
    }
  }
}

/// The message of the std::exception f throws, or "<no exception>".
template <class F>
std::string message(F&& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "<no exception>";
}

/// Every bad call's message, in order: the checks live in Backend, so every
/// backend must give the same words.
std::vector<std::string> bad_input_messages(Backend& b, const TissueModel<double>& m) {
  const index_t n = m.n_nodes;
  std::vector<std::string> out;
  out.push_back(message([&] { b.set_displacements(std::vector<double>(3 * n - 1, 0.0)); }));
  std::vector<double> u(3 * size_t(n), 0.0);
  u[n + 5] = std::nan("");
  out.push_back(message([&] { b.set_displacements(u); }));
  const index_t nodes[] = {3, n};
  const double t6[6] = {};
  out.push_back(message([&] { b.set_driven(nodes, std::span<const double>(t6, 5)); }));
  out.push_back(message([&] { b.set_driven(nodes, t6); }));
  const index_t one[] = {3};
  const double nan3[3] = {0, std::nan(""), 0};
  out.push_back(message([&] { b.set_driven(one, nan3); }));
  const std::uint8_t mask8[] = {8};
  out.push_back(message([&] { b.set_driven_axes(one, std::span<const double>(t6, 3), mask8); }));
  out.push_back(message([&] { b.build_region(one, -3); }));
  const index_t bad_seed[] = {n};
  out.push_back(message([&] { b.build_region(bad_seed, 1); }));
  const index_t seed[] = {n - 1};
  b.build_region(seed, 0);
  const index_t far[] = {0};
  out.push_back(message([&] { b.set_driven(far, std::span<const double>(t6, 3)); }));
  out.push_back(message([&] { b.advance(-1); }));
  out.push_back(message([&] { b.write_positions(nullptr); }));
  const ToolShape bad_tools[] = {{"probe", 0.0, 0}};
  out.push_back(message([&] { b.set_tools(bad_tools); }));
  const ToolShape neg_shaft[] = {{"probe", 0.001, -1}};
  out.push_back(message([&] { b.set_tools(neg_shaft); }));
  const std::vector<ToolShape> five(5);
  out.push_back(message([&] { b.set_tools(five); }));
  const ToolShape one_tool[] = {{"probe", 0.001, 0}};
  b.set_tools(one_tool);
  out.push_back(message([&] { b.move_tools({}); }));
  const ToolMotion nan_tip[] = {{{{std::nan(""), 0, 0}, {0, 0, 1}}, {}}};
  out.push_back(message([&] { b.move_tools(nan_tip); }));
  const ToolMotion zero_axis[] = {{{{0, 0, 0}, {0, 0, 0}}, {}}};
  out.push_back(message([&] { b.move_tools(zero_axis); }));
  return out;
}

TEST_P(Contract, BadInputGivesTheSameClearErrorOnEveryBackend) {
  auto fresh = make();
  EXPECT_NE(message([&] { fresh->advance(1); }).find("before upload()"), std::string::npos);
  EXPECT_NE(message([&] { fresh->reduce(); }).find("before upload()"), std::string::npos);
  const auto m = box_model(2);
  auto b = make(m);
  const std::vector<std::string> got = bad_input_messages(*b, m);
  auto reference = create_backend("cpu", Precision::Double);
  reference->upload(m);
  const std::vector<std::string> want = bad_input_messages(*reference, m);
  ASSERT_EQ(got.size(), want.size());
  // the one backend-specific word: write_positions writes host memory on the cpu, device memory on cuda
  auto same_rule = [&](std::string msg) {
    if (const auto at = msg.find("of device memory"); at != std::string::npos && GetParam().backend == "cuda")
      msg.replace(at, 16, "of host memory");
    return msg;
  };
  for (std::size_t k = 0; k < got.size(); ++k) {
    EXPECT_EQ(same_rule(got[k]), want[k]) << "call " << k;
    EXPECT_NE(got[k], "<no exception>") << "call " << k;
  }
  const index_t n = m.n_nodes;
  // and the words name the value and the rule
  for (const auto& [k, part] : std::vector<std::pair<int, std::string>>{
           {0, fmt::format("need 3 x n_nodes = {}", 3 * n)},
           {1, "node 5: displacement y = nan is not finite"},
           {2, "5 displacement values for 2 nodes"},
           {3, fmt::format("node {} out of range", n)},
           {5, "axis mask 8 must be 1..7"},
           {6, "depth -3 must be >= 0"},
           {8, "node 0 is outside the deformation region"},
           {9, "step count -1 must be >= 0"},
           {11, "radius = 0 m must be finite and > 0"},
           {12, "shaft-length = -1 m must be finite and >= 0"},
           {13, "at most 4"},
           {14, "0 motions for 1 tools"},
           {15, "tip (nan, 0, 0) is not finite"},
           {16, "must be a non-zero finite direction"}})
    EXPECT_NE(got[k].find(part), std::string::npos) << got[k];
}

// ---- tool contact --------------------------------------------------------------

/// A 40 x 40 x 20 mm box of n x n x n/2 cells (6 tets each) on a fixed base,
/// brain-like tissue.
/// dt: the step (s); 0 = 0.9 dt_crit.
TissueModel<double> slab(int n, bool fix_all = false, double dt = 0) {
  ModelInput in;
  in.dt = dt;
  box_mesh(in, n, n, n / 2, 0.04, 0.04, 0.02);
  const double E = 3000, nu = 0.45;
  in.materials = {{E / (2 * (1 + nu)), E / (3 * (1 - 2 * nu)), 1000}};
  in.fixed.assign(in.nodes.size() / 3, 0);
  for (size_t i = 0; i < in.fixed.size(); ++i) in.fixed[i] = fix_all || in.nodes[3 * i + 2] == 0.0;
  in.source = "contact slab";
  in.dt_safety = 0.9;
  return build_model(in);
}

constexpr double kTop = 0.02;

/// A scheduler over the backend with these tools (depth all).
SchedulerSettings tools_settings(std::vector<ToolSetting> tools) {
  SchedulerSettings st;
  st.depth = kDepthAll;
  st.tools = std::move(tools);
  return st;
}

ToolSetting sphere(double r, double shaft = 0, std::string name = "probe") { return {{name, r, shaft}, {0, 0, 1}}; }

/// Approach from 3 mm above, press `depth` (the sphere's lowest point below
/// the top) over 0.1 s at (x, y), hold `hold` s.
std::vector<Waypoint> press_at(double x, double y, double r, double depth, double hold = 0.4) {
  return press_path({x, y, kTop + r}, {0, 0, -1}, depth, 0.003, 0.05, 0.1, hold, 0.05);
}

/// Largest penetration of a pushed node into a sphere at `c` (m; <= 0 when
/// none lies inside).
double penetration(const TissueModel<double>& m, const Fields& f, const std::vector<ContactNode>& contacts,
                   Vec3<double> c, double r) {
  const index_t n = m.n_nodes;
  double worst = -INFINITY;
  for (const ContactNode& k : contacts) {
    const Vec3<double> x = Vec3<double>{m.X[k.node], m.X[n + k.node], m.X[2 * n + k.node]} + node_u(f.u, n, k.node);
    worst = std::max(worst, r - norm(x - c));
  }
  return worst;
}

TEST_P(Contract, PressedSphereHoldsTheSurfaceOutsideAndFeelsItPushBack) {
  const auto m = slab(8);  // 5 mm cells
  auto b = make(m);
  const double r = 0.004;
  Scheduler sched(*b, m, tools_settings({sphere(r)}));
  ScriptedDevice dev(press_at(0.0203, 0.0196, r, 0.002));
  TickReport rep;
  while (sched.time() < 0.3) rep = sched.tick(dev);
  ASSERT_GT(rep.contact_nodes, 0);
  const std::vector<ContactNode> c = b->contacts();
  ASSERT_FALSE(c.empty());
  for (const ContactNode& k : c) {
    EXPECT_EQ(k.tool, 0);
    EXPECT_EQ(k.kind, kPushed);
    EXPECT_NEAR(norm(k.normal), 1.0, 1e-5);
    EXPECT_LT(k.normal.z, 0.0) << "the contact normal points out of the tool, into the tissue below";
  }
  // no node inside the tool (float: rounding of positions near 2 cm)
  EXPECT_LT(penetration(m, b->download(), c, rep.tool, r), is_float() ? 1e-7 : 1e-12);
  // the tissue pushes the tool up, mostly along the press
  EXPECT_GT(rep.force.z, 0.0);
  EXPECT_LT(std::hypot(rep.force.x, rep.force.y), 0.2 * rep.force.z);
}

TEST_P(Contract, AtEquilibriumTheToolForceBalancesTheSupports) {
  const auto m = slab(8);
  auto b = make(m);
  const double r = 0.004;
  Scheduler sched(*b, m, tools_settings({sphere(r)}));
  ScriptedDevice dev(press_at(0.0203, 0.0196, r, 0.002, 3.0));
  TickReport rep;
  bool eq = false;
  while (sched.time() < 3.0 && !eq) {
    rep = sched.tick(dev);
    eq = rep.equilibrium && rep.time > 0.2;
  }
  ASSERT_TRUE(eq) << "no equilibrium under the held tool";
  const Fields f = b->download();
  const index_t n = m.n_nodes;
  Vec3<double> support{0, 0, 0};  // the internal forces on fixed nodes are the supports' reactions
  for (index_t a = 0; a < n; ++a)
    if (m.node_flags[a] & kFixed) support = support + node_u(f.f, n, a);
  // Newton: the tool's force and the supports' sum to zero on the body, so
  // F_tool = -sum(contact) f = sum(fixed) f, to the equilibrium tolerance (1e-3)
  EXPECT_GT(rep.force.z, 0);
  EXPECT_LT(norm(rep.force - support), 2e-3 * norm(rep.force)) << "tool (" << rep.force.x << ", " << rep.force.y
                                                                << ", " << rep.force.z << ") support (" << support.x
                                                                << ", " << support.y << ", " << support.z << ")";
}

TEST_P(Contract, ContactNeverPullsAndEndsWhenTheToolWithdraws) {
  const auto m = slab(8);
  auto b = make(m);
  const double r = 0.004;
  Scheduler sched(*b, m, tools_settings({sphere(r)}));
  ScriptedDevice dev(press_at(0.0203, 0.0196, r, 0.002, 0.1));  // retracts to 3 mm above at t = 0.3 s
  double min_fz = INFINITY;
  TickReport rep;
  std::vector<std::string> notes;
  while (sched.time() < 0.5) {
    rep = sched.tick(dev);
    if (rep.contact_nodes > 0) min_fz = std::min(min_fz, rep.force.z);
    for (std::string& s : sched.take_notes()) notes.push_back(std::move(s));
  }
  EXPECT_TRUE(notes.empty()) << "a slow press and withdrawal is neither fast nor through the surface: " << notes[0];
  EXPECT_GE(min_fz, 0.0) << "a frictionless contact never pulls the tool into the tissue";
  EXPECT_EQ(rep.contact_nodes, 0);
  EXPECT_EQ(norm(rep.force), 0.0);
  EXPECT_TRUE(b->contacts().empty());
}

/// What a sphere of 8 mm pressed 0.8 mm into the slab (a shallow press: the
/// contact's slopes stay below 0.32) and dragged 4 mm along +x at 10 mm/s
/// (from t = 0.3 to 0.7 s) feels, with friction coefficient mu.
struct Drag {
  double ratio_early = 0;    ///< -F_x / F_z on the tool after 0.1 mm of drag
  double node_dx_early = 0;  ///< x displacement of the contact node nearest the tool's axis then (m)
  double ratio_end = 0;      ///< -F_x / F_z at the end of the drag (4 mm)
  double node_dx = 0;        ///< that node's x displacement at the end (m)
  double support_gap = 0;    ///< |F_tool - sum of the supports' reactions| / |F_tool| at the end
};

Drag drag_sphere(Backend& b, const TissueModel<double>& m, double mu) {
  const double r = 0.008;
  ToolSetting tool = sphere(r);
  tool.shape.friction = mu;
  Scheduler sched(b, m, tools_settings({tool}));
  const Vec3<double> touch{0.014, 0.02, kTop + r};
  const Vec3<double> down{0, 0, -0.0008}, along{0.004, 0, 0};
  ScriptedDevice dev({{0.0, touch + Vec3<double>{0, 0, 0.002}},
                      {0.1, touch + down},
                      {0.3, touch + down},
                      {0.7, touch + down + along},
                      {1.0, touch + down + along}});
  const index_t n = m.n_nodes;
  // the x displacement of the contact node nearest the tool's axis
  const auto nearest_dx = [&](const Fields& f, Vec3<double> tool_tip) {
    double nearest = INFINITY, dx = 0;
    for (const ContactNode& c : b.contacts()) {
      const Vec3<double> x = Vec3<double>{m.X[c.node], m.X[n + c.node], m.X[2 * n + c.node]} + node_u(f.u, n, c.node);
      const double off = std::hypot(x.x - tool_tip.x, x.y - tool_tip.y);
      if (off < nearest) nearest = off, dx = f.u[c.node];
    }
    return dx;
  };
  Drag d;
  TickReport rep;
  while (sched.time() < 0.31 - 1e-9) rep = sched.tick(dev);
  d.ratio_early = -rep.force.x / rep.force.z;
  d.node_dx_early = nearest_dx(b.download(), rep.tool);
  while (sched.time() < 0.7 - 1e-9) rep = sched.tick(dev);
  d.ratio_end = -rep.force.x / rep.force.z;
  const Fields f = b.download();
  d.node_dx = nearest_dx(f, rep.tool);
  Vec3<double> support{0, 0, 0};
  for (index_t a = 0; a < n; ++a)
    if (m.node_flags[a] & kFixed) support = support + node_u(f.f, n, a);
  d.support_gap = norm(rep.force - support) / norm(rep.force);
  return d;
}

// Coulomb friction (core/node_rules.hpp coulomb_slip, core/contact.hpp
// contact_reaction): a sphere dragged along the surface first carries the
// tissue with it, below mu times the normal force, then slides, adding mu
// times the normal force to what the frictionless drag feels (the tissue
// heaped before a moving tool: a few per cent of it, on this coarse mesh);
// a rougher one stays stuck; the supports feel what the tool feels.
TEST_P(Contract, ADraggedSphereSlidesAtMuTimesTheNormalForceAndSticksBelowIt) {
  const auto m = slab(12);  // 3.3 mm cells
  const Drag smooth = drag_sphere(*make(m), m, 0.0), sliding = drag_sphere(*make(m), m, 0.3),
             sticking = drag_sphere(*make(m), m, 5.0);
  std::printf("[measured] drag -F_x/F_z at 0.1 mm and 4 mm: mu 0 %.4f %.4f, mu 0.3 %.4f %.4f, mu 5 %.4f %.4f; nearest "
              "contact node's dx (mm) %.4f %.4f, %.4f %.4f, %.4f %.4f; support gaps %.3g %.3g %.3g\n",
              smooth.ratio_early, smooth.ratio_end, sliding.ratio_early, sliding.ratio_end, sticking.ratio_early,
              sticking.ratio_end, 1e3 * smooth.node_dx_early, 1e3 * smooth.node_dx, 1e3 * sliding.node_dx_early,
              1e3 * sliding.node_dx, 1e3 * sticking.node_dx_early, 1e3 * sticking.node_dx, smooth.support_gap,
              sliding.support_gap, sticking.support_gap);
  EXPECT_LT(std::fabs(smooth.ratio_end), 0.03) << "frictionless: only the heap before the moving tool";
  EXPECT_NEAR(sliding.ratio_end - smooth.ratio_end, 0.3, 0.015) << "sliding: mu N more than frictionless";
  EXPECT_LT(sliding.ratio_early, 0.3) << "sticking: below the cone";
  EXPECT_GT(sliding.node_dx_early, 0.7e-4) << "the node under the tool moved with it (0.1 mm)";
  EXPECT_LT(sliding.node_dx, 1e-3) << "then slid: the tool went on 4 mm";
  EXPECT_GT(sticking.ratio_end, 1.0) << "mu 5: still stuck after 4 mm, the shear keeps growing";
  EXPECT_GT(sticking.node_dx, 0.0039) << "a stuck node moves with the tool (4 mm)";
  EXPECT_LT(std::fabs(smooth.node_dx), 0.2e-3) << "a frictionless tool slides over the tissue";
  for (const Drag* d : {&smooth, &sliding, &sticking})
    EXPECT_LT(d->support_gap, 0.05) << "the supports balance the tool's force, tangential part included";
}

TEST_P(Contract, GraspedTissueFollowsTheToolAndPullsBack) {
  const auto m = slab(8);
  auto b = make(m);
  const double r = 0.004;
  Scheduler sched(*b, m, tools_settings({sphere(r)}));
  const Vec3<double> touch{0.0203, 0.0196, kTop + r};
  // press 1 mm, grasp, lift to 3 mm above the undeformed top, hold, release
  std::vector<Waypoint> path = {{0.0, touch + Vec3<double>{0, 0, 0.002}},
                                {0.05, touch - Vec3<double>{0, 0, 0.001}},
                                {0.1, touch - Vec3<double>{0, 0, 0.001}, true},
                                {0.3, touch + Vec3<double>{0, 0, 0.003}, true},
                                {0.5, touch + Vec3<double>{0, 0, 0.003}, true},
                                {0.6, touch + Vec3<double>{0, 0, 0.003}, false}};
  ScriptedDevice dev(path);
  TickReport rep;
  index_t grasped = 0;
  while (sched.time() < 0.5) {
    rep = sched.tick(dev);
    grasped = std::max(grasped, rep.tools[0].grasped);
  }
  ASSERT_GT(grasped, 0);
  EXPECT_TRUE(rep.tools[0].grasp);
  EXPECT_EQ(rep.tools[0].grasped, grasped) << "the grasped set is fixed while the button is held";
  // the grasped nodes rose with the tool: the tissue is pulled up by ~4 mm
  const Fields f = b->download();
  const index_t n = m.n_nodes;
  double max_uz = 0;
  for (const ContactNode& c : b->contacts()) {
    EXPECT_EQ(c.kind, kGrasped);
    max_uz = std::max(max_uz, f.u[2 * n + c.node]);
  }
  EXPECT_GT(max_uz, 0.003);
  EXPECT_LT(rep.force.z, 0.0) << "the stretched tissue pulls the tool down: the force includes tension";
  while (sched.time() < 0.7) rep = sched.tick(dev);  // released 3 mm above the surface
  EXPECT_EQ(rep.tools[0].grasped, 0);
  EXPECT_EQ(rep.contact_nodes, 0);
}

TEST_P(Contract, TwoToolsEachFeelTheirOwnForce) {
  const auto m = slab(8);
  auto b = make(m);
  const double r = 0.004;
  Scheduler sched(*b, m, tools_settings({sphere(r, 0, "left"), sphere(r, 0.01, "right")}));
  ScriptedDevice left(press_at(0.011, 0.02, r, 0.001)), right(press_at(0.029, 0.02, r, 0.003));
  Device* devices[] = {&left, &right};
  TickReport rep;
  while (sched.time() < 0.4) rep = sched.tick(devices);
  ASSERT_EQ(rep.n_tools, 2);
  EXPECT_GT(rep.tools[0].contact_nodes, 0);
  EXPECT_GT(rep.tools[1].contact_nodes, 0);
  EXPECT_GT(rep.tools[0].force.z, 0);
  EXPECT_GT(rep.tools[1].force.z, 1.5 * rep.tools[0].force.z) << "the deeper press feels more";
  for (const ContactNode& c : b->contacts()) {
    const index_t n = m.n_nodes;
    const double x = m.X[c.node];
    EXPECT_EQ(c.tool, x < 0.02 ? 0 : 1) << "node " << c.node << " at x = " << x;
    (void)n;
  }
  // the devices got their own tool's force
  EXPECT_EQ(left.last_force().z, rep.tools[0].force.z);
  EXPECT_EQ(right.last_force().z, rep.tools[1].force.z);
}

TEST_P(Contract, ASmallToolBetweenNodesIsCaughtByTheFaces) {
  const auto m = slab(4);  // 10 mm cells: a 1 mm tool fits between the nodes
  const double r = 0.001;
  for (bool face : {true, false}) {
    auto b = make(m);
    SchedulerSettings st = tools_settings({sphere(r)});
    st.contact.face = face;
    Scheduler sched(*b, m, st);
    ScriptedDevice dev(press_at(0.0233, 0.0167, r, 0.002));  // inside a top triangle, away from its corners
    TickReport rep;
    while (sched.time() < 0.3) rep = sched.tick(dev);
    if (face) {
      EXPECT_GT(rep.contact_nodes, 0);
      EXPECT_GT(rep.force.z, 0);
      EXPECT_LT(rep.max_disp, 0.0025);
      EXPECT_GT(rep.max_disp, 0.0015) << "the surface under the tool follows it down";
    } else {  // node contact alone lets it slip through the face: what face contact is for
      EXPECT_EQ(rep.contact_nodes, 0);
      EXPECT_EQ(norm(rep.force), 0.0);
    }
  }
}

TEST_P(Contract, AFastPlungeIsCaughtByOneCheckThroughTheFaceSide) {
  const auto m = slab(8);
  const index_t n = m.n_nodes;
  const double r = 0.002;
  // from 20 mm above to 3 mm deep within one tick (23 m/s: 11 radii in the
  // tick). Checked every r / 2 of travel (the default) the tool pushes the
  // surface ahead of it; checked once per step (max_travel 1000 radii) the
  // tip lands 1 mm under the surface, behind the faces over it, which the
  // sidedness rule pushes inward (along -N), not out over the tool. Either
  // way the top node nearest the axis ends under the tip.
  for (double travel : {0.5, 1000.0}) {
    auto b = make(m);
    SchedulerSettings st = tools_settings({sphere(r)});
    st.contact.max_travel = travel;
    Scheduler sched(*b, m, st);
    const Vec3<double> top{0.0203, 0.0196, kTop + r};
    ScriptedDevice dev(std::vector<Waypoint>{{0.0, top + Vec3<double>{0, 0, 0.02}},
                                             {0.001, top + Vec3<double>{0, 0, 0.02}},
                                             {0.002, top - Vec3<double>{0, 0, 0.003}},
                                             {1.0, top - Vec3<double>{0, 0, 0.003}}});
    sched.tick(dev);
    const TickReport rep = sched.tick(dev);  // the fast tick
    const Fields f = b->download();
    index_t under = -1;  // the top node nearest the tool's axis
    double best = INFINITY;
    for (index_t a = 0; a < n; ++a)
      if (m.X[2 * n + a] == kTop && std::hypot(m.X[a] - top.x, m.X[n + a] - top.y) < best) {
        best = std::hypot(m.X[a] - top.x, m.X[n + a] - top.y);
        under = a;
      }
    const double z = m.X[2 * n + under] + f.u[2 * n + under] - rep.tool.z;  // relative to the tip centre
    EXPECT_GT(rep.contact_nodes, 0) << "max_travel " << travel;
    EXPECT_LT(z, -0.5 * r) << "max_travel " << travel << ": the node under the tool is not under the tip";
  }
}

TEST_P(Contract, AToolCrossingAThinPlateWithinAStepIsSubSteppedNotTunnelled) {
  // a 40 x 40 x 1 mm plate held at its sides and a 0.5 mm tool moving
  // 2.5 mm per TLED step (17 m/s). Its centre is 0.25 mm over the tool's
  // reach of the plate at the end of one step and 0.25 mm under it at the
  // end of the next. Checked every r / 2 of travel (the default) it meets
  // the plate and throws it down; checked once per step it never touches
  // it: it tunnelled.
  ModelInput in;
  box_mesh(in, 10, 10, 1, 0.04, 0.04, 0.001);
  const double E = 3000, nu = 0.45;
  in.materials = {{E / (2 * (1 + nu)), E / (3 * (1 - 2 * nu)), 1000}};
  in.fixed.assign(in.nodes.size() / 3, 0);
  for (size_t i = 0; i < in.fixed.size(); ++i) {
    const double x = in.nodes[3 * i], y = in.nodes[3 * i + 1];
    in.fixed[i] = x == 0.0 || y == 0.0 || x == 0.04 || y == 0.04;
  }
  in.source = "thin plate";
  const auto m = build_model(in);
  const double r = 0.0005, step_travel = 0.0025;
  int steps = 0;
  {  // the number of steps in a tick
    auto b = make(m);
    Scheduler sched(*b, m, tools_settings({sphere(r)}));
    ScriptedDevice far(std::vector<Waypoint>{{0.0, {0.02, 0.02, 0.05}}});
    steps = sched.tick(far).steps;
  }
  ASSERT_GT(steps, 1);
  // centre at the end of the last two steps: z = 1.75 mm, then -0.75 mm
  const Vec3<double> below{0.0203, 0.0196, -0.00075}, above = below + Vec3<double>{0, 0, steps * step_travel};
  for (double travel : {0.5, 1000.0}) {
    auto b = make(m);
    SchedulerSettings st = tools_settings({sphere(r)});
    st.contact.max_travel = travel;
    Scheduler sched(*b, m, st);
    ScriptedDevice dev(std::vector<Waypoint>{{0.0, above}, {0.001, above}, {0.002, below}, {1.0, below}});
    EXPECT_EQ(sched.tick(dev).max_disp, 0.0);
    const TickReport rep = sched.tick(dev);  // the crossing tick
    if (travel < 1)
      EXPECT_GT(rep.max_disp, 1e-3) << "the sub-stepped tool met the plate and threw it down";
    else
      EXPECT_EQ(rep.max_disp, 0.0) << "one check per step: the tool went through the plate without touching it";
  }
}

TEST_P(Contract, ARigidSupportUnderTheToolIsReportedByName) {
  const auto m = slab(4, /*fix_all=*/true);
  auto b = make(m);
  const double r = 0.004;
  Scheduler sched(*b, m, tools_settings({sphere(r)}));
  ScriptedDevice dev(press_at(0.02, 0.02, r, 0.002));
  TickReport rep;
  std::vector<std::string> notes;
  while (sched.time() < 0.3) {
    rep = sched.tick(dev);
    for (std::string& s : sched.take_notes()) notes.push_back(std::move(s));
  }
  EXPECT_GT(rep.tools[0].rigid_nodes, 0);
  EXPECT_EQ(rep.contact_nodes, 0);
  EXPECT_EQ(norm(rep.force), 0.0);
  ASSERT_EQ(notes.size(), 1u) << "reported once per episode";
  EXPECT_NE(notes[0].find("rigid support"), std::string::npos) << notes[0];
  const std::vector<ContactNode> c = b->contacts();
  ASSERT_FALSE(c.empty());
  EXPECT_EQ(c[0].kind, kRigidContact);
  EXPECT_NE(notes[0].find(std::to_string(c[0].node)), std::string::npos) << notes[0];
}

TEST_P(Contract, ContactCandidatesSeedALimitedRegion) {
  const auto m = slab(8);
  auto b = make(m);
  const double r = 0.004;
  SchedulerSettings st = tools_settings({sphere(r)});
  st.depth = 2;
  Scheduler sched(*b, m, st);
  EXPECT_EQ(sched.region().n_elems, 0);  // nothing touched yet
  ScriptedDevice dev(press_at(0.0203, 0.0196, r, 0.002));
  TickReport rep;
  while (sched.time() < 0.3) rep = sched.tick(dev);
  EXPECT_GT(rep.contact_nodes, 0);
  EXPECT_GT(rep.region_elems, 0);
  EXPECT_LT(rep.region_elems, m.n_elems);
  const Region reg = b->region();
  for (const ContactNode& c : b->contacts()) EXPECT_EQ(reg.role[c.node], kInner) << "node " << c.node;
  EXPECT_GT(rep.force.z, 0);
  // candidates are not-yet-inner surface nodes the pending motion reaches
  ToolMotion far_away{{{0.005, 0.005, kTop + r}, {0, 0, 1}}, {{0.005, 0.005, kTop + r - 0.001}, {0, 0, 1}}};
  b->move_tools(std::span<const ToolMotion>(&far_away, 1));
  const std::vector<index_t> cand = b->contact_candidates();
  ASSERT_FALSE(cand.empty());
  EXPECT_TRUE(std::is_sorted(cand.begin(), cand.end()));
  for (index_t a : cand) {
    EXPECT_NE(reg.role[a], kInner);
    EXPECT_TRUE(m.node_flags[a] & kSurface);
  }
}

/// Every member of two reductions, bit for bit.
void expect_same(const Reductions& a, const Reductions& b) {
  const auto same3 = [](Vec3<double> x, Vec3<double> y) { return x.x == y.x && x.y == y.y && x.z == y.z; };
  EXPECT_TRUE(same3(a.reaction, b.reaction));
  EXPECT_TRUE(same3(a.internal, b.internal));
  EXPECT_EQ(a.free_force2, b.free_force2);
  EXPECT_EQ(a.held_force2, b.held_force2);
  EXPECT_EQ(a.kinetic, b.kinetic);
  EXPECT_EQ(a.max_disp, b.max_disp);
  EXPECT_EQ(a.strain_energy, b.strain_energy);
  EXPECT_EQ(a.front_disp, b.front_disp);
  EXPECT_EQ(a.visco_power, b.visco_power);
  EXPECT_EQ(a.visco_stored, b.visco_stored);
  EXPECT_EQ(a.bad_elem, b.bad_elem);
  EXPECT_EQ(a.bad_J, b.bad_J);
  EXPECT_EQ(a.finite, b.finite);
  for (int t = 0; t < kMaxTools; ++t) {
    EXPECT_TRUE(same3(a.tools[t].reaction, b.tools[t].reaction)) << "tool " << t;
    EXPECT_EQ(a.tools[t].contact, b.tools[t].contact) << "tool " << t;
    EXPECT_EQ(a.tools[t].grasped, b.tools[t].grasped) << "tool " << t;
    EXPECT_EQ(a.tools[t].rigid, b.tools[t].rigid) << "tool " << t;
    EXPECT_EQ(a.tools[t].rigid_first, b.tools[t].rigid_first) << "tool " << t;
    EXPECT_EQ(a.tools[t].outside, b.tools[t].outside) << "tool " << t;
  }
}

// advance_reduce (one graph on the cuda backend) against advance then reduce:
// a tool pressing and then grasping, over the whole mesh and a limited
// region, with step counts that start graphs at every buffer phase, one of
// more steps than a graph holds, and none.
TEST_P(Contract, AdvanceReduceGivesTheBitsOfAdvanceThenReduce) {
  const auto m = slab(8);
  const double r = 0.004;
  const ToolShape shape{"probe", r, 0.01};
  for (int depth : {kDepthAll, 2}) {
    SCOPED_TRACE(::testing::Message() << "depth " << depth);
    auto twice = make(m), once = make(m);
    for (Backend* b : {twice.get(), once.get()}) b->set_tools(std::span<const ToolShape>(&shape, 1));
    double z = kTop + r + 5e-4, x = 0.0203;
    int tick = 0;
    bool seeded = depth == kDepthAll;
    // the tool moves in every tick (sliding along x), so that ticks of more than one graph's steps (33, 65)
    // cut a moving motion: advance_reduce must cut it where advance does
    for (int steps : {4, 4, 7, 1, 33, 4, 0, 65, 5, 4}) {
      SCOPED_TRACE(::testing::Message() << "tick " << tick << ", " << steps << " steps");
      const double z1 = std::max(z - 8e-4, kTop + r - 2.5e-3), x1 = x + 2e-4;
      const ToolMotion mv{{{x, 0.0196, z}, {0, 0, 1}}, {{x1, 0.0196, z1}, {0, 0, 1}}, tick >= 7};
      z = z1;
      x = x1;
      for (Backend* b : {twice.get(), once.get()}) {
        b->move_tools(std::span<const ToolMotion>(&mv, 1));
        if (seeded) continue;
        b->build_region({}, depth);  // empty, as the Scheduler starts: candidates are nodes outside the region
        const std::vector<index_t> seeds = b->contact_candidates();
        ASSERT_FALSE(seeds.empty());
        b->build_region(seeds, depth);
      }
      seeded = true;
      twice->advance(steps);
      const Reductions want = twice->reduce();
      const Reductions got = once->advance_reduce(steps);
      expect_same(got, want);
      if (tick >= 3) {
        EXPECT_GT(got.tools[0].contact, 0);
      }
      if (tick >= 7) {
        EXPECT_GT(got.tools[0].grasped, 0);
      }
      const Fields a = twice->download(), b = once->download();
      EXPECT_EQ(b.u, a.u);
      EXPECT_EQ(b.f, a.f);
      EXPECT_EQ(b.node_p, a.node_p);
      EXPECT_EQ(b.elem_J, a.elem_J);
      ++tick;
    }
  }
  auto b = make();
  EXPECT_THROW(b->advance_reduce(1), std::logic_error);
  b->upload(m);
  EXPECT_THROW(b->advance_reduce(-1), std::invalid_argument);
}

// The motion (u^n, u^{n-1}) read from one run and set on a fresh backend
// (set_motion, what a cut carries over) steps on as that run does: bit for
// bit in double, within float's rounding of the carried low bits (which
// set_motion clears) in float.
TEST_P(Contract, AMotionSetFromAnotherRunStepsOnAsThatRunDoes) {
  const auto m = box_model(3, true);
  auto a = make(m);
  a->set_displacements(field(m, [](Vec3<double> X) { return Vec3<double>{0.05 * X.x, 0.02 * X.z, 0}; }));
  a->advance(3);  // moving: u^n != u^{n-1}
  const std::vector<double> u = a->download().u, u_prev = a->previous_displacements();
  ASSERT_EQ(u_prev.size(), u.size());
  double moving = 0;
  for (std::size_t k = 0; k < u.size(); ++k) moving = std::max(moving, std::fabs(u[k] - u_prev[k]));
  ASSERT_GT(moving, 0);
  auto b = make(m);
  b->set_motion(u, u_prev);
  EXPECT_EQ(b->download().u, u);
  EXPECT_EQ(b->previous_displacements(), u_prev);
  a->advance(5);
  b->advance(5);
  const std::vector<double> ua = a->download().u;
  expect_same_run(ua, b->download().u);
  // bad motions: named, as set_displacements' are
  std::vector<double> short_prev(u_prev.begin(), u_prev.end() - 1), nan_prev = u_prev;
  nan_prev[4] = NAN;
  EXPECT_THROW(b->set_motion(u, short_prev), std::invalid_argument);
  try {
    b->set_motion(u, nan_prev);
    ADD_FAILURE() << "a NaN previous displacement was taken";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("node 4: previous displacement x = nan is not finite"), std::string::npos)
        << e.what();
  }
  EXPECT_THROW(make()->previous_displacements(), std::logic_error);
}

// New nodal masses (the step guard's, Backend::set_masses) step on as an
// upload of the model with them does (bit for bit in double, within float's
// carried bits in float), the state kept; the deformed altitudes are the
// model's at the downloaded displacements.
TEST_P(Contract, NewMassesStepOnAsAnUploadWithThem) {
  const auto m = box_model(3, true);
  TissueModel<double> heavier = m;
  for (index_t a = 0; a < m.n_nodes; a += 3) heavier.mass[a] *= 7.5;
  set_time_step(heavier, m.dt, m.damping);  // the constants set_masses computes
  auto a = make(m);
  a->set_displacements(field(m, [](Vec3<double> X) { return Vec3<double>{0.05 * X.x, 0.02 * X.z, 0}; }));
  a->advance(3);
  const std::vector<double> u = a->download().u, u_prev = a->previous_displacements();
  a->set_masses(heavier.mass, m.dt, m.damping);
  auto b = make(heavier);
  b->set_motion(u, u_prev);
  a->advance(5);
  b->advance(5);
  const std::vector<double> ua = a->download().u;
  expect_same_run(ua, b->download().u);
  auto c = make(m);  // the old masses step elsewhere: the check can fail
  c->set_motion(u, u_prev);
  c->advance(5);
  EXPECT_NE(c->download().u, ua);
  const std::vector<index_t> elems = {0, 7, m.n_elems - 1};
  const std::vector<double> alt = a->deformed_altitudes(m, elems);
  for (std::size_t k = 0; k < elems.size(); ++k)
    EXPECT_NEAR(alt[k], deformed_altitude(m, std::span<const double>(ua), elems[k]), 1e-12 * alt[k]);
  EXPECT_THROW(a->set_masses(box_model(2, true).mass, m.dt, m.damping), std::invalid_argument);
  heavier.mass[2] = -1;
  EXPECT_THROW(a->set_masses(heavier.mass, m.dt, m.damping), std::invalid_argument);
  const std::vector<index_t> outside = {m.n_elems};
  EXPECT_THROW(a->deformed_altitudes(m, outside), std::out_of_range);
}

// advance_reduce_in_region runs the tick exactly when contact_candidates()
// is empty (the cuda backend tests that inside the tick's graph), with the
// bits of advance_reduce; otherwise nothing moves and the tools stay.
TEST_P(Contract, AdvanceReduceInRegionRunsOnlyWhileTheRegionHolds) {
  const auto m = slab(8);
  const double r = 0.004;
  const ToolShape shape{"probe", r, 0.01};
  auto checked = make(m), plain = make(m);
  for (Backend* b : {checked.get(), plain.get()}) {
    b->set_tools(std::span<const ToolShape>(&shape, 1));
    const ToolMotion start{{{0.0203, 0.0196, kTop + r + 5e-4}, {0, 0, 1}}, {{0.0203, 0.0196, kTop + r - 5e-4}, {0, 0, 1}}};
    b->move_tools(std::span<const ToolMotion>(&start, 1));
    b->build_region({}, 2);
    b->build_region(b->contact_candidates(), 2);
  }
  double z = kTop + r - 5e-4;
  int ran = 0, refused = 0, refused_in_contact = 0;
  // pressing in place (the region holds), then a slide that leaves the region; steps 4 then 7 (two graphs)
  for (int tick = 0; tick < 10; ++tick) {
    SCOPED_TRACE(::testing::Message() << "tick " << tick);
    const double x0 = tick < 6 ? 0.0203 : 0.0203 + 0.004 * (tick - 6), x1 = tick < 5 ? 0.0203 : x0 + 0.004;
    const ToolMotion mv{{{x0, 0.0196, z}, {0, 0, 1}}, {{x1, 0.0196, z - 1e-4}, {0, 0, 1}}};
    const int steps = tick % 2 ? 7 : 4;
    for (Backend* b : {checked.get(), plain.get()}) b->move_tools(std::span<const ToolMotion>(&mv, 1));
    const bool reaches = !plain->contact_candidates().empty();
    const Fields before = checked->download();
    const std::vector<ContactNode> contacts_before = checked->contacts();
    const std::optional<Reductions> got = checked->advance_reduce_in_region(steps);
    EXPECT_EQ(got.has_value(), !reaches);
    if (!got) {
      ++refused;
      const Fields after = checked->download();
      EXPECT_EQ(after.u, before.u) << "nothing ran";
      EXPECT_EQ(after.f, before.f);
      EXPECT_EQ(after.node_p, before.node_p);  // passes 1-2 did nothing either
      EXPECT_EQ(after.elem_J, before.elem_J);
      // nor the contact stage (the sweep and the merge of a refused tick store nothing)
      if (!contacts_before.empty()) ++refused_in_contact;
      expect_same_contacts(checked->contacts(), contacts_before, "the contacts of a refused tick");
      // the caller grows the region with the same candidates, then runs the tick
      for (Backend* b : {checked.get(), plain.get()}) {
        const std::vector<index_t> cand = b->contact_candidates();
        ASSERT_FALSE(cand.empty());
        std::vector<index_t> seeds = cand;
        for (index_t a : b->region().seeds) seeds.push_back(a);
        std::sort(seeds.begin(), seeds.end());
        seeds.erase(std::unique(seeds.begin(), seeds.end()), seeds.end());
        b->build_region(seeds, 2);
      }
      expect_same(checked->advance_reduce(steps), plain->advance_reduce(steps));
    } else {
      ++ran;
      expect_same(*got, plain->advance_reduce(steps));
    }
    EXPECT_EQ(checked->download().u, plain->download().u);
    z -= 1e-4;
  }
  EXPECT_GT(ran, 3);
  EXPECT_GT(refused, 0);
  EXPECT_GT(refused_in_contact, 0) << "a tick refused while the tool pressed";
  EXPECT_THROW(checked->advance_reduce_in_region(-1), std::invalid_argument);
}

// A tick in two halves (start_tick, finish_tick) gives the bits of the one call, also with two backends' ticks
// in flight at once (a batch's scenes), the region holding or not; between the halves the backend refuses
// every other call.
TEST_P(Contract, ATickInTwoHalvesGivesTheBitsOfOneCall) {
  const auto m = slab(8);
  const double r = 0.004;
  const ToolShape shape{"probe", r, 0.01};
  for (int depth : {kDepthAll, 2}) {
    SCOPED_TRACE(::testing::Message() << "depth " << depth);
    auto one = make(m), first = make(m), second = make(m);
    std::vector<Backend*> all = {one.get(), first.get(), second.get()};
    const ToolMotion start{{{0.0203, 0.0196, kTop + r + 5e-4}, {0, 0, 1}}, {{0.0203, 0.0196, kTop + r - 5e-4}, {0, 0, 1}}};
    for (Backend* b : all) {
      b->set_tools(std::span<const ToolShape>(&shape, 1));
      b->move_tools(std::span<const ToolMotion>(&start, 1));
      if (depth != kDepthAll) {
        b->build_region({}, depth);
        b->build_region(b->contact_candidates(), depth);
      }
    }
    double z = kTop + r - 5e-4;
    int refused = 0;
    for (int tick = 0; tick < 10; ++tick) {
      SCOPED_TRACE(::testing::Message() << "tick " << tick);
      const double x0 = tick < 6 ? 0.0203 : 0.0203 + 0.004 * (tick - 6), x1 = tick < 5 ? 0.0203 : x0 + 0.004;
      const ToolMotion mv{{{x0, 0.0196, z}, {0, 0, 1}}, {{x1, 0.0196, z - 1e-4}, {0, 0, 1}}};
      const int steps = tick % 2 ? 7 : 4;
      for (Backend* b : all) b->move_tools(std::span<const ToolMotion>(&mv, 1));
      const bool in_region = depth != kDepthAll;
      std::optional<Reductions> want =
          in_region ? one->advance_reduce_in_region(steps) : std::optional(one->advance_reduce(steps));
      first->start_tick(steps, in_region);
      second->start_tick(steps, in_region);
      EXPECT_TRUE(first->tick_pending());
      EXPECT_THROW(first->download(), std::logic_error);
      EXPECT_THROW(first->advance(1), std::logic_error);
      const std::optional<Reductions> got2 = second->finish_tick();
      const std::optional<Reductions> got1 = first->finish_tick();
      EXPECT_FALSE(first->tick_pending());
      ASSERT_EQ(got1.has_value(), want.has_value());
      ASSERT_EQ(got2.has_value(), want.has_value());
      if (!want) {  // the region must grow first: every backend grows it alike, then runs the tick
        ++refused;
        for (Backend* b : all) {
          std::vector<index_t> seeds = b->contact_candidates();
          for (index_t a : b->region().seeds) seeds.push_back(a);
          std::sort(seeds.begin(), seeds.end());
          seeds.erase(std::unique(seeds.begin(), seeds.end()), seeds.end());
          b->build_region(seeds, depth);
        }
        want = one->advance_reduce(steps);
        first->start_tick(steps, false);
        expect_same(*first->finish_tick(), *want);
        expect_same(second->advance_reduce(steps), *want);
      } else {
        expect_same(*got1, *want);
        expect_same(*got2, *want);
      }
      const Fields a = one->download(), b1 = first->download(), b2 = second->download();
      EXPECT_EQ(b1.u, a.u);
      EXPECT_EQ(b2.u, a.u);
      EXPECT_EQ(b1.f, a.f);
      EXPECT_EQ(b1.node_p, a.node_p);
      z -= 1e-4;
    }
    if (depth != kDepthAll) {
      EXPECT_GT(refused, 0) << "the slide left the region";
    }
    EXPECT_THROW(first->finish_tick(), std::logic_error);
    first->start_tick(0, false);  // no steps: the reduction alone
    expect_same(*first->finish_tick(), one->reduce());
  }
}

// A tool whose first pose already presses the tissue is brought in from
// out of contact along its axis at kEntrySpeed (the Scheduler's entry), named
// in a note, and then follows its device.
TEST_P(Contract, AToolStartingInContactIsBroughtInFromOutsideAndNoted) {
  const auto m = slab(8);
  auto b = make(m);
  const double r = 0.004;
  Scheduler sched(*b, m, tools_settings({sphere(r, 0.02)}));
  const Vec3<double> held{0.0203, 0.0196, kTop + r - 0.0015};  // 1.5 mm deep, held
  ScriptedDevice dev(std::vector<Waypoint>{{0.0, held}});
  const TickReport first = sched.tick(dev);
  EXPECT_EQ(first.contact_nodes, 0) << "it starts out of contact";
  EXPECT_GT(first.tools[0].tip.z, held.z + 1.5e-3) << "retracted along its axis (+z)";
  const std::vector<std::string> notes = sched.take_notes();
  ASSERT_EQ(notes.size(), 1u);
  EXPECT_NE(notes[0].find("tool 'probe' starts in contact with the tissue: it is brought in from 1.6 mm back"),
            std::string::npos)
      << notes[0];
  TickReport rep = first;
  while (sched.time() < 0.1 - 1e-9) rep = sched.tick(dev);  // 1.6 mm at 25 mm/s: there at 64 ms
  EXPECT_EQ(rep.tools[0].tip.z, held.z) << "it follows its device once in";
  EXPECT_GT(rep.contact_nodes, 0);
  EXPECT_GT(rep.force.z, 0);
  EXPECT_TRUE(sched.take_notes().empty());
}

/// The force on a 4 mm sphere held 1.1 radii deep in a nearly incompressible
/// block (nu 0.49, 20 x 20 x 10 mm, 1.67 mm cells) after a path that starts
/// `start` deep (0: at the surface) and presses to 1.1 R over 0.2 s.
Vec3<double> deep_press(Backend& b, double start) {
  ModelInput in;
  box_mesh(in, 12, 12, 6, 0.02, 0.02, 0.01);
  const double E = 3000, nu = 0.49;
  in.materials = {{E / (2 * (1 + nu)), E / (3 * (1 - 2 * nu)), 1000}};
  in.fixed.assign(in.nodes.size() / 3, 0);
  for (size_t i = 0; i < in.fixed.size(); ++i) in.fixed[i] = in.nodes[3 * i + 2] == 0.0;
  in.source = "nu 0.49 block";
  const TissueModel<double> m = build_model(in);
  b.upload(m);
  const double R = 0.004;
  Scheduler sched(b, m, tools_settings({sphere(R)}));
  const Vec3<double> top{0.01, 0.01, 0.01 + R};
  ScriptedDevice dev(std::vector<Waypoint>{{0.0, top - Vec3<double>{0, 0, start}},
                                           {0.2, top - Vec3<double>{0, 0, 1.1 * R}},
                                           {0.45, top - Vec3<double>{0, 0, 1.1 * R}}});
  TickReport rep;
  while (sched.time() < 0.45 - 1e-9) rep = sched.tick(dev);  // a stop throws, naming the element
  return rep.force;
}

// Extremes end well: a press to 1.1 radii into a nu 0.49 block runs to its
// end, and so does the same press from a start half a radius inside the
// block (brought in from outside: it would otherwise push the surface half a
// radius in one step and invert elements two radii away), to the same force.
TEST_P(Contract, APressBeyondTheRadiusFromAStartInsideTheBlockEndsAsOneFromOutside) {
  const Vec3<double> outside = deep_press(*make(), 0.0), inside = deep_press(*make(), 0.002);
  EXPECT_GT(outside.z, 0.1);
  EXPECT_LT(norm(inside - outside), 0.01 * norm(outside)) << "inside " << inside.z << " N, outside " << outside.z;
}

TEST_P(Contract, AToolCrossingTheSurfaceAt100MetresPerSecondPushesItAndIsNamed) {
  // a 2 mm sphere from 90 mm above the slab's top to 10 mm under it in one 1 ms tick of 4 TLED steps
  // (100 m/s, 25 mm a step): the steps' sub-checks (every r / 2 of its path) meet the top and carry it down
  // with the tool, on the whole mesh and on a region of 2 rings seeded along the swept path; and a speed
  // that carries the surface 5 times half an edge in one step is named, with the tool, not left silent
  const auto m = slab(8, false, 0.00025);
  const double r = 0.002;
  const Vec3<double> from{0.0203, 0.0196, 0.11}, to{0.0203, 0.0196, 0.01};
  for (int depth : {kDepthAll, 2}) {
    SCOPED_TRACE(depth);
    auto b = make(m);
    SchedulerSettings st = tools_settings({sphere(r)});
    st.depth = depth;
    Scheduler sched(*b, m, st);
    ASSERT_EQ(sched.steps_per_tick(), 4);
    ScriptedDevice dev(std::vector<Waypoint>{{0.0, from}, {0.001, from}, {0.002, to}, {1.0, to}});
    EXPECT_EQ(sched.tick(dev).contact_nodes, 0);
    sched.take_notes();
    const TickReport rep = sched.tick(dev);  // the crossing tick
    EXPECT_GT(rep.contact_nodes, 0) << "the swept checks met the surface";
    EXPECT_GT(rep.max_disp, 2 * r) << "the surface went down with the tool: not tunnelled";
    RecordProperty(depth == kDepthAll ? "max_disp_mm_whole" : "max_disp_mm_region", std::to_string(1e3 * rep.max_disp));
    const std::vector<std::string> notes = sched.take_notes();
    bool named = false;
    for (const std::string& s : notes)
      named = named || (s.find("tool 'probe' moved 25 mm per TLED step (100 m/s) in contact") != std::string::npos);
    EXPECT_TRUE(named) << "no note names the fast tool";
  }
  {  // across the slab at mid-height, 25 mm a step: the side it meets is carried 20 mm into 5 mm elements in
     // one step and the run stops; the message names the tool and its speed, not only the element
    auto b = make(m);
    Scheduler sched(*b, m, tools_settings({sphere(r)}));
    const Vec3<double> left{-0.03, 0.0196, 0.012}, right{0.07, 0.0196, 0.012};
    ScriptedDevice dev(std::vector<Waypoint>{{0.0, left}, {0.001, left}, {0.002, right}, {1.0, right}});
    sched.tick(dev);
    try {
      sched.tick(dev);
      sched.tick(dev);
      ADD_FAILURE() << "the crossing did not stop the run";
    } catch (const SimulationError& e) {
      EXPECT_NE(std::string(e.what()).find("tool 'probe' moved 25 mm per TLED step (100 m/s)"), std::string::npos)
          << e.what();
    }
  }
}

TEST_P(Contract, AHorizontalCapsulePressedThroughTheTopHoldsItOrIsNamed) {
  // a horizontal capsule (1.5 mm radius, 30 mm shaft) pressed 12 mm into 6.7 mm elements at 0.9 dt_crit: the
  // tissue pushes the faces under the shaft more than its radius into it in one step, beyond what the
  // contact can hold (docs/contact.md, the rule's limit), and the shaft ends under the top face. It may not
  // do so silently: the tool is named in a note when its contact ends inside the tissue
  const auto m = slab(6);
  const double r = 0.0015, l = 0.03;
  auto b = make(m);
  Scheduler sched(*b, m, tools_settings({{{"shaft", r, l}, {1, 0, 0}}}));
  const Vec3<double> top{0.0053, 0.0196, kTop + r};
  ScriptedDevice dev(std::vector<Waypoint>{{0.0, top + Vec3<double>{0, 0, 0.003}},
                                           {0.05, top},
                                           {0.55, top - Vec3<double>{0, 0, 0.012}},
                                           {1.0, top - Vec3<double>{0, 0, 0.012}}});
  std::vector<std::string> notes;
  TickReport rep;
  double peak = 0;
  while (sched.time() < 0.7) {
    rep = sched.tick(dev);
    peak = std::max(peak, rep.force.z);
    for (std::string& s : sched.take_notes()) notes.push_back(std::move(s));
  }
  ASSERT_GT(peak, 0.3) << "the shaft pressed the block";
  bool named = false;
  for (const std::string& s : notes) named = named || s.find("tool 'shaft' lost contact") != std::string::npos;
  if (rep.contact_nodes > 0) {
    EXPECT_GT(rep.force.z, 0.0) << "the shaft held the surface";
  } else {
    EXPECT_TRUE(named) << "the shaft went through the top face silently (peak " << peak << " N, now 0 N)";
  }
}

// Float as close to double as float allows: a nu 0.49 cube of 3,072 tets,
// base fixed, 0.05 N spread over its top nodes from the first step, 600
// steps in both precisions. The largest |u_float - u_double| over max |u|:
// 5.5e-5 with the uncompensated central difference (docs/accuracy.md,
// section 7), 1e-6 with float's compensated update.
TEST_P(Contract, FloatStaysWithin1e5OfDoubleOnANearlyIncompressibleCube) {
  if (!is_float()) GTEST_SKIP() << "compares this backend's float with its double: runs in the float instance";
  ModelInput in;
  box_mesh(in, 8, 8, 8, kL, kL, kL);
  const double E = 3000, nu = 0.49;
  in.materials = {{E / (2 * (1 + nu)), E / (3 * (1 - 2 * nu)), 1000}};
  in.source = "nu 0.49 cube";
  const std::size_t nn = in.nodes.size() / 3;
  in.fixed.assign(nn, 0);
  std::vector<index_t> top;
  for (std::size_t i = 0; i < nn; ++i) {
    in.fixed[i] = in.nodes[3 * i + 2] == 0.0;
    if (in.nodes[3 * i + 2] == kL) top.push_back(index_t(i));
  }
  const TissueModel<double> m = build_model(in);
  std::vector<double> force;
  for (std::size_t k = 0; k < top.size(); ++k) force.insert(force.end(), {0.0, 0.0, -0.05 / double(top.size())});
  std::vector<double> u[2];
  int i = 0;
  for (Precision p : {Precision::Double, Precision::Float}) {
    auto b = create_backend(GetParam().backend, p);
    b->upload(m);
    b->set_loads(top, force);
    b->advance(600);
    u[i++] = b->download().u;
  }
  const double scale = max_abs(u[0]), drift = max_diff(u[0], u[1]) / scale;
  RecordProperty("float_vs_double", fmt::format("{:.3g}", drift));
  EXPECT_GT(scale, 1e-4) << "the load compressed the cube";
  EXPECT_LT(drift, 1e-5) << "float's largest |u - u_double| over max |u| (" << scale << " m)";
}

}  // namespace
}  // namespace tissue
