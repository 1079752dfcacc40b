// The embedding facade (tissue/simulation.hpp, libtissue): it runs a scene
// exactly as the Scheduler does, a host-driven tool equals the scripted
// one, a host's mesh presses back with a force proportional to E (the
// Neo-Hookean law's exact scaling at equilibrium), and every misuse is a
// clear exception.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include "backends/registry.hpp"
#include "core/box_mesh.hpp"
#include "core/scheduler.hpp"
#include "io/kidney.hpp"
#include "io/scene_xml.hpp"
#include "scene/validate.hpp"
#include "tissue/simulation.hpp"
#include "tissue/tissue_c.h"
#include "tests/api/api_test_support.hpp"
#include "tests/temp_dir.hpp"

namespace {

using tissue::Simulation;
using tissue::test::block;
using tissue::test::fat_press_tip;
using tissue::test::thrown;

/// Presses the block's top centre `depth` deep over 200 ticks, holds for
/// `hold` ticks; returns the force on the tool.
tissue::Vector3 press(Simulation& sim, double depth, int hold) {
  const double r = sim.tool_radius(0);
  for (int k = 1; k <= 200 + hold; ++k) {
    const double s = std::min(1.0, k / 200.0);
    sim.set_tool_pose(0, {0.01, 0.01, 0.01 + r - s * depth});
    sim.step();
  }
  return sim.force(0);
}

TEST(Facade, RunsTheKidneyExactlyAsTheScheduler) {
  Simulation sim = Simulation::load("@kidney", {"cpu", "double", "5"});
  EXPECT_EQ(sim.backend(), "cpu");
  EXPECT_EQ(sim.precision(), "double");

  tissue::scene::Scene s = tissue::io::default_kidney_scene();
  s.solver.backend = "cpu";
  s.solver.precision = tissue::Precision::Double;
  s.solver.depth = 5;
  const tissue::TissueModel<double> model = tissue::scene::load_model(s);
  auto backend = tissue::create_backend("cpu", tissue::Precision::Double);
  backend->upload(model);
  tissue::Scheduler sched(*backend, model, tissue::scene::scheduler_settings(s));
  tissue::ScriptedDevice device(s.tools.at(0).path);

  ASSERT_EQ(sim.n_nodes(), std::size_t(model.n_nodes));
  ASSERT_EQ(sim.steps_per_tick(), sched.steps_per_tick());
  double peak = 0;
  for (int k = 0; k < 300; ++k) {
    const tissue::TickReport r = sched.tick(device);
    const tissue::TickResult t = sim.step();
    ASSERT_EQ(t.tick, r.tick + 1);  // the report numbers ticks from 0, the facade counts them
    for (int c = 0; c < 3; ++c) ASSERT_EQ(t.tools[0].force[c], r.force[c]) << "tick " << k;
    peak = std::max(peak, std::fabs(r.force.z));
  }
  EXPECT_GT(peak, 1e-3);  // the scripted press has reached the kidney
  const std::vector<double> u = sim.field(tissue::Field::Displacement);
  const tissue::Fields f = backend->download();  // component-major; the facade gives x y z per node
  const std::size_t n = sim.n_nodes();
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t c = 0; c < 3; ++c) ASSERT_EQ(u[3 * i + c], f.u[c * n + i]);
}

TEST(Facade, HostPoseEqualsTheScriptedPath) {
  Simulation scripted = Simulation::load("@kidney", {"cpu", "double", ""});
  Simulation hosted = Simulation::load("@kidney", {"cpu", "double", ""});
  tissue::ScriptedDevice path(tissue::io::default_kidney_scene().tools.at(0).path);
  for (int k = 1; k <= 250; ++k) {
    const tissue::ToolInput in = path.read(k * hosted.tick_seconds());
    hosted.set_tool_pose(0, {in.tip.x, in.tip.y, in.tip.z});
    const tissue::Vector3 a = scripted.step().tools[0].force, b = hosted.step().tools[0].force;
    for (int c = 0; c < 3; ++c) ASSERT_EQ(a[c], b[c]) << "tick " << k;
  }
  EXPECT_GT(std::fabs(scripted.force(0)[2]), 1e-3);
}

