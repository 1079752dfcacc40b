// Tests of the model precomputation (core/model.cpp) on box meshes
// (core/box_mesh.hpp): lumped masses, volumes, node -> element lists, the
// outward surface, the critical time step and every input rule with its
// message, and convert<float>.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "core/box_mesh.hpp"
#include "core/model.hpp"
#include "core/tet.hpp"
#include "tests/sliver.hpp"

namespace tissue {
namespace {

constexpr double kE = 3000.0, kNu = 0.45, kRho = 1000.0;

MaterialParams material(double E, double nu, double rho) {
  return {E / (2 * (1 + nu)), E / (3 * (1 - 2 * nu)), rho};
}

/// A box [0, lx] x [0, ly] x [0, lz] of nx x ny x nz cells with brain-like tissue.
ModelInput box_input(int nx, int ny, int nz, double lx, double ly, double lz) {
  ModelInput in;
  box_mesh(in, nx, ny, nz, lx, ly, lz);
  in.materials = {material(kE, kNu, kRho)};
  in.source = "box";
  return in;
}

/// Calls fn, expects a ModelError whose message contains every one of parts.
void expect_model_error(const std::function<void()>& fn, const std::vector<std::string>& parts) {
  try {
    fn();
    ADD_FAILURE() << "no ModelError thrown; expected a message with '" << parts.front() << "'";
  } catch (const ModelError& e) {
    const std::string msg = e.what();
    for (const auto& p : parts) EXPECT_NE(msg.find(p), std::string::npos) << "'" << p << "' missing from: " << msg;
  }
}

Vec3<double> node_X(const TissueModel<double>& m, index_t i) {
  return {m.X[i], m.X[m.n_nodes + i], m.X[2 * m.n_nodes + i]};
}

// ---------------------------------------------------------------- geometry and mass

TEST(Model, BoxMeshSizesAndVolumes) {
  const int nx = 3, ny = 2, nz = 4;
  const double lx = 0.03, ly = 0.02, lz = 0.025;
  const auto m = build_model(box_input(nx, ny, nz, lx, ly, lz));
  EXPECT_EQ(m.n_nodes, (nx + 1) * (ny + 1) * (nz + 1));
  EXPECT_EQ(m.n_elems, 6 * nx * ny * nz);
  EXPECT_EQ(m.reoriented, 0);
  const double cell = lx / nx * ly / ny * lz / nz;
  double total = 0;
  for (index_t e = 0; e < m.n_elems; ++e) {
    EXPECT_NEAR(m.volume[e], cell / 6, 1e-12 * cell) << "element " << e;  // Kuhn tets are equal
    total += m.volume[e];
  }
  EXPECT_NEAR(total, lx * ly * lz, 1e-12 * lx * ly * lz);
  // node numbering of box_mesh
  const index_t i = box_node(nx, ny, 2, 1, 3);
  EXPECT_NEAR(node_X(m, i).x, 2 * lx / nx, 1e-15);
  EXPECT_NEAR(node_X(m, i).y, 1 * ly / ny, 1e-15);
  EXPECT_NEAR(node_X(m, i).z, 3 * lz / nz, 1e-15);
}

TEST(Model, ShapeGradientsMatchTetMath) {
  const auto m = build_model(box_input(2, 2, 2, 0.02, 0.03, 0.01));
  const index_t ne = m.n_elems;
  for (index_t e = 0; e < ne; ++e) {
    Vec3<double> X[4];
    for (int a = 0; a < 4; ++a) X[a] = node_X(m, m.elem_nodes[a * ne + e]);
    double dN[12];
    EXPECT_NEAR(tet_shape_gradients(X, dN), m.volume[e], 1e-15 * m.volume[e]);
    for (int k = 0; k < 12; ++k) EXPECT_NEAR(m.dndx[k * ne + e], dN[k], 1e-12 * 200) << "element " << e << " k " << k;
  }
}

// Each tet gives rho_e V_e / 4 to each corner; the masses add up to the
// total rho V, here with two materials of different density.
TEST(Model, LumpedMassesTwoMaterials) {
  ModelInput in = box_input(2, 3, 2, 0.02, 0.03, 0.02);
  in.materials.push_back(material(kE, kNu, 2.5 * kRho));
  const index_t ne = static_cast<index_t>(in.tets.size() / 4);
  in.elem_material.resize(ne);
  for (index_t e = 0; e < ne; ++e) in.elem_material[e] = e % 3 == 0 ? 1 : 0;
  const auto m = build_model(in);
  std::vector<double> expect(m.n_nodes, 0.0);
  double total = 0;
  for (index_t e = 0; e < ne; ++e) {
    const double rho = in.materials[in.elem_material[e]].rho;
    total += rho * m.volume[e];
    for (int a = 0; a < 4; ++a) expect[m.elem_nodes[a * ne + e]] += rho * m.volume[e] / 4;
  }
  double sum = 0;
  for (index_t i = 0; i < m.n_nodes; ++i) {
    EXPECT_NEAR(m.mass[i], expect[i], 1e-14 * total) << "node " << i;
    EXPECT_GT(m.mass[i], 0) << "node " << i;
    sum += m.mass[i];
  }
  EXPECT_NEAR(sum, total, 1e-12 * total);
  EXPECT_NEAR(m.total_mass, total, 1e-12 * total);
  // one material: rho times the box volume
  const auto m1 = build_model(box_input(2, 3, 2, 0.02, 0.03, 0.02));
  EXPECT_NEAR(m1.total_mass, kRho * 0.02 * 0.03 * 0.02, 1e-12 * m1.total_mass);
  // per-element materials are copied
  for (index_t e = 0; e < ne; ++e) EXPECT_EQ(m.mu[e], in.materials[in.elem_material[e]].mu);
}

TEST(Model, SingleTetMassIsQuarterEach) {
  ModelInput in;
  in.nodes = {0, 0, 0, 0.01, 0, 0, 0, 0.02, 0, 0, 0, 0.03};
  in.tets = {0, 1, 2, 3};
  in.materials = {material(kE, kNu, kRho)};
  const auto m = build_model(in);
  const double V = 0.01 * 0.02 * 0.03 / 6;
  ASSERT_NEAR(m.volume[0], V, 1e-15 * V);
  for (index_t i = 0; i < 4; ++i) EXPECT_NEAR(m.mass[i], kRho * V / 4, 1e-15 * kRho * V);
}

// ---------------------------------------------------------------- connectivity

TEST(Model, NodeElementListsSortedAndComplete) {
  const auto m = build_model(box_input(3, 2, 2, 0.03, 0.02, 0.02));
  const index_t n = m.n_nodes, ne = m.n_elems;
  ASSERT_EQ(m.node_elem_start.size(), size_t(n + 1));
  EXPECT_EQ(m.node_elem_start.front(), 0);
  EXPECT_EQ(m.node_elem_start.back(), 4 * ne);
  ASSERT_EQ(m.node_elem.size(), size_t(4 * ne));
  std::vector<int> seen(4 * ne, 0);
  for (index_t i = 0; i < n; ++i) {
    EXPECT_LT(m.node_elem_start[i], m.node_elem_start[i + 1]) << "node " << i << " has no element";
    for (index_t k = m.node_elem_start[i]; k < m.node_elem_start[i + 1]; ++k) {
      const index_t entry = m.node_elem[k], e = entry / 4, a = entry % 4;
      ASSERT_EQ(incident_element(entry), e);
      ASSERT_EQ(incident_corner(entry), a);
      ASSERT_EQ(incident_entry(e, int(a)), entry);
      ASSERT_GE(e, 0);
      ASSERT_LT(e, ne);
      EXPECT_EQ(m.elem_nodes[a * ne + e], i) << "entry (" << e << ", " << a << ") listed under node " << i;
      if (k > m.node_elem_start[i]) {
        EXPECT_LT(m.node_elem[k - 1], entry) << "node " << i << " list not ascending";
      }
      ++seen[entry];
    }
  }
  for (index_t entry = 0; entry < 4 * ne; ++entry) EXPECT_EQ(seen[entry], 1) << "(element, corner) " << entry;
  // an interior node of a Kuhn mesh touches 24 tets, a box corner at the origin 1 (the 000 corner) ...
  const index_t interior = box_node(3, 2, 1, 1, 1);
  EXPECT_EQ(m.node_elem_start[interior + 1] - m.node_elem_start[interior], 24);
  const index_t far_corner = box_node(3, 2, 3, 2, 2);  // ... and the 111 corner of the last cell 6
  EXPECT_EQ(m.node_elem_start[far_corner + 1] - m.node_elem_start[far_corner], 6);
}

TEST(Model, SurfaceTrianglesCountAndOrientation) {
  const int nx = 3, ny = 2, nz = 4;
  const double l[3] = {0.03, 0.02, 0.025};
  const auto m = build_model(box_input(nx, ny, nz, l[0], l[1], l[2]));
  EXPECT_EQ(m.n_tris, 4 * (nx * ny + ny * nz + nx * nz));
  ASSERT_EQ(m.tris.size(), size_t(3 * m.n_tris));
  ASSERT_EQ(m.tri_elem.size(), size_t(m.n_tris));
  const Vec3<double> centre = {l[0] / 2, l[1] / 2, l[2] / 2};
  const index_t nt = m.n_tris, ne = m.n_elems;
  double area = 0;
  for (index_t t = 0; t < nt; ++t) {
    const index_t v[3] = {m.tris[t], m.tris[nt + t], m.tris[2 * nt + t]};
    const Vec3<double> p0 = node_X(m, v[0]), p1 = node_X(m, v[1]), p2 = node_X(m, v[2]);
    const Vec3<double> normal = cross(p1 - p0, p2 - p0);
    const Vec3<double> centroid = (1.0 / 3.0) * (p0 + p1 + p2);
    EXPECT_GT(dot(normal, centroid - centre), 0) << "triangle " << t << " points inward";
    area += 0.5 * norm(normal);
    // all three corners lie on one face of the box
    bool on_face = false;
    for (int c = 0; c < 3; ++c)
      for (double side : {0.0, l[c]})
        on_face |= std::fabs(p0[c] - side) < 1e-12 && std::fabs(p1[c] - side) < 1e-12 && std::fabs(p2[c] - side) < 1e-12;
    EXPECT_TRUE(on_face) << "triangle " << t;
    // the owning tet has the triangle's nodes as corners
    const index_t e = m.tri_elem[t];
    for (index_t node : v) {
      bool corner = false;
      for (int a = 0; a < 4; ++a) corner |= m.elem_nodes[a * ne + e] == node;
      EXPECT_TRUE(corner) << "triangle " << t << " node " << node << " not in element " << e;
    }
    for (index_t node : v) EXPECT_TRUE(m.node_flags[node] & kSurface);
  }
  const double box_area = 2 * (l[0] * l[1] + l[1] * l[2] + l[0] * l[2]);
  EXPECT_NEAR(area, box_area, 1e-12 * box_area);
  // interior nodes are not surface nodes
  EXPECT_FALSE(m.node_flags[box_node(nx, ny, 1, 1, 1)] & kSurface);
  EXPECT_FALSE(m.node_flags[box_node(nx, ny, 2, 1, 3)] & kSurface);
}

TEST(Model, FixedFlags) {
  ModelInput in = box_input(2, 2, 2, 0.02, 0.02, 0.02);
  const size_t n = in.nodes.size() / 3;
  in.fixed.assign(n, 0);
  for (int j = 0; j <= 2; ++j)
    for (int i = 0; i <= 2; ++i) in.fixed[box_node(2, 2, i, j, 0)] = 1;
  const auto m = build_model(in);
  int fixed = 0;
  for (index_t i = 0; i < m.n_nodes; ++i) {
    const bool want = node_X(m, i).z == 0.0;
    EXPECT_EQ(bool(m.node_flags[i] & kFixed), want) << "node " << i;
    fixed += want;
  }
  EXPECT_EQ(fixed, 9);
}

// ---------------------------------------------------------------- time step

TEST(Model, CriticalStepOfRegularTet) {
  const double a = 0.01;
  ModelInput in;
  in.nodes = {0, 0, 0, a, 0, 0, a / 2, a * std::sqrt(3.0) / 2, 0, a / 2, a * std::sqrt(3.0) / 6, a * std::sqrt(2.0 / 3.0)};
  in.tets = {0, 1, 2, 3};
  in.materials = {material(kE, kNu, kRho)};
  const auto m = build_model(in);
  // by hand: L = a sqrt(2/3) (every altitude of a regular tet),
  // lambda = K - 2 mu / 3, c = sqrt((lambda + 2 mu) / rho)
  const double mu = kE / (2 * (1 + kNu)), K = kE / (3 * (1 - 2 * kNu));
  const double lambda = K - 2 * mu / 3;
  EXPECT_NEAR(lambda, kE * kNu / ((1 + kNu) * (1 - 2 * kNu)), 1e-9 * lambda);
  const double c = std::sqrt((lambda + 2 * mu) / kRho);
  const double expect = a * std::sqrt(2.0 / 3.0) / c;
  EXPECT_NEAR(m.dt_crit, expect, 1e-12 * expect);
  EXPECT_EQ(m.dt_crit_elem, 0);
  EXPECT_NEAR(m.dt, 0.5 * expect, 1e-12 * expect);  // default safety 0.5
}

TEST(Model, SquashedTetSetsCriticalStep) {
  const int n = 2;
  const double s = 0.01, h = 0.05 * s;  // cell size, apex height of the squashed tet
  ModelInput in = box_input(n, n, n, n * s, n * s, n * s);
  // a flat tet on the top-face triangle (0,0,top)-(1,0,top)-(1,1,top), apex h above its centroid
  const index_t a = box_node(n, n, 0, 0, n), b = box_node(n, n, 1, 0, n), c = box_node(n, n, 1, 1, n);
  const index_t apex = static_cast<index_t>(in.nodes.size() / 3);
  in.nodes.insert(in.nodes.end(), {2 * s / 3, s / 3, n * s + h});
  in.tets.insert(in.tets.end(), {a, b, c, apex});
  const auto m = build_model(in);
  const index_t squashed = 6 * n * n * n;
  EXPECT_EQ(m.dt_crit_elem, squashed);
  const MaterialParams p = material(kE, kNu, kRho);
  const double wave = std::sqrt((p.K + 4 * p.mu / 3) / p.rho);
  // the base (area s^2/2) is the largest face, so L = h
  EXPECT_NEAR(m.dt_crit, h / wave, 1e-9 * h / wave);
  // without it, a Kuhn tet of cell s sets the step: L = s / sqrt(2)
  const auto plain = build_model(box_input(n, n, n, n * s, n * s, n * s));
  EXPECT_NEAR(plain.dt_crit, s / std::sqrt(2.0) / wave, 1e-12 * plain.dt_crit);
}

/// The 2 x 2 x 2 box with a flat tet (apex 5 % of a cell above the top face)
/// that sets the critical step 14x below the Kuhn tets'.
ModelInput box_with_flat_tet() {
  const int n = 2;
  const double s = 0.01, h = 0.05 * s;
  ModelInput in = box_input(n, n, n, n * s, n * s, n * s);
  const index_t apex = static_cast<index_t>(in.nodes.size() / 3);
  in.nodes.insert(in.nodes.end(), {2 * s / 3, s / 3, n * s + h});
  in.tets.insert(in.tets.end(), {box_node(n, n, 0, 0, n), box_node(n, n, 1, 0, n), box_node(n, n, 1, 1, n), apex});
  return in;
}

TEST(Model, TimeStepAboveCriticalIsRefused) {
  ModelInput in = box_with_flat_tet();
  const auto ok = build_model(in);
  const double dt_crit = ok.dt_crit;
  in.dt = 1.01 * dt_crit;
  const std::string limit = fmt::format("{:.6g}", dt_crit);
  expect_model_error([&] { build_model(in); }, {"box", "dt_crit", limit, "element 48"});
  in.dt = dt_crit;  // the limit itself is accepted
  EXPECT_NO_THROW(build_model(in));
  // set_time_step refuses too and leaves the model as it was
  auto m = ok;
  expect_model_error([&] { set_time_step(m, 2 * dt_crit, 0.0); }, {"dt_crit", limit, "element 48"});
  EXPECT_EQ(m.dt, ok.dt);
  expect_model_error([&] { set_time_step(m, -1e-4, 0.0); }, {"dt", "> 0"});
  expect_model_error([&] { set_time_step(m, 0.5 * dt_crit, -1.0); }, {"damping"});
  set_time_step(m, 0.25 * dt_crit, 3.0);
  EXPECT_EQ(m.dt, 0.25 * dt_crit);
  EXPECT_EQ(m.damping, 3.0);
  const auto k = central_difference_constants(m.mass[0], m.dt, 3.0);
  EXPECT_DOUBLE_EQ(m.cd_A[0], k.A);
  EXPECT_DOUBLE_EQ(m.cd_B[0], k.B);
  EXPECT_DOUBLE_EQ(m.cd_C[0], k.C);
}

// ---------------------------------------------------------------- mass scaling

// choose_mass_scaling on hand-made elements: three of 1 kg each, element
// steps 10, 40 and 100 us, tick 1 ms, safety 0.5. Without scaling dt = 5 us
// (200 steps). n steps need every dt_e >= 2 ms / n: n = 50 (40 us) costs
// (40/10)^2 - 1 = 15 kg on the first element, n = 25 (80 us) costs 63 + 3 kg.
TEST(MassScaling, ChoosesTheFewestStepsWithinTheBudget) {
  const std::vector<double> dt_e = {10e-6, 40e-6, 100e-6}, rho_V = {1, 1, 1};
  MassScaling r = choose_mass_scaling(dt_e, rho_V, 1e-3, 0.5, 0.0);
  EXPECT_EQ(r.steps, 200);  // no budget: no mass, the unscaled step count
  EXPECT_EQ(r.added_mass, 0);
  EXPECT_EQ(r.scaled_elems, 0);
  r = choose_mass_scaling(dt_e, rho_V, 1e-3, 0.5, 15.0 / 3);  // 15 kg allowed
  EXPECT_EQ(r.steps, 50);
  EXPECT_NEAR(r.dt, 20e-6, 1e-18);
  EXPECT_NEAR(r.need, 40e-6, 1e-18);
  EXPECT_NEAR(r.added_mass, 15.0, 1e-9);
  EXPECT_EQ(r.scaled_elems, 1);
  EXPECT_NEAR(r.max_scale, 16.0, 1e-9);
  r = choose_mass_scaling(dt_e, rho_V, 1e-3, 0.5, 66.0 / 3 + 1e-9);
  EXPECT_EQ(r.steps, 25);
  EXPECT_NEAR(r.added_mass, 66.0, 1e-9);
  EXPECT_EQ(r.scaled_elems, 2);
}

TEST(MassScaling, LiftsTheFlatTetAndAddsMassOnlyToItsCorners) {
  ModelInput in = box_with_flat_tet();
  in.dt_safety = 0.9;
  const TissueModel<double> plain = build_model(in);
  in.tick = 1e-3;
  in.mass_scaling = 0.01;
  const TissueModel<double> m = build_model(in);
  const index_t flat = m.n_elems - 1;
  EXPECT_EQ(m.scaled_elems, 1);
  EXPECT_GT(m.added_mass, 0);
  EXPECT_LE(m.added_mass, 0.01 * m.total_mass);
  EXPECT_DOUBLE_EQ(m.total_mass, plain.total_mass);  // the physical mass
  EXPECT_DOUBLE_EQ(m.dt_crit_physical, plain.dt_crit);
  EXPECT_GT(m.dt_crit, 2 * plain.dt_crit);  // 1 % buys 3 steps per tick instead of 8
  // whole steps per tick, and dt = safety x the lifted limit at most
  const double steps = 1e-3 / m.dt;
  EXPECT_NEAR(steps, std::round(steps), 1e-9);
  EXPECT_LE(m.dt, 0.9 * m.dt_crit * (1 + 1e-12));
  EXPECT_LE(2 * std::round(steps), std::ceil(1e-3 / plain.dt));
  // the flat tet's four corners carry the added mass, in equal parts
  double sum = 0;
  for (index_t a = 0; a < m.n_nodes; ++a) {
    sum += m.mass[a];
    bool corner = false;
    for (int k = 0; k < 4; ++k) corner = corner || m.elem_nodes[k * m.n_elems + flat] == a;
    if (corner)
      EXPECT_NEAR(m.mass[a] - plain.mass[a], m.added_mass / 4, 1e-12 * m.added_mass) << "node " << a;
    else
      EXPECT_EQ(m.mass[a], plain.mass[a]) << "node " << a;
  }
  EXPECT_NEAR(sum, m.total_mass + m.added_mass, 1e-12 * sum);
  // the assembled system's step: the apex alone along the face's normal has
  // omega^2 = K_nn / m_apex with K_nn = V (lambda + 2 mu) / h^2 and m_apex =
  // rho_s V / 4, a step 2 / omega = h / c_s = the scaled L_e / c_e (dt_crit);
  // coupled to the face's corners the top mode is a little faster, and the
  // model's dt = 0.9 of dt_crit is within 0.95 of it, so no mass is added
  ::testing::Test::RecordProperty("assembled_step_over_dt_crit", std::to_string(m.assembled_step / m.dt_crit));
  EXPECT_LE(m.assembled_step, m.dt_crit * (1 + 1e-6));
  EXPECT_GE(m.assembled_step, m.dt / 0.95);
  EXPECT_EQ(m.assembled_nodes, 0);
  // a budget too small for one step less leaves the model as it was
  in.mass_scaling = 1e-12;
  const TissueModel<double> same = build_model(in);
  EXPECT_EQ(same.scaled_elems, 0);
  EXPECT_EQ(same.mass, plain.mass);
}

TEST(MassScaling, BadBudgetsAndUnreachableStepsAreNamed) {
  ModelInput in = box_with_flat_tet();
  in.tick = 1e-3;
  for (double bad : {-0.1, 1.0, 2.0}) {
    in.mass_scaling = bad;
    expect_model_error([&] { build_model(in); }, {"box", "mass scaling budget", "[0, 1)"});
  }
  in.mass_scaling = 0.01;
  in.tick = 0;
  expect_model_error([&] { build_model(in); }, {"box", "mass scaling needs a haptic tick"});
  // an explicit dt the budget cannot reach: the limit, the element and the mass it would take
  const TissueModel<double> plain = build_model(box_with_flat_tet());
  in.dt = 0.5 * 1e-3;
  expect_model_error([&] { build_model(in); },
                     {"box", "above the stable limit", fmt::format("element {}", plain.dt_crit_elem), "added mass",
                      "budget 1 %"});
  // one it can (0.4 % added): accepted, every element lifted to dt / safety
  in.dt = 2 * plain.dt_crit;
  in.dt_safety = 0.9;
  const TissueModel<double> m = build_model(in);
  EXPECT_EQ(m.dt, in.dt);
  EXPECT_NEAR(m.dt_crit, in.dt / 0.9, 1e-12 * m.dt_crit);
}

TEST(Model, SafetyFactorAndDefaultDamping) {
  ModelInput in = box_input(2, 2, 3, 0.02, 0.02, 0.04);
  in.dt_safety = 0.8;
  const auto m = build_model(in);
  EXPECT_NEAR(m.dt, 0.8 * m.dt_crit, 1e-15 * m.dt_crit);
  // default alpha = 2 omega, omega = (pi/2) sqrt(mu/rho) / L_max
  const double mu = material(kE, kNu, kRho).mu;
  const double omega = 0.5 * M_PI * std::sqrt(mu / kRho) / 0.04;
  EXPECT_NEAR(lowest_mode_estimate(m), omega, 1e-12 * omega);
  EXPECT_NEAR(m.damping, 2 * omega, 1e-12 * omega);
  for (double bad : {0.0, 1.0, 1.5, -0.2}) {
    in.dt_safety = bad;
    expect_model_error([&] { build_model(in); }, {"box", "safety"});
  }
  in.dt_safety = 0.5;
  in.damping = 0;
  EXPECT_EQ(build_model(in).damping, 0.0);
}

// ---------------------------------------------------------------- bad input

TEST(ModelErrors, ZeroVolumeTetNamesElement) {
  ModelInput in = box_input(2, 2, 2, 0.02, 0.02, 0.02);
  // four coplanar nodes of the bottom face
  in.tets.insert(in.tets.end(), {box_node(2, 2, 0, 0, 0), box_node(2, 2, 1, 0, 0), box_node(2, 2, 0, 1, 0),
                                 box_node(2, 2, 1, 1, 0)});
  expect_model_error([&] { build_model(in); }, {"box", "element 48", "zero volume"});
  // a repeated node
  in.tets.resize(in.tets.size() - 4);
  in.tets.insert(in.tets.end(), {0, 1, 1, 4});
  expect_model_error([&] { build_model(in); }, {"box", "element 48", "node 1", "twice"});
}

// A tet listed twice (any corner order, inverted or not) would double the
// mass and stiffness there: both element ids and the shared nodes are named.
TEST(ModelErrors, DuplicatedTetNamesBothElements) {
  ModelInput in = box_input(2, 2, 2, 0.02, 0.02, 0.02);
  const index_t e = 17, ne = index_t(in.tets.size() / 4);
  std::vector<index_t> corners(in.tets.begin() + 4 * e, in.tets.begin() + 4 * e + 4);
  std::sort(corners.begin(), corners.end());
  in.tets.insert(in.tets.end(), {in.tets[4 * e + 3], in.tets[4 * e + 1], in.tets[4 * e + 0], in.tets[4 * e + 2]});
  expect_model_error([&] { build_model(in); },
                     {"box", fmt::format("elements {} and {}", e, ne), "same four nodes",
                      fmt::format("({} {} {} {})", corners[0], corners[1], corners[2], corners[3]), "remove one"});
}

// The flat-tet test is relative to each tet's own size: a mesh scaled by
// 1e-40 or 1e40 builds the same model; coordinates whose volumes leave
// the range of a double are named as that, never as a contradicting "zero
// volume 1e+300 m^3".
TEST(ModelErrors, VolumeTestIsScaleFreeAndNamesOverflow) {
  const ModelInput ref_in = box_input(2, 2, 2, 0.02, 0.02, 0.02);
  const TissueModel<double> ref = build_model(ref_in);
  for (double scale : {1e-40, 1e40}) {
    ModelInput in = ref_in;
    for (double& x : in.nodes) x *= scale;
    const TissueModel<double> m = build_model(in);
    EXPECT_EQ(m.n_elems, ref.n_elems) << scale;
    EXPECT_NEAR(m.volume[0] / (scale * scale * scale), ref.volume[0], 1e-12 * ref.volume[0]) << scale;
  }
  ModelInput big = ref_in;
  for (double& x : big.nodes) x *= 1e80;
  expect_model_error([&] { build_model(big); }, {"box", "element 0", "overflows a double", "metres"});
  ModelInput tiny = ref_in;
  for (double& x : tiny.nodes) x *= 1e-80;
  expect_model_error([&] { build_model(tiny); }, {"box", "element 0", "underflows a double", "metres"});
  // a flat tet far from the origin is still named as flat, with its ratio
  ModelInput flat = box_input(2, 2, 2, 0.02, 0.02, 0.02);
  for (double& x : flat.nodes) x += 1e3;
  // three corners on the box's x edge: a flat tet
  flat.tets.insert(flat.tets.end(), {box_node(2, 2, 0, 0, 0), box_node(2, 2, 1, 0, 0), box_node(2, 2, 2, 0, 0),
                                     box_node(2, 2, 0, 1, 0)});
  expect_model_error([&] { build_model(flat); }, {"box", "zero volume", "longest edge", "flat tet"});
}

// A modulus or density far outside tissue's range makes the stable step so
// small that one tick would need more steps than any run can take: the
// message names the element, the material and its wave speed, not a dt the
// user never set.
TEST(ModelErrors, ExtremeMaterialNamesTheCauseOfTheStepLimit) {
  ModelInput in = box_input(2, 1, 1, 0.02, 0.01, 0.01);
  in.materials = {material(1e30, kNu, kRho)};
  in.material_names = {"capsule"};
  in.tick = 1e-3;
  in.dt_safety = 0.9;
  for (double budget : {0.0, 0.025}) {
    in.mass_scaling = budget;
    expect_model_error([&] { build_model(in); },
                       {"box", "material 'capsule'", "mu = 3.448e+29 Pa", "rho = 1000 kg/m^3", "wave speed",
                        "TLED steps", "far too high", "Pa, kg/m^3"});
  }
  in.materials = {material(kE, kNu, 1e-30)};
  expect_model_error([&] { build_model(in); }, {"box", "material 'capsule'", "rho = 1e-30 kg/m^3", "wave speed"});
  // an absurd safety factor on a sound material is named as the cause
  in.materials = {material(kE, kNu, kRho)};
  in.dt_safety = 1e-300;
  expect_model_error([&] { build_model(in); }, {"box", "dt safety factor 1e-300", "TLED steps", "about 0.9"});
  in.dt_safety = 0.9;
  // a sound material in a body far too small for an organ: the size and its unit are named, not the material
  ModelInput tiny = box_input(2, 1, 1, 0.02e-40, 0.01e-40, 0.01e-40);
  tiny.materials = {material(kE, kNu, kRho)};
  tiny.material_names = {"capsule"};
  tiny.tick = 1e-3;
  tiny.dt_safety = 0.9;
  expect_model_error([&] { build_model(tiny); },
                     {"box", "element", "in a body 2e-42 m across", "soft tissue's", "check its unit", "metres"});
  in.materials = {material(kE, kNu, 1e-30)};
  // without a tick (a model built for a relaxation) no such limit applies
  in.tick = 0;
  in.mass_scaling = 0;
  EXPECT_NO_THROW(build_model(in));
}

/// The wave speed a message prints and the moduli it prints it from, "c =
/// sqrt((K + 4 mu / 3 [+ 4 eta]) / rho) = sqrt((K Pa + 4 x mu Pa / 3 [+ 4 x
/// eta Pa]) / rho kg/m^3) = c m/s": success when c follows from them (to the
/// 4 digits printed).
testing::AssertionResult speed_follows_from_the_moduli(const std::string& msg) {
  size_t at = msg.find("/ rho) = sqrt((");  // the numbers follow the formula
  if (at == std::string::npos) return testing::AssertionFailure() << "no sqrt((...)) in: " << msg;
  at += 7;
  double K = 0, mu = 0, eta = 0, rho = 0, c = 0;
  const char* p = msg.c_str() + at;
  if (std::sscanf(p, "= sqrt((%lf Pa + 4 x %lf Pa / 3 + 4 x %lf Pa) / %lf kg/m^3) = %lf m/s", &K, &mu, &eta, &rho,
                  &c) != 5) {
    eta = 0;
    if (std::sscanf(p, "= sqrt((%lf Pa + 4 x %lf Pa / 3) / %lf kg/m^3) = %lf m/s", &K, &mu, &rho, &c) != 4)
      return testing::AssertionFailure() << "cannot read the moduli in: " << msg;
  }
  const double want = std::sqrt((K + 4 * mu / 3 + 4 * eta) / rho);
  if (std::fabs(c - want) > 1e-3 * want)
    return testing::AssertionFailure() << "c = " << c << " but the moduli give " << want << ": " << msg;
  return testing::AssertionSuccess();
}

// A fibre stiffness far beyond the matrix's set the step; the refusal
// printed mu, K and rho but a speed that included the fibre's share: the
// numbers printed now give the speed printed.
TEST(ModelErrors, FibreStiffnessRefusalPrintsTheModuliOfItsSpeed) {
  ModelInput in = box_input(2, 1, 1, 0.02, 0.01, 0.01);
  in.materials = {material(kE, kNu, kRho)};
  in.materials[0].fibre_eta = 1e25;
  in.material_names = {"muscle"};
  in.tick = 1e-3;
  in.dt_safety = 0.9;
  try {
    build_model(in);
    FAIL() << "a fibre of 1e25 Pa was accepted";
  } catch (const ModelError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("fibre stiffness eta = 1e+25 Pa"), std::string::npos) << msg;
    EXPECT_NE(msg.find("c = sqrt((K + 4 mu / 3 + 4 eta) / rho)"), std::string::npos) << msg;
    EXPECT_NE(msg.find("The fibre stiffness is far too high"), std::string::npos) << msg;
    EXPECT_TRUE(speed_follows_from_the_moduli(msg));
  }
  in.materials[0].fibre_eta = 0;  // the isotropic refusal's numbers too
  in.materials[0].rho = 1e-30;
  try {
    build_model(in);
    FAIL() << "a density of 1e-30 was accepted";
  } catch (const ModelError& e) {
    EXPECT_NE(std::string(e.what()).find("The modulus is far too high"), std::string::npos) << e.what();
    EXPECT_TRUE(speed_follows_from_the_moduli(e.what()));
  }
}

TEST(ModelErrors, InvertedTetsAreReorientedAndCounted) {
  const ModelInput good = box_input(2, 2, 2, 0.02, 0.02, 0.02);
  const auto ref = build_model(good);
  ModelInput in = good;
  const index_t flipped[] = {3, 10, 17, 40};
  for (index_t e : flipped) std::swap(in.tets[4 * e + 1], in.tets[4 * e + 2]);
  const auto m = build_model(in);
  EXPECT_EQ(m.reoriented, 4);
  // swapping corners 1 and 2 back restores the original element exactly
  EXPECT_EQ(m.elem_nodes, ref.elem_nodes);
  EXPECT_EQ(m.volume, ref.volume);
  EXPECT_EQ(m.dndx, ref.dndx);
  EXPECT_EQ(m.mass, ref.mass);
  // another inversion (corners 0 and 3): positive volume, consistent gradients
  ModelInput in2 = good;
  std::swap(in2.tets[4 * 5 + 0], in2.tets[4 * 5 + 3]);
  const auto m2 = build_model(in2);
  EXPECT_EQ(m2.reoriented, 1);
  const index_t ne = m2.n_elems;
  Vec3<double> X[4];
  for (int a = 0; a < 4; ++a) X[a] = node_X(m2, m2.elem_nodes[a * ne + 5]);
  double dN[12];
  EXPECT_NEAR(tet_shape_gradients(X, dN), ref.volume[5], 1e-15);
  for (int k = 0; k < 12; ++k) EXPECT_DOUBLE_EQ(m2.dndx[k * ne + 5], dN[k]);
  EXPECT_EQ(m2.n_tris, ref.n_tris);
}

TEST(ModelErrors, UnusedNodeNamed) {
  ModelInput in = box_input(2, 2, 2, 0.02, 0.02, 0.02);
  in.nodes.insert(in.nodes.end(), {0.05, 0.05, 0.05});
  expect_model_error([&] { build_model(in); }, {"box", "node 27", "no element"});
}

TEST(ModelErrors, BadConnectivityAndCoordinates) {
  ModelInput in = box_input(1, 1, 1, 0.01, 0.01, 0.01);
  in.tets[4 * 2 + 3] = 99;
  expect_model_error([&] { build_model(in); }, {"box", "element 2", "node 99"});
  in.tets[4 * 2 + 3] = -1;
  expect_model_error([&] { build_model(in); }, {"box", "element 2", "node -1"});
  in = box_input(1, 1, 1, 0.01, 0.01, 0.01);
  in.nodes[3 * 5 + 1] = std::numeric_limits<double>::quiet_NaN();
  expect_model_error([&] { build_model(in); }, {"box", "node 5", "not finite"});
  in = box_input(1, 1, 1, 0.01, 0.01, 0.01);
  in.tets.pop_back();
  expect_model_error([&] { build_model(in); }, {"box", "multiple of 4"});
  in = box_input(1, 1, 1, 0.01, 0.01, 0.01);
  in.fixed.assign(3, 1);
  expect_model_error([&] { build_model(in); }, {"box", "fixed"});
}

TEST(ModelErrors, BadMaterialsNamed) {
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  struct Case {
    MaterialParams p;
    const char* what;
  };
  const MaterialParams ok = material(kE, kNu, kRho);
  const Case cases[] = {{{0, ok.K, ok.rho}, "shear modulus"},   {{-5, ok.K, ok.rho}, "shear modulus"},
                        {{nan, ok.K, ok.rho}, "shear modulus"}, {{ok.mu, 0, ok.rho}, "bulk modulus"},
                        {{ok.mu, -1, ok.rho}, "bulk modulus"},  {{ok.mu, inf, ok.rho}, "bulk modulus"},
                        {{ok.mu, ok.K, 0}, "density"},          {{ok.mu, ok.K, -kRho}, "density"},
                        {{ok.mu, ok.K, nan}, "density"}};
  for (const Case& c : cases) {
    ModelInput in = box_input(1, 1, 1, 0.01, 0.01, 0.01);
    in.materials = {ok, c.p};
    in.elem_material.assign(6, 1);
    SCOPED_TRACE(c.what);
    expect_model_error([&] { build_model(in); }, {"box", "material 1", c.what});
  }
  ModelInput in = box_input(1, 1, 1, 0.01, 0.01, 0.01);
  in.materials.clear();
  expect_model_error([&] { build_model(in); }, {"box", "no material"});
  in = box_input(1, 1, 1, 0.01, 0.01, 0.01);
  in.elem_material = {0, 0, 0, 5, 0, 0};
  expect_model_error([&] { build_model(in); }, {"box", "element 3", "material index 5"});
  in.elem_material = {0, 0};
  expect_model_error([&] { build_model(in); }, {"box", "material ids"});
}

// ---------------------------------------------------------------- per-element fibre directions

/// A 2 x 1 x 1 box: material 0 (fibres, eta = 5000 Pa along z) for the
/// elements of the cell x < 0.01, material 1 (Neo-Hookean) for the others.
ModelInput fibre_box() {
  ModelInput in = box_input(2, 1, 1, 0.02, 0.01, 0.01);
  MaterialParams fibre = material(kE, kNu, kRho);
  fibre.fibre_eta = 5000;
  fibre.fibre_dir = {0, 0, 1};
  in.materials = {fibre, material(kE, kNu, kRho)};
  in.material_names = {"muscle", "fat"};
  in.elem_material.assign(12, 0);
  for (index_t e = 0; e < 12; ++e) {
    double cx = 0;
    for (int a = 0; a < 4; ++a) cx += in.nodes[3 * in.tets[4 * e + a]] / 4;
    in.elem_material[e] = cx < 0.01 ? 0 : 1;
  }
  return in;
}

TEST(Model, PerElementFibreDirectionsAreNormalisedInTheFibreElementsOnly) {
  ModelInput in = fibre_box();
  // without fibre_dirs: the material's direction in every fibre element
  TissueModel<double> m = build_model(in);
  ASSERT_EQ(m.fibre.size(), 4u * 12);
  for (index_t e = 0; e < 12; ++e) {
    const bool fibre = in.elem_material[e] == 0;
    EXPECT_EQ(m.fibre[2 * 12 + e], fibre ? 1.0 : 0.0) << e;
    EXPECT_EQ(m.fibre[3 * 12 + e], fibre ? 5000.0 : 0.0) << e;
  }
  // with them: element e's own direction, of length e + 1, normalised; the
  // Neo-Hookean elements keep eta = 0 whatever their entry (here zero)
  in.fibre_dirs.assign(3 * 12, 0.0);
  for (index_t e = 0; e < 12; ++e)
    if (in.elem_material[e] == 0) {
      const double t = 0.3 * e, len = e + 1.0;
      in.fibre_dirs[3 * e] = len * std::cos(t);
      in.fibre_dirs[3 * e + 1] = len * std::sin(t);
      in.fibre_dirs[3 * e + 2] = 0;
    }
  m = build_model(in);
  int fibres = 0;
  for (index_t e = 0; e < 12; ++e) {
    if (in.elem_material[e] != 0) {
      for (int c = 0; c < 4; ++c) EXPECT_EQ(m.fibre[c * 12 + e], 0.0) << e;
      continue;
    }
    ++fibres;
    EXPECT_NEAR(m.fibre[0 * 12 + e], std::cos(0.3 * e), 1e-15) << e;
    EXPECT_NEAR(m.fibre[1 * 12 + e], std::sin(0.3 * e), 1e-15) << e;
    EXPECT_EQ(m.fibre[2 * 12 + e], 0.0) << e;
    EXPECT_EQ(m.fibre[3 * 12 + e], 5000.0) << e;
  }
  EXPECT_EQ(fibres, 6);
}

TEST(ModelErrors, BadPerElementFibreDirectionsNamed) {
  ModelInput in = fibre_box();
  in.fibre_dirs.assign(3 * 11, 1.0);
  expect_model_error([&] { build_model(in); }, {"box: ", "33 fibre direction components for 12 elements", "36"});
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  index_t first = 0;
  while (in.elem_material[first] != 0) ++first;
  for (const Vec3<double> bad : {Vec3<double>{0, 0, 0}, Vec3<double>{nan, 1, 0}, Vec3<double>{1, inf, 0}}) {
    in.fibre_dirs.assign(3 * 12, 1.0);
    for (int c = 0; c < 3; ++c) in.fibre_dirs[3 * first + c] = bad[c];
    SCOPED_TRACE(fmt::format("{} {} {}", bad.x, bad.y, bad.z));
    expect_model_error([&] { build_model(in); },
                       {"box: ", fmt::format("element {} (material 'muscle', fibre stiffness 5000 Pa)", first),
                        fmt::format("fibre direction ({}, {}, {}) must be finite and non-zero", bad.x, bad.y, bad.z)});
  }
  // a zero entry of an element without fibres is not used, so not an error
  in.fibre_dirs.assign(3 * 12, 1.0);
  index_t plain = 0;
  while (in.elem_material[plain] != 1) ++plain;
  for (int c = 0; c < 3; ++c) in.fibre_dirs[3 * plain + c] = 0;
  EXPECT_NO_THROW(build_model(in));
}

// ---------------------------------------------------------------- conversion

TEST(Model, ConvertFloatKeepsSizesAndValues) {
  const auto m = build_model(box_input(3, 2, 2, 0.03, 0.02, 0.02));
  const auto f = convert<float>(m);
  EXPECT_EQ(f.n_nodes, m.n_nodes);
  EXPECT_EQ(f.n_elems, m.n_elems);
  EXPECT_EQ(f.n_tris, m.n_tris);
  EXPECT_EQ(f.X.size(), m.X.size());
  EXPECT_EQ(f.dndx.size(), m.dndx.size());
  EXPECT_EQ(f.volume.size(), m.volume.size());
  EXPECT_EQ(f.mass.size(), m.mass.size());
  EXPECT_EQ(f.cd_A.size(), m.cd_A.size());
  EXPECT_EQ(f.cd_B.size(), m.cd_B.size());
  EXPECT_EQ(f.cd_C.size(), m.cd_C.size());
  EXPECT_EQ(f.mu.size(), m.mu.size());
  EXPECT_EQ(f.K.size(), m.K.size());
  EXPECT_EQ(f.elem_nodes, m.elem_nodes);
  EXPECT_EQ(f.node_elem_start, m.node_elem_start);
  EXPECT_EQ(f.node_elem, m.node_elem);
  EXPECT_EQ(f.tris, m.tris);
  EXPECT_EQ(f.tri_elem, m.tri_elem);
  EXPECT_EQ(f.node_flags, m.node_flags);
  EXPECT_EQ(f.dt, m.dt);
  EXPECT_EQ(f.dt_crit, m.dt_crit);
  EXPECT_EQ(f.dt_crit_elem, m.dt_crit_elem);
  EXPECT_EQ(f.damping, m.damping);
  EXPECT_EQ(f.ianp, m.ianp);
  for (size_t k = 0; k < m.dndx.size(); ++k) EXPECT_NEAR(f.dndx[k], m.dndx[k], 1e-6 * std::fabs(m.dndx[k]));
  for (size_t k = 0; k < m.cd_A.size(); ++k) EXPECT_NEAR(f.cd_A[k], m.cd_A[k], 1e-6 * m.cd_A[k]);
  const auto d = convert<double>(m);
  EXPECT_EQ(d.X, m.X);
  EXPECT_EQ(d.mass, m.mass);
}

/// The shape gradients recomputed at a precision as the cuda backend's
/// CudaGradients::Recomputed does (core worst_gradient_deviation: in float
/// from the reference grid, tet_shape_gradients_on_grid; in double from the
/// double positions, tet_shape_gradients_from) on a box of 1 mm cells placed
/// 0.1-0.12 m from the origin. Edges differenced exactly and then rounded to
/// float stay within a few 1e-7 of the double gradients; float copies of the
/// absolute coordinates (the alternative not taken) carry their rounding of
/// 0.1 m into every millimetre edge, ten times more. In double the
/// recomputation is the model's own to rounding.
TEST(Model, GradientsRecomputedFromExactEdgesStayNearTheModels) {
  ModelInput in = box_input(6, 6, 6, 0.006, 0.006, 0.006);
  for (size_t i = 0; i < in.nodes.size(); ++i) in.nodes[i] += 0.1 + 0.01 * double(i % 3);
  const TissueModel<double> m = build_model(in);
  const GradientDeviation dev_float = worst_gradient_deviation(m, Precision::Float);
  const double dev_double = worst_gradient_deviation(m, Precision::Double).deviation;
  const index_t ne = m.n_elems;
  double naive = 0;  // float absolute coordinates
  for (index_t e = 0; e < ne; ++e) {
    Vec3<float> X[4];
    for (int a = 0; a < 4; ++a) {
      const Vec3<double> x = node_X(m, m.elem_nodes[a * ne + e]);
      X[a] = {float(x.x), float(x.y), float(x.z)};
    }
    float dN[12] = {};
    tet_shape_gradients(X, dN);
    double scale = 0, worst = 0;
    for (int k = 0; k < 12; ++k) {
      scale = std::max(scale, std::fabs(m.dndx[k * ne + e]));
      worst = std::max(worst, std::fabs(double(dN[k]) - m.dndx[k * ne + e]));
    }
    naive = std::max(naive, worst / scale);
  }
  std::printf("[measured] worst gradient deviation: float %.3g (float absolute coordinates %.3g), double %.3g\n",
              dev_float.deviation, naive, dev_double);
  EXPECT_GT(dev_float.deviation, 0.0);
  EXPECT_LT(dev_float.deviation, 1e-6);
  EXPECT_GE(dev_float.elem, 0);
  EXPECT_GT(naive, 10 * dev_float.deviation);
  EXPECT_LT(dev_double, 1e-13);
}

/// The reference grid (core reference_grid): its step is a power of two,
/// the smallest that spans the mesh's widest extent in fewer than 2^31
/// steps; every node lies within half a step of its grid point, whose
/// coordinates are non-negative 32-bit integers. Checked on three meshes:
/// millimetre cells 0.1 m from the origin, a 2 m box around it and a
/// 20-micrometre box.
TEST(Model, ReferenceGridHoldsEveryNodeWithinHalfAStep) {
  struct Case {
    double cell, offset;
  };
  for (const Case c : {Case{0.001, 0.1}, Case{0.4, -1.0}, Case{4e-6, 0.0}}) {
    ModelInput in = box_input(5, 4, 3, 5 * c.cell, 4 * c.cell, 3 * c.cell);
    for (size_t i = 0; i < in.nodes.size(); ++i) in.nodes[i] += c.offset + 0.3 * c.cell * double(i % 3);
    const TissueModel<double> m = build_model(in);
    const ReferenceGrid g = reference_grid(m);
    int exponent = 0;
    EXPECT_EQ(std::frexp(g.step, &exponent), 0.5) << "a power of two: " << g.step;
    double widest = 0;
    std::int64_t most = 0;
    for (index_t a = 0; a < m.n_nodes; ++a) {
      const GridPoint q = grid_point(g, m, a);
      const Vec3<double> x = reference_position(m, a);
      const std::int64_t qs[3] = {q.x, q.y, q.z};
      const double xs[3] = {x.x, x.y, x.z}, os[3] = {g.origin.x, g.origin.y, g.origin.z};
      for (int k = 0; k < 3; ++k) {
        EXPECT_GE(qs[k], 0);
        EXPECT_LE(std::fabs(os[k] + double(qs[k]) * g.step - xs[k]),
                  0.5 * g.step * (1 + 1e-9) + 1e-12 * std::fabs(xs[k]));
        most = std::max(most, qs[k]);
        widest = std::max(widest, xs[k] - os[k]);
      }
    }
    EXPECT_LE(double(most), kMaxGridSteps);
    EXPECT_LE(widest / g.step, kMaxGridSteps);
    EXPECT_GT(widest / (0.5 * g.step), kMaxGridSteps) << "not the smallest step";
  }
  // extents at the rule's edges: just above kMaxGridSteps steps of 2^-34 (the step doubles), exactly
  // kMaxGridSteps of them, and a power of two
  const double fine = std::ldexp(1.0, -34);
  for (const double extent : {(kMaxGridSteps + 0.5) * fine, kMaxGridSteps * fine, 0.125}) {
    TissueModel<double> two;  // two nodes, on the x axis
    two.n_nodes = 2;
    two.X = {0.0, extent, 0.0, 0.0, 0.0, 0.0};
    const ReferenceGrid g = reference_grid(two);
    EXPECT_EQ(g.step, extent == kMaxGridSteps * fine ? fine : 2 * fine) << extent;
    EXPECT_LE(double(grid_point(g, two, 1).x), kMaxGridSteps);
  }
}

/// Float gradients from the grid (tet_shape_gradients_on_grid) and from the
/// double positions (tet_shape_gradients_from) on 2,000 random tets of
/// 1-3 mm edges placed up to 0.1 m from the origin, on the grid of a 0.1 m
/// mesh. Each grid edge is the true edge to a step, and the grid's
/// gradients are exactly tet_shape_gradients<float> of those edges rounded
/// to float once. Against the double gradients both paths stray by ~1e-6
/// on these random (often poorly shaped) tets, the grid's by less than
/// twice the double positions' worst.
TEST(TetGeometry, GradientsOnTheGridAreThoseOfDoubleEdgesToAFewUlps) {
  TissueModel<double> bounds;  // two corners that fix the grid: a 0.1 m cube
  bounds.n_nodes = 2;
  bounds.X = {0.0, 0.1, 0.0, 0.1, 0.0, 0.1};
  const ReferenceGrid g = reference_grid(bounds);
  EXPECT_EQ(g.step, std::ldexp(1.0, -34));
  std::uint64_t seed = 7;
  auto uniform = [&] {
    seed = seed * 6364136223846793005ull + 1442695040888963407ull;
    return double(seed >> 11) * 0x1.0p-53;
  };
  double worst_grid = 0, worst_double = 0, worst_between = 0;
  int tested = 0;
  for (int t = 0; t < 2000; ++t) {
    Vec3<double> X[4];
    const Vec3<double> at = {0.005 + 0.09 * uniform(), 0.005 + 0.09 * uniform(), 0.005 + 0.09 * uniform()};
    for (int a = 0; a < 4; ++a) X[a] = at + Vec3<double>{0.003 * uniform(), 0.003 * uniform(), 0.003 * uniform()};
    double ref[12];
    const double V = tet_shape_gradients(X, ref);
    if (std::fabs(V) < 1e-10) continue;  // a near-flat draw: its conditioning, not the grid, would dominate
    ++tested;
    TissueModel<double> corners;
    corners.n_nodes = 4;
    corners.X.resize(12);
    for (int a = 0; a < 4; ++a) corners.X[a] = X[a].x, corners.X[4 + a] = X[a].y, corners.X[8 + a] = X[a].z;
    GridPoint q[4];
    for (int a = 0; a < 4; ++a) q[a] = grid_point(g, corners, a);
    float on_grid[12], from_double[12];
    const float Vg = tet_shape_gradients_on_grid<float>(q, float(g.step), on_grid);
    Vec3<float> R[4] = {};  // the grid's edges, exact in double, rounded to float once
    for (int a = 1; a < 4; ++a) {
      const std::int64_t d[3] = {std::int64_t(q[a].x) - q[0].x, std::int64_t(q[a].y) - q[0].y,
                                 std::int64_t(q[a].z) - q[0].z};
      const double x[3] = {X[a].x - X[0].x, X[a].y - X[0].y, X[a].z - X[0].z};
      for (int k = 0; k < 3; ++k) ASSERT_LE(std::fabs(double(d[k]) * g.step - x[k]), g.step * (1 + 1e-9));
      R[a] = {float(double(d[0]) * g.step), float(double(d[1]) * g.step), float(double(d[2]) * g.step)};
    }
    float from_edges[12] = {};
    ASSERT_EQ(tet_shape_gradients(R, from_edges), Vg);
    for (int k = 0; k < 12; ++k) ASSERT_EQ(from_edges[k], on_grid[k]) << k;
    const float Vd = tet_shape_gradients_from<float>(X, from_double);
    worst_grid = std::max(worst_grid, gradient_deviation(on_grid, Vg, ref, V));
    worst_double = std::max(worst_double, gradient_deviation(from_double, Vd, ref, V));
    double from_double_d[12];
    for (int k = 0; k < 12; ++k) from_double_d[k] = from_double[k];
    worst_between = std::max(worst_between, gradient_deviation(on_grid, Vg, from_double_d, double(Vd)));
  }
  std::printf("[measured] %d tets: float gradients from the grid %.3g, from double positions %.3g, between %.3g\n",
              tested, worst_grid, worst_double, worst_between);
  EXPECT_GT(tested, 1000);
  EXPECT_LT(worst_grid, 2 * worst_double);
  EXPECT_LT(worst_between, 2 * worst_double);
}

/// Where the elements are far smaller than the mesh (20 micrometre cells,
/// and one tet 3 m away: a grid step of 2^-29 m, 9.3e-5 of a cell),
/// rounding to the grid moves the edges by more than the cuda backend's
/// kGradientTolerance (1e-5) allows, and the check names an element: its
/// float passes then keep the stored gradients. From double coordinates the
/// same float gradients stay within 1e-6.
TEST(Model, FloatGridStraysWhereElementsAreFarSmallerThanTheMesh) {
  constexpr double kCell = 2e-5;
  ModelInput in = box_input(4, 4, 4, 4 * kCell, 4 * kCell, 4 * kCell);
  test::append_corner_tet(in, {3.0, 0.0, 0.0}, kCell);
  const TissueModel<double> m = build_model(in);
  EXPECT_EQ(reference_grid(m).step, std::ldexp(1.0, -29));
  const GradientDeviation grid = worst_gradient_deviation(m, Precision::Float);
  double coordinates = 0;  // float gradients from double coordinates, every element
  const index_t ne = m.n_elems;
  for (index_t e = 0; e < ne; ++e) {
    Vec3<double> X[4];
    double dN[12];
    for (int a = 0; a < 4; ++a) X[a] = reference_position(m, m.elem_nodes[a * ne + e]);
    for (int k = 0; k < 12; ++k) dN[k] = m.dndx[k * std::size_t(ne) + e];
    coordinates = std::max(coordinates, shape_gradient_deviation<float>(X, dN, m.volume[e]));
  }
  std::printf(
      "[measured] 20 um cells in a 3 m mesh: float gradients from the grid %.3g (element %d), from "
      "double coordinates %.3g\n",
      grid.deviation, int(grid.elem), coordinates);
  EXPECT_GT(grid.deviation, 1e-5);
  EXPECT_GE(grid.elem, 0);
  EXPECT_LT(grid.elem, ne);
  EXPECT_LT(coordinates, 1e-6);
}

/// A sliver the model accepts (tests/sliver.hpp), apart from a box:
/// recomputed in float, its gradients stray by far more than the cuda
/// backend's kGradientTolerance (1e-5; Auto then keeps the stored
/// gradients), in double they do not; the deviation names it, and
/// stop_above stops at it.
TEST(Model, SliverGradientsStrayWhenRecomputedInFloat) {
  ModelInput in = box_input(2, 2, 2, 0.01, 0.01, 0.01);
  const TissueModel<double> box = build_model(in);
  const index_t sliver = test::append_sliver(in, {0.03, 0.0, 0.0});
  const TissueModel<double> m = build_model(in);
  const GradientDeviation dev = worst_gradient_deviation(m, Precision::Float);
  std::printf("[measured] worst gradient deviation: box %.3g, box and sliver %.3g (float), %.3g (double)\n",
              worst_gradient_deviation(box, Precision::Float).deviation, dev.deviation,
              worst_gradient_deviation(m, Precision::Double).deviation);
  EXPECT_LT(worst_gradient_deviation(box, Precision::Float).deviation, 1e-6);
  EXPECT_GT(dev.deviation, 1e-4);
  EXPECT_EQ(dev.elem, sliver);
  EXPECT_LT(worst_gradient_deviation(m, Precision::Double).deviation, 1e-8);
  const GradientDeviation stopped = worst_gradient_deviation(m, Precision::Float, 1e-5);
  EXPECT_GT(stopped.deviation, 1e-5);
  EXPECT_EQ(stopped.elem, sliver);
}

/// A tet with no volume at float precision (flat to 1e-50 m): its
/// gradients from double positions come back zero, volume and all
/// (whatever dN held), which deviates by 1 (all of it) from the double
/// ones; against a zero reference volume the deviation is HUGE_VAL, not a
/// NaN.
TEST(TetGeometry, GradientsFromDoubleOfAFlatTetAreZeroAndItsDeviationHuge) {
  // (at the origin, where a double holds the 1e-50 and a float does not)
  const Vec3<double> X[4] = {{0.0, 0.0, 0.0}, {0.001, 0.0, 0.0}, {0.0, 0.001, 0.0}, {0.0, 0.0, 1e-50}};
  float dN[12];
  for (float& v : dN) v = std::numeric_limits<float>::quiet_NaN();
  EXPECT_EQ(tet_shape_gradients_from<float>(X, dN), 0.0f);
  for (float v : dN) EXPECT_EQ(v, 0.0f);
  double ref[12];
  const double V = tet_shape_gradients(X, ref);
  ASSERT_GT(V, 0.0);  // not flat in double
  EXPECT_GE(shape_gradient_deviation<float>(X, ref, V), 1.0);
  EXPECT_EQ(shape_gradient_deviation<double>(X, ref, 0.0), HUGE_VAL);
}

}  // namespace
}  // namespace tissue
