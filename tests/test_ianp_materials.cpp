// IANP where materials of different bulk modulus meet (core/model.hpp
// node_bulk_moduli, docs/design.md section 2): pass 2 averages the elements'
// volume change at a node and gives it the pressure K_a theta_a with the
// node's volume-weighted K_a. Checked against properties no code here sets:
// the linearised stiffness of an energy is symmetric (averaging the element
// pressures K_e (J_e - 1) instead is not, and the explicit step then
// diverges); a free vibration at the stable step stays bounded.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "backend_test_support.hpp"
#include "core/box_mesh.hpp"
#include "core/model.hpp"

namespace tissue::test {
namespace {

constexpr double kE = 3000, kNu = 0.45, kRatio = 10;

MaterialParams params(double E) { return {E / (2 * (1 + kNu)), E / (3 * (1 - 2 * kNu)), 1000}; }

/// A box of n^3 cells: elements whose centroid lies at x > L/2 are
/// kRatio times stiffer (same nu and rho).
ModelInput two_material_box(int n) {
  ModelInput in;
  box_mesh(in, n, n, n, kL, kL, kL);
  in.materials = {params(kE), params(kRatio * kE)};
  in.material_names = {"tissue", "tumour"};
  const std::size_t ne = in.tets.size() / 4;
  in.elem_material.assign(ne, 0);
  for (std::size_t e = 0; e < ne; ++e) {
    double x = 0;
    for (int a = 0; a < 4; ++a) x += 0.25 * in.nodes[3 * std::size_t(in.tets[4 * e + a])];
    in.elem_material[e] = x > 0.5 * kL ? 1 : 0;
  }
  in.source = "two-material box";
  return in;
}

std::vector<double> internal_force(const TissueModel<double>& m, const std::vector<double>& u) {
  std::vector<double> uu = u, up = u, held_u(u.size(), 0.0);
  const std::vector<std::uint8_t> held(m.n_nodes, 0);
  return reference_step(m, uu, up, held, held_u);
}

TEST(IanpMaterials, NodalBulkModulusIsTheElementsOwnAwayFromTheInterfaceAndBetweenAtIt) {
  const TissueModel<double> m = build_model(two_material_box(4));
  const std::vector<double> K = node_bulk_moduli(m);
  const double K1 = params(kE).K, K2 = params(kRatio * kE).K;
  int soft = 0, stiff = 0, between = 0;
  const index_t N = m.n_nodes;
  for (index_t a = 0; a < N; ++a) {
    const double x = m.X[a];
    if (x < 0.5 * kL - 1e-12) {
      EXPECT_EQ(K[a], K1) << "node " << a;  // exactly: one material around it
      ++soft;
    } else if (x > 0.5 * kL + 1e-12) {
      EXPECT_EQ(K[a], K2) << "node " << a;
      ++stiff;
    } else {
      EXPECT_GT(K[a], K1) << "node " << a;
      EXPECT_LT(K[a], K2) << "node " << a;
      ++between;
    }
  }
  EXPECT_EQ(between, 5 * 5);  // the plane x = L/2 of a 4^3 grid
  EXPECT_GT(soft, 0);
  EXPECT_GT(stiff, 0);
}

TEST(IanpMaterials, LinearisedStiffnessAcrossTheInterfaceIsSymmetric) {
  // K_ij = d f_i / d u_j at u = 0 by central differences over every degree of
  // freedom: the forces of an energy have a symmetric Hessian. The volume
  // coupling across the interface is where the two averagings differ: with
  // the element pressures averaged, K_ij / K_ji there is the ratio of the
  // two materials' K (10 here).
  const TissueModel<double> m = build_model(two_material_box(3));
  const index_t n = m.n_nodes;
  const std::size_t dofs = 3 * std::size_t(n);
  const double h = 1e-9 * kL;
  std::vector<double> Kmat(dofs * dofs);
  std::vector<double> u(dofs, 0.0);
  for (std::size_t j = 0; j < dofs; ++j) {
    u[j] = h;
    const std::vector<double> fp = internal_force(m, u);
    u[j] = -h;
    const std::vector<double> fm = internal_force(m, u);
    u[j] = 0;
    for (std::size_t i = 0; i < dofs; ++i) Kmat[i * dofs + j] = (fp[i] - fm[i]) / (2 * h);
  }
  double kmax = 0, asym = 0;
  std::size_t wi = 0, wj = 0;
  for (std::size_t i = 0; i < dofs; ++i)
    for (std::size_t j = 0; j < dofs; ++j) {
      kmax = std::max(kmax, std::fabs(Kmat[i * dofs + j]));
      const double d = std::fabs(Kmat[i * dofs + j] - Kmat[j * dofs + i]);
      if (d > asym) asym = d, wi = i, wj = j;
    }
  ASSERT_GT(kmax, 0);
  EXPECT_LT(asym, 1e-5 * kmax) << "K[" << wi << "][" << wj << "] = " << Kmat[wi * dofs + wj] << " but K[" << wj << "]["
                               << wi << "] = " << Kmat[wj * dofs + wi];
}

TEST(IanpMaterials, AFreeVibrationAtTheStableStepStaysBounded) {
  // undamped central differences at the model's dt from a random start:
  // stable means the displacements stay of the start's size (a divergent
  // scheme grows them without bound within a few hundred steps)
  ModelInput in = two_material_box(4);
  in.damping = 0.0;
  const TissueModel<double> m = build_model(in);
  const index_t n = m.n_nodes;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uni(-1, 1);
  std::vector<double> u(3 * std::size_t(n)), u_prev, held_u(u.size(), 0.0);
  for (double& x : u) x = 1e-4 * kL * uni(rng);
  u_prev = u;
  const std::vector<std::uint8_t> held(n, 0);
  const double start = max_abs(u);
  double peak = start;
  for (int step = 0; step < 4000; ++step) {
    reference_step(m, u, u_prev, held, held_u);
    peak = std::max(peak, max_abs(u));
    ASSERT_TRUE(std::isfinite(peak)) << "step " << step;
  }
  EXPECT_LT(peak, 20 * start);
}

}  // namespace
}  // namespace tissue::test