TEST(Facade, MeshPressesBackInProportionToE) {
  // Neo-Hookean stress at a given deformation scales with E at fixed nu, so
  // the equilibrium force of the same press doubles with E: exactly, up to
  // the route dependence of the frictionless equilibria on a faceted
  // surface (docs/contact.md section 7: 1-2 % on coarse boxes; 1.06 % here).
  Simulation soft = Simulation::from_mesh(block(3000), {"cpu", "double", "all"});
  Simulation stiff = Simulation::from_mesh(block(6000), {"cpu", "double", "all"});
  EXPECT_TRUE(soft.warnings().empty()) << soft.warnings().front();
  const tissue::Vector3 f1 = press(soft, 1e-3, 800), f2 = press(stiff, 1e-3, 800);
  EXPECT_GT(f1[2], 1e-3);                                 // pushes the tool back up
  EXPECT_NEAR(f2[2] / f1[2], 2.0, 0.03);
  // a centred press: sideways only what the cells' diagonal split tilts (3.7 % here)
  EXPECT_LT(std::fabs(f1[0]) + std::fabs(f1[1]), 0.05 * f1[2]);
  EXPECT_GT(soft.last().tools[0].contact_nodes, 0);

  // The fields: the top centre moved down about the press depth; J near 1.
  const std::vector<double> u = soft.field(tissue::Field::Displacement);
  const std::vector<double> x = soft.field(tissue::Field::Position);
  const auto X = soft.rest_positions();
  const std::size_t top = std::size_t(tissue::box_node(6, 6, 3, 3, 3));
  EXPECT_NEAR(u[3 * top + 2], -1e-3, 2e-4);
  EXPECT_DOUBLE_EQ(x[3 * top + 2], X[3 * top + 2] + u[3 * top + 2]);
  for (double J : soft.field(tissue::Field::Jacobian)) ASSERT_NEAR(J, 1.0, 0.2);
  std::vector<float> xf(3 * soft.n_nodes());
  ASSERT_FALSE(soft.positions_on_device());
  soft.write_positions(xf.data());
  EXPECT_NEAR(xf[3 * top + 2], x[3 * top + 2], 1e-6);

  soft.reset();
  EXPECT_EQ(soft.ticks(), 0);
  for (double v : soft.field(tissue::Field::Displacement)) ASSERT_EQ(v, 0.0);
}

TEST(Facade, LoadsAreHeldByTheFixedBaseAndKeptByReset) {
  // 1 mN up on each of the top's 49 nodes, the tool far away: at rest the
  // fixed base holds the total (internal forces sum to zero over the body)
  Simulation sim = Simulation::from_mesh(block(3000), {"cpu", "double", ""});
  std::vector<std::int32_t> top;
  std::vector<double> forces;
  for (int j = 0; j <= 6; ++j)
    for (int i = 0; i <= 6; ++i) {
      top.push_back(tissue::box_node(6, 6, i, j, 3));
      forces.insert(forces.end(), {0.0, 0.0, 1e-3});
    }
  sim.set_loads(top, forces);
  const auto rest = [&] {
    for (int k = 0; k < 1500; ++k) {
      sim.set_tool_pose(0, {0.01, 0.01, 0.1});
      sim.step();
    }
    const std::vector<double> f = sim.field(tissue::Field::InternalForce), u = sim.field(tissue::Field::Displacement);
    double base = 0;
    for (int j = 0; j <= 6; ++j)
      for (int i = 0; i <= 6; ++i) base += f[3 * tissue::box_node(6, 6, i, j, 0) + 2];
    return std::pair{base, u[3 * top[24] + 2]};
  };
  const auto [base, lift] = rest();
  EXPECT_NEAR(base, -49e-3, 1e-3 * 49e-3);
  EXPECT_GT(lift, 0);
  EXPECT_EQ(sim.dissipated_energy(), 0.0);  // an elastic block
  sim.reset();  // keeps the loads
  const auto [base2, lift2] = rest();
  EXPECT_NEAR(base2, base, 1e-9 * 49e-3);
  EXPECT_NEAR(lift2, lift, 1e-9 * lift);
  sim.set_loads({}, {});  // none: the block rests unloaded
  const auto [base3, lift3] = rest();
  EXPECT_NEAR(lift3, 0, 1e-3 * lift);
  const std::vector<std::int32_t> far = {100000};
  const std::vector<double> one = {1, 0, 0};
  EXPECT_NE(thrown([&] { sim.set_loads(far, one); }).find("node 100000 out of range"), std::string::npos);
  EXPECT_NE(thrown([&] { sim.set_loads(top, one); }).find("need 3 per node"), std::string::npos);
}

