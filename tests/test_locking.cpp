// Volumetric locking (docs/design.md section 2, IANP) on the cpu backend: a box
// of 4 x 4 x 4 cells, bottom face fixed, top face pushed down by a
// prescribed displacement (all top nodes tool-driven), relaxed to
// equilibrium by damped explicit dynamics. At nu = 0.499 the plain linear
// tet locks: its reaction force is much larger than the IANP tet's. At
// nu = 0.3 there is little volumetric constraint and the two agree closely.
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <random>
#include <string>
#include <vector>

#include "accuracy/locking.hpp"
#include "backends/registry.hpp"
#include "core/box_mesh.hpp"
#include "core/model.hpp"

namespace tissue {
namespace {

constexpr int kCells = 4;         // per side
constexpr double kSide = 0.04;    // box side (m)
constexpr double kE = 3000.0;     // Pa
constexpr double kRho = 1000.0;   // kg/m^3
constexpr double kPress = 0.02;   // top displacement / side (2% compression)

/// What one quasi-static indentation gives.
struct Indentation {
  double force = 0;     ///< |z reaction| on the top face at equilibrium (N)
  double residual = 0;  ///< |f_free| / |f_held| at the end
  double kinetic = 0;   ///< kinetic energy at the end (J)
  long steps = 0;       ///< TLED steps taken
};

/// Builds the box (plain or IANP tets, Poisson ratio nu), fixes its bottom,
/// ramps the top face down by kPress * kSide over `ramp` seconds, holds it
/// and steps until the free-node residual and the kinetic energy are small.
/// The time step is 0.8 dt_crit: dt_crit = L/c with L the smallest altitude
/// overestimates the stable step of the plain tet on this Kuhn mesh by ~11%
/// at nu = 0.499 (measured 2 / omega_max = 0.89 dt_crit), so the safety must
/// be below 0.89 for the plain element; IANP alone is stable at dt_crit.
Indentation indent(bool ianp, double nu) {
  ModelInput in;
  box_mesh(in, kCells, kCells, kCells, kSide, kSide, kSide);
  in.materials = {{kE / (2 * (1 + nu)), kE / (3 * (1 - 2 * nu)), kRho}};
  in.ianp = ianp;
  in.dt_safety = 0.8;
  const index_t n = static_cast<index_t>(in.nodes.size() / 3);
  in.fixed.assign(n, 0);
  std::vector<index_t> top;
  for (int j = 0; j <= kCells; ++j)
    for (int i = 0; i <= kCells; ++i) {
      in.fixed[box_node(kCells, kCells, i, j, 0)] = 1;
      top.push_back(box_node(kCells, kCells, i, j, kCells));
    }
  const TissueModel<double> m = build_model(in);  // default damping: 2 x lowest-mode estimate
  auto be = create_backend("cpu", Precision::Double);
  be->upload(m);

  const double depth = kPress * kSide, ramp = 0.2;
  const int chunk = std::max(1, static_cast<int>(std::lround(0.005 / m.dt)));  // 5 ms of steps
  std::vector<double> target(3 * top.size(), 0.0);
  Indentation out;
  double t = 0;
  for (int k = 0; k < 4000; ++k) {
    const double d = depth * std::min(1.0, t / ramp);
    for (size_t i = 0; i < top.size(); ++i) target[3 * i + 2] = -d;
    be->set_driven(top, target);
    be->advance(chunk);
    out.steps += chunk;
    t += chunk * m.dt;
    const Reductions r = be->reduce();
    EXPECT_TRUE(r.finite);
    EXPECT_LT(r.bad_elem, 0);
    if (!r.finite || r.bad_elem >= 0) break;
    out.force = std::fabs(r.reaction.z);
    out.residual = std::sqrt(r.free_force2 / r.held_force2);
    out.kinetic = r.kinetic;
    if (t > ramp && out.residual < 1e-5 && out.kinetic < 1e-9 * 0.5 * out.force * depth) break;
  }
  return out;
}

void report(const char* what, const Indentation& plain, const Indentation& ianp) {
  std::cout << "[ INFO     ] " << what << ": reaction plain " << plain.force << " N (" << plain.steps << " steps), IANP "
            << ianp.force << " N (" << ianp.steps << " steps), plain / IANP = " << plain.force / ianp.force << "\n";
  ::testing::Test::RecordProperty(std::string(what) + "_plain_over_ianp", std::to_string(plain.force / ianp.force));
}

void expect_equilibrium(const Indentation& r, const char* what) {
  EXPECT_LT(r.residual, 1e-5) << what << ": not at equilibrium";
  EXPECT_LT(r.kinetic, 1e-9 * 0.5 * r.force * kPress * kSide) << what << ": still moving";
  EXPECT_GT(r.force, 0) << what;
}

// Observed on this 4 x 4 x 4 mesh (double): nu = 0.499 gives plain 0.733 N,
// IANP 0.156 N (ratio 4.7); nu = 0.4999 gives plain 4.53 N, IANP 0.159 N
// (ratio 28.5); nu = 0.3 gives 0.1086 N and 0.1072 N (ratio 1.013). Refining
// to 8 x 8 x 8 cells brings IANP at nu = 0.499 to 0.132 N and plain to 0.319 N.
// The unconfined linear estimate E A eps is 0.096 N; the clamped faces stiffen.
TEST(Locking, MeshesMustAscend) {
  try {
    (void)accuracy::locking_study(0.45, {8, 4});
    FAIL() << "expected an error";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("cells 4 after 8: the meshes must ascend"), std::string::npos) << e.what();
  }
}

TEST(Locking, PlainTetLocksAtNearlyIncompressible) {
  const Indentation plain = indent(false, 0.499), ianp = indent(true, 0.499);
  expect_equilibrium(plain, "plain, nu = 0.499");
  expect_equilibrium(ianp, "IANP, nu = 0.499");
  report("nu = 0.499", plain, ianp);
  const double unconfined = kE * kSide * kSide * kPress;
  EXPECT_GT(ianp.force, unconfined);
  EXPECT_LT(ianp.force, 3 * unconfined);
  EXPECT_GT(plain.force / ianp.force, 3.0) << "plain tets should lock at nu = 0.499";
}

// Locking is a stiffness that grows with the bulk modulus: from nu = 0.499 to
// 0.4999 (K x 10) the plain tet's force grows several times, the IANP tet's
// hardly at all (the incompressible limit is finite).
TEST(Locking, IanpForceIndependentOfBulkModulus) {
  const Indentation plain = indent(false, 0.4999), ianp = indent(true, 0.4999);
  const Indentation plain3 = indent(false, 0.499), ianp3 = indent(true, 0.499);
  expect_equilibrium(plain, "plain, nu = 0.4999");
  expect_equilibrium(ianp, "IANP, nu = 0.4999");
  report("nu = 0.4999", plain, ianp);
  EXPECT_GT(plain.force / plain3.force, 4.0);
  EXPECT_LT(ianp.force / ianp3.force, 1.05);
  EXPECT_GT(ianp.force / ianp3.force, 1.0);
}

TEST(Locking, FormulationsAgreeAtModerateNu) {
  const Indentation plain = indent(false, 0.3), ianp = indent(true, 0.3);
  expect_equilibrium(plain, "plain, nu = 0.3");
  expect_equilibrium(ianp, "IANP, nu = 0.3");
  report("nu = 0.3", plain, ianp);
  EXPECT_GE(plain.force, ianp.force);  // averaging the pressure only relaxes the volumetric constraint
  EXPECT_LT(plain.force / ianp.force, 1.05);
}

// The critical step of docs/design.md section 2 (dt_crit = min_e L_e / c_e, L_e the
// smallest altitude) is stable for the IANP element, the engine's default:
// undamped at dt = dt_crit exactly, a random perturbation of a clamped box at
// nu = 0.499 (the stiffest case) stays bounded over 20000 steps. (The plain
// element is not: see indent()'s note.)
TEST(CriticalStep, IanpStableAtCriticalStep) {
  ModelInput in;
  box_mesh(in, kCells, kCells, kCells, kSide, kSide, kSide);
  const double nu = 0.499;
  in.materials = {{kE / (2 * (1 + nu)), kE / (3 * (1 - 2 * nu)), kRho}};
  const index_t n = static_cast<index_t>(in.nodes.size() / 3);
  in.fixed.assign(n, 0);
  for (int j = 0; j <= kCells; ++j)
    for (int i = 0; i <= kCells; ++i) in.fixed[box_node(kCells, kCells, i, j, 0)] = 1;
  in.damping = 0;
  in.dt = build_model(in).dt_crit;
  const TissueModel<double> m = build_model(in);
  ASSERT_EQ(m.dt, m.dt_crit);
  auto be = create_backend("cpu", Precision::Double);
  be->upload(m);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> uni(-1e-5, 1e-5);  // 0.1% of a cell
  std::vector<double> u(3 * n, 0.0);
  for (index_t a = 0; a < n; ++a)
    if (!in.fixed[a])
      for (int c = 0; c < 3; ++c) u[c * n + a] = uni(rng);
  be->set_displacements(u);
  double peak = 0;
  for (int k = 0; k < 40; ++k) {
    be->advance(500);
    const Reductions r = be->reduce();
    ASSERT_TRUE(r.finite) << "after " << 500 * (k + 1) << " steps";
    peak = std::max(peak, r.max_disp);
  }
  EXPECT_LT(peak, 1e-4) << "the perturbation grew: dt_crit is not stable";
}

}  // namespace
}  // namespace tissue