TEST(Facade, TheViscoelasticKidneyReportsTheEnergyItDissipates) {
  Simulation sim = Simulation::load("@kidney-visco", {"cpu", "float", ""});
  EXPECT_EQ(sim.dissipated_energy(), 0.0);
  sim.step(600);  // into the press
  EXPECT_GT(sim.dissipated_energy(), 0.0);
  EXPECT_GT(sim.viscous_stored_energy(), 0.0);
  const double d = sim.dissipated_energy();
  sim.step(100);
  EXPECT_GT(sim.dissipated_energy(), d);  // it only grows
}

TEST(Facade, MisuseIsAClearError) {
  Simulation sim = Simulation::from_mesh(block(3000), {"cpu", "float", ""});
  EXPECT_NE(thrown([&] { sim.set_tool_pose(1, {0, 0, 0}); }).find("tool 1 does not exist"), std::string::npos);
  EXPECT_NE(thrown([&] { sim.set_tool_pose(0, {0, NAN, 0}); }).find("not finite"), std::string::npos);
  EXPECT_NE(thrown([&] { sim.step(0); }).find("must be >= 1"), std::string::npos);
  std::vector<double> small(5);
  EXPECT_NE(thrown([&] { sim.read_field(tissue::Field::Pressure, small); }).find("holds 5"), std::string::npos);
  EXPECT_NE(thrown([&] { sim.write_positions(nullptr); }).find("null"), std::string::npos);

  tissue::MeshScene bad = block(3000);
  bad.tets[4 * 7 + 2] = 100000;  // element 7 names a node that does not exist
  EXPECT_NE(thrown([&] { Simulation::from_mesh(bad); }).find("7"), std::string::npos);
  bad = block(3000);
  bad.tets.pop_back();
  EXPECT_NE(thrown([&] { Simulation::from_mesh(bad); }).find("not 4 per tetrahedron"), std::string::npos);
  bad = block(3000);
  bad.poisson_ratio = 0.5;
  EXPECT_NE(thrown([&] { Simulation::from_mesh(bad); }).find("nu"), std::string::npos);
  EXPECT_NE(thrown([&] { Simulation::load("@kidney", {"vulkan", "", ""}); }).find("vulkan"), std::string::npos);
  EXPECT_NE(thrown([&] { Simulation::load("@kidney", {"", "half", ""}); }).find("half"), std::string::npos);
  EXPECT_NE(thrown([&] { Simulation::load("/no/such/scene.xml"); }).find("/no/such/scene.xml"), std::string::npos);

  tissue::MeshScene loose = block(3000);
  loose.fixed_nodes.clear();
  EXPECT_FALSE(Simulation::from_mesh(loose).warnings().empty());  // no support: warned, not refused
}

TEST(Facade, CudaRunsTheKidneyAsTheCpuDoes) {
  const std::vector<std::string> b = tissue::available_backends();
  if (std::find(b.begin(), b.end(), "cuda") == b.end()) GTEST_SKIP() << "no usable cuda backend here";
  // depth 5, as the consistency suite compares them (under depth auto a
  // ring can be added a tick apart on the two backends)
  Simulation gpu = Simulation::load("@kidney", {"cuda", "double", "5"});
  Simulation cpu = Simulation::load("@kidney", {"cpu", "double", "5"});
  EXPECT_TRUE(gpu.positions_on_device());
  double peak = 0, worst = 0;
  for (int k = 0; k < 400; ++k) {
    const tissue::Vector3 a = gpu.step().tools[0].force, c = cpu.step().tools[0].force;
    peak = std::max(peak, std::hypot(c[0], c[1], c[2]));
    worst = std::max(worst, std::hypot(a[0] - c[0], a[1] - c[1], a[2] - c[2]));
  }
  EXPECT_GT(peak, 1e-3);
  // the backends' consistency tolerance on the kidney (tests/cuda/test_cuda_consistency.cpp)
  EXPECT_LT(worst, 2e-3 * peak) << "peak " << peak;
  const std::vector<double> xg = gpu.field(tissue::Field::Position), xc = cpu.field(tissue::Field::Position);
  double dx = 0;
  for (std::size_t i = 0; i < xg.size(); ++i) dx = std::max(dx, std::fabs(xg[i] - xc[i]));
  EXPECT_LT(dx, 1e-5);  // m
}

/// Two 20 x 20 x 10 mm blocks of 6 x 6 x 3 cells (E 3 kPa, nu 0.4), the
/// second 30 mm along x from the first, each held at its base by a box that
/// spans both bases but selects its own body's nodes: the bodies "left" and
/// "right" of one scene, or (alone = 0 or 1) that block alone as a
/// single-mesh scene. A 4 mm sphere parked above between them; cpu, double, damping and
/// dt fixed so that the two scenes step alike. Written (one TetGen pair per
/// body) into dir; returns the scene file.
std::string blocks_scene(const tissue::testing_support::TempDir& dir, int alone = -1) {
  namespace sc = tissue::scene;
  sc::Scene s;
  s.materials.push_back({.name = "tissue", .form = sc::Material::Form::YoungPoisson, .a = 3000, .b = 0.4, .rho = 1000});
  for (int k = 0; k < 2; ++k) {
    if (alone >= 0 && k != alone) continue;
    tissue::ModelInput in;
    tissue::box_mesh(in, 6, 6, 3, 0.02, 0.02, 0.01);
    for (std::size_t i = 0; i < in.nodes.size(); i += 3) in.nodes[i] += 0.03 * k;
    const int body = alone >= 0 ? -1 : int(s.bodies.size());
    sc::Body b;
    b.name = k == 0 ? "left" : "right";
    b.first_node = tissue::index_t(s.nodes.size() / 3);
    b.first_element = tissue::index_t(s.tets.size() / 4);
    b.n_nodes = tissue::index_t(in.nodes.size() / 3);
    b.n_elements = tissue::index_t(in.tets.size() / 4);
    s.nodes.insert(s.nodes.end(), in.nodes.begin(), in.nodes.end());
    for (tissue::index_t v : in.tets) s.tets.push_back(v + b.first_node);
    s.sets.push_back({.name = b.name, .material = "tissue", .all = true, .elements = {}, .line = 0, .body = body});
    sc::Constraint base;
    base.kind = sc::Constraint::Kind::Box;
    base.lo[0] = base.lo[1] = base.lo[2] = -1;
    base.hi[0] = base.hi[1] = 1;
    base.hi[2] = 1e-4;
    base.body = body;
    s.constraints.push_back(base);
    if (alone < 0) s.bodies.push_back(b);
  }
  sc::Tool t;
  t.radius = 4e-3;
  t.path = {{0, {0.025, 0.01, 0.03}}, {1, {0.025, 0.01, 0.03}}};  // parked for a second
  s.tools.push_back(t);
  s.solver.precision = tissue::Precision::Double;
  s.solver.damping = 30;
  s.solver.mass_scaling = 0;
  const std::string path = dir.file(alone < 0 ? "blocks.xml" : alone == 0 ? "left.xml" : "right.xml");
  tissue::io::write_scene(s, path, false);
  return path;
}

/// Presses block k's top centre 1 mm deep over 200 ticks and holds 300;
/// returns the tool force of every tick.
std::vector<tissue::Vector3> press_block(Simulation& sim, int k) {
  std::vector<tissue::Vector3> out;
  for (int t = 1; t <= 500; ++t) {
    const double s = std::min(1.0, t / 200.0);
    sim.set_tool_pose(0, {0.01 + 0.03 * k, 0.01, 0.014 - s * 1e-3});
    out.push_back(sim.step().tools[0].force);
  }
  return out;
}

// A scene of two bodies is each body's scene side by side: pressing one
// gives, tick by tick and bit for bit on the cpu, the force and field of
// that body alone, while the other stays exactly at rest (its region is
// never seeded); the bodies' ranges name the nodes of each.
TEST(Facade, EachOfTwoBodiesPressesAsItDoesAlone) {
  tissue::testing_support::TempDir dir;
  const std::string both = blocks_scene(dir);
  EXPECT_TRUE(std::filesystem::exists(dir.file("blocks-left.node")));
  EXPECT_TRUE(std::filesystem::exists(dir.file("blocks-right.ele")));
  for (int k = 0; k < 2; ++k) {
    Simulation two = Simulation::load(both, {"cpu", "double", "auto"});
    Simulation one = Simulation::load(blocks_scene(dir, k), {"cpu", "double", "auto"});
    EXPECT_TRUE(two.warnings().empty()) << two.warnings().front();
    const std::vector<tissue::BodyRange> bodies = two.bodies();
    ASSERT_EQ(bodies.size(), 2u);
    EXPECT_EQ(bodies[0].name, "left");
    EXPECT_EQ(bodies[1].name, "right");
    EXPECT_EQ(bodies[1].first_node, bodies[0].n_nodes);
    EXPECT_EQ(bodies[1].first_element, bodies[0].n_elements);
    ASSERT_EQ(bodies[k].n_nodes, one.n_nodes());
    ASSERT_EQ(bodies[k].n_elements, one.n_elements());
    ASSERT_EQ(two.steps_per_tick(), one.steps_per_tick());
    ASSERT_EQ(one.bodies().size(), 1u);
    EXPECT_EQ(one.bodies()[0].name, "body");
    EXPECT_TRUE(two.body_contacts().empty());  // two bodies, no <contact bodies>

    const std::vector<tissue::Vector3> f2 = press_block(two, k), f1 = press_block(one, k);
    for (std::size_t t = 0; t < f1.size(); ++t)
      for (int c = 0; c < 3; ++c) ASSERT_EQ(f2[t][c], f1[t][c]) << "body " << k << " tick " << t + 1;
    EXPECT_GT(f1.back()[2], 1e-3) << "the press reached block " << k;
    const std::vector<double> u2 = two.field(tissue::Field::Displacement), u1 = one.field(tissue::Field::Displacement);
    const std::size_t first = 3 * bodies[k].first_node;
    for (std::size_t i = 0; i < u1.size(); ++i) ASSERT_EQ(u2[first + i], u1[i]) << "body " << k << " value " << i;
    const tissue::BodyRange& other = bodies[1 - k];
    for (std::size_t i = 3 * other.first_node; i < 3 * (other.first_node + other.n_nodes); ++i)
      ASSERT_EQ(u2[i], 0.0) << "the untouched body moved, value " << i;
  }
}

// On the GPU the two-body scene presses as on the cpu (the consistency
// tolerance of the backends) and the untouched body stays at rest.
TEST(Facade, CudaRunsTwoBodiesAsTheCpuDoes) {
  const std::vector<std::string> b = tissue::available_backends();
  if (std::find(b.begin(), b.end(), "cuda") == b.end()) GTEST_SKIP() << "no usable cuda backend here";
  tissue::testing_support::TempDir dir;
  const std::string both = blocks_scene(dir);
  Simulation gpu = Simulation::load(both, {"cuda", "double", "auto"});
  Simulation cpu = Simulation::load(both, {"cpu", "double", "auto"});
  const std::vector<tissue::Vector3> fg = press_block(gpu, 1), fc = press_block(cpu, 1);
  double peak = 0, worst = 0;
  for (std::size_t t = 0; t < fc.size(); ++t) {
    peak = std::max(peak, std::hypot(fc[t][0], fc[t][1], fc[t][2]));
    worst = std::max(worst, std::hypot(fg[t][0] - fc[t][0], fg[t][1] - fc[t][1], fg[t][2] - fc[t][2]));
  }
  EXPECT_GT(peak, 1e-3);
  EXPECT_LT(worst, 1e-6 * peak) << "peak " << peak;
  const std::vector<double> u = gpu.field(tissue::Field::Displacement);
  const tissue::BodyRange left = gpu.bodies()[0];
  for (std::size_t i = 0; i < 3 * left.n_nodes; ++i) ASSERT_EQ(u[i], 0.0) << "the untouched body moved, value " << i;
}

// "@kidney-fat" pressed through its layer: each body contact is a surface
// node of one body inside a surface triangle of the other, both ways, as
// deep as the press pushes it; the C interface gives the same contacts, and
// a capacity below their count is refused naming both; the bare kidney, one
// body, has none.
TEST(Facade, BodyContactsAreANodeInsideTheOtherBodysTriangle) {
  Simulation sim = Simulation::load("@kidney-fat", {"cpu", "", ""});
  tissue_simulation* c = nullptr;
  ASSERT_EQ(tissue_open_scene("@kidney-fat", "cpu", nullptr, nullptr, &c), TISSUE_OK) << tissue_last_error();
  EXPECT_TRUE(sim.body_contacts().empty());  // before the first step
  const tissue::ToolResult first = sim.step().tools[0];
  ASSERT_EQ(tissue_step(c, 1), TISSUE_OK);
  for (int k = 1; k <= 24; ++k) {
    const tissue::Vector3 tip = fat_press_tip(first, k);
    sim.set_tool_pose(0, tip);
    sim.step();
    ASSERT_EQ(tissue_set_tool_pose(c, 0, tip.data(), nullptr), TISSUE_OK);
    ASSERT_EQ(tissue_step(c, 1), TISSUE_OK);
  }
  ASSERT_GT(sim.last().tools[0].contact_nodes, 0) << "the probe reached the layer";

  const std::vector<tissue::BodyContact> contacts = sim.body_contacts();
  ASSERT_FALSE(contacts.empty());
  const std::vector<tissue::BodyRange> bodies = sim.bodies();
  ASSERT_EQ(bodies.size(), 2u);
  const auto in = [&](std::int32_t node, int body) {
    return body >= 0 && body < int(bodies.size()) && std::size_t(node) >= bodies[std::size_t(body)].first_node &&
           std::size_t(node) < bodies[std::size_t(body)].first_node + bodies[std::size_t(body)].n_nodes;
  };
  std::set<std::array<std::int32_t, 3>> surface;  // corner ids, sorted
  const std::span<const std::int32_t> tris = sim.surface_triangles();
  for (std::size_t t = 0; t < tris.size(); t += 3) {
    std::array<std::int32_t, 3> v = {tris[t], tris[t + 1], tris[t + 2]};
    std::sort(v.begin(), v.end());
    surface.insert(v);
  }
  int ways[2] = {0, 0};
  double deepest = 0;
  for (std::size_t i = 0; i < contacts.size(); ++i) {
    const tissue::BodyContact& b = contacts[i];
    ASSERT_TRUE(in(b.node, b.body)) << "contact " << i << ": node " << b.node << " body " << b.body;
    ASSERT_NE(b.body, b.other_body) << "contact " << i;
    std::array<std::int32_t, 3> v = b.triangle;
    for (std::int32_t corner : v) ASSERT_TRUE(in(corner, b.other_body)) << "contact " << i << ": corner " << corner;
    std::sort(v.begin(), v.end());
    ASSERT_EQ(surface.count(v), 1u) << "contact " << i << ": not a surface triangle";
    ASSERT_TRUE(std::isfinite(b.depth) && b.depth >= 0) << "contact " << i << ": depth " << b.depth;
    if (i > 0) {
      ASSERT_LT(contacts[i - 1].node, b.node) << "ascending node ids";
    }
    ++ways[b.body];
    deepest = std::max(deepest, b.depth);
  }
  EXPECT_GT(ways[0], 0) << "kidney nodes inside the fat";
  EXPECT_GT(ways[1], 0) << "fat nodes inside the kidney";
  // measured 1.5e-4 m where the probe pinches the layer (at rest, rounding leaves nodes ~3e-9 m inside)
  EXPECT_GT(deepest, 1e-5);

  std::int32_t count = -1;
  ASSERT_EQ(tissue_body_contact_count(c, &count), TISSUE_OK);
  ASSERT_EQ(std::size_t(count), contacts.size());
  const std::size_t n = std::size_t(count);
  std::vector<std::int32_t> nodes(n), corners(3 * n), owners(2 * n);
  std::vector<double> depths(n);
  std::size_t written = 0;
  ASSERT_EQ(tissue_body_contacts(c, nodes.data(), corners.data(), owners.data(), depths.data(), n, &written),
            TISSUE_OK);
  ASSERT_EQ(written, n);
  for (std::size_t i = 0; i < n; ++i) {
    EXPECT_EQ(nodes[i], contacts[i].node) << i;
    for (std::size_t k = 0; k < 3; ++k) EXPECT_EQ(corners[3 * i + k], contacts[i].triangle[k]) << i;
    EXPECT_EQ(owners[2 * i], contacts[i].body) << i;
    EXPECT_EQ(owners[2 * i + 1], contacts[i].other_body) << i;
    EXPECT_EQ(depths[i], contacts[i].depth) << i;
  }
  written = 99;
  EXPECT_EQ(tissue_body_contacts(c, nodes.data(), corners.data(), owners.data(), depths.data(), n - 1, &written),
            TISSUE_BAD_ARGUMENT);
  EXPECT_EQ(written, 0u);
  EXPECT_NE(std::string(tissue_last_error()).find("capacity " + std::to_string(n - 1) + " is below the " +
                                                  std::to_string(n) + " contacts"),
            std::string::npos)
      << tissue_last_error();
  tissue_close(c);

  Simulation kidney = Simulation::load("@kidney", {"cpu", "", ""});
  kidney.step(3);
  EXPECT_TRUE(kidney.body_contacts().empty());
}

// A body that nothing holds is warned about by name.
TEST(Facade, AnUnsupportedBodyIsNamed) {
  tissue::testing_support::TempDir dir;
  tissue::scene::Scene s = tissue::io::read_scene(blocks_scene(dir));
  s.constraints.pop_back();  // the right block's base
  const std::string path = dir.file("loose.xml");
  tissue::io::write_scene(s, path, true);
  const Simulation sim = Simulation::load(path, {"cpu", "double", ""});
  ASSERT_EQ(sim.warnings().size(), 1u);
  EXPECT_NE(sim.warnings()[0].find("(all of body 'right')"), std::string::npos) << sim.warnings()[0];
}

TEST(Facade, ReportsTheVersionAndBackends) {
  EXPECT_EQ(std::string(tissue::version()).substr(0, 4), "0.2.");
  const std::vector<std::string> b = tissue::available_backends();
  ASSERT_FALSE(b.empty());
  EXPECT_EQ(b.front(), "cpu");
}

}  // namespace
