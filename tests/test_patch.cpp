// The patch test on the cpu backend: a homogeneous deformation u = (G - I) X
// prescribed on every node of a box mesh (regular and with distorted
// interior elements) must give zero internal force on interior nodes, for
// the IANP and the plain tet, in stretch and in shear; and u = 0 must give
// no force anywhere. Also checks passes 1 and 2 (J_e = det G, nodal
// pressure K (det G - 1)) on the same states.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <string>

#include "backends/registry.hpp"
#include "core/box_mesh.hpp"
#include "core/model.hpp"
#include "core/vec.hpp"

namespace tissue {
namespace {

constexpr int kN = 3;                                // cells per side: 2 x 2 x 2 interior nodes
constexpr double kL[3] = {0.03, 0.024, 0.036};       // box size (m)
constexpr double kE = 3000.0, kNu = 0.45, kRho = 1000.0;

/// Box model; `distort` moves every interior node by up to 15% of a cell in
/// each direction (seeded), so the elements are irregular.
TissueModel<double> patch_model(bool ianp, bool distort) {
  ModelInput in;
  box_mesh(in, kN, kN, kN, kL[0], kL[1], kL[2]);
  in.materials = {{kE / (2 * (1 + kNu)), kE / (3 * (1 - 2 * kNu)), kRho}};
  in.ianp = ianp;
  if (distort) {
    std::mt19937 rng(1234);
    std::uniform_real_distribution<double> uni(-0.15, 0.15);
    for (int k = 1; k < kN; ++k)
      for (int j = 1; j < kN; ++j)
        for (int i = 1; i < kN; ++i) {
          const index_t a = box_node(kN, kN, i, j, k);
          for (int c = 0; c < 3; ++c) in.nodes[3 * a + c] += uni(rng) * kL[c] / kN;
        }
  }
  return build_model(in);
}

bool interior(const TissueModel<double>& m, index_t a) { return !(m.node_flags[a] & kSurface); }

struct Case {
  const char* name;
  Mat3<double> G;
};

const Case kCases[] = {
    {"stretch", {{1.1, 0, 0, 0, 0.95, 0, 0, 0, 1.03}}},
    {"simple shear", {{1, 0.2, 0, 0, 1, 0, 0, 0, 1}}},
    {"general", {{1.05, 0.1, -0.04, 0.02, 0.97, 0.08, -0.03, 0.05, 1.02}}},
};

struct Param {
  Precision precision;
  bool ianp;
  bool distort;
};

std::string param_name(const ::testing::TestParamInfo<Param>& info) {
  return std::string(to_string(info.param.precision)) + (info.param.ianp ? "_ianp" : "_plain") +
         (info.param.distort ? "_distorted" : "_regular");
}

class PatchTest : public ::testing::TestWithParam<Param> {
 protected:
  /// Relative tolerance of "zero" interior forces: rounding of sums of O(1)
  /// terms (observed about 1e-14 in double and 3e-6 in float).
  double tol() const { return GetParam().precision == Precision::Double ? 1e-11 : 1e-4; }
};

TEST_P(PatchTest, ZeroDisplacementGivesZeroForce) {
  const auto m = patch_model(GetParam().ianp, GetParam().distort);
  auto be = create_backend("cpu", GetParam().precision);
  be->upload(m);
  be->advance(1);
  const Fields f = be->download();
  ASSERT_EQ(f.f.size(), size_t(3 * m.n_nodes));
  for (size_t k = 0; k < f.f.size(); ++k) EXPECT_EQ(f.f[k], 0.0) << "component " << k;
  for (double u : f.u) EXPECT_EQ(u, 0.0);
  for (double J : f.elem_J) EXPECT_EQ(J, 1.0);
}

TEST_P(PatchTest, HomogeneousDeformationGivesNoInteriorForce) {
  const auto m = patch_model(GetParam().ianp, GetParam().distort);
  ASSERT_EQ(m.reoriented, 0) << "the distortion tangled the mesh";
  const index_t n = m.n_nodes;
  auto be = create_backend("cpu", GetParam().precision);
  be->upload(m);
  int n_interior = 0;
  for (index_t a = 0; a < n; ++a) n_interior += interior(m, a);
  ASSERT_EQ(n_interior, (kN - 1) * (kN - 1) * (kN - 1));
  for (const Case& c : kCases) {
    SCOPED_TRACE(c.name);
    std::vector<double> u(3 * n);
    for (index_t a = 0; a < n; ++a) {
      const Vec3<double> X = {m.X[a], m.X[n + a], m.X[2 * n + a]};
      const Vec3<double> d = c.G * X - X;
      for (int k = 0; k < 3; ++k) u[k * n + a] = d[k];
    }
    be->set_displacements(u);
    be->advance(1);
    const Fields f = be->download();
    double f_boundary = 0, f_interior = 0;
    Vec3<double> total = {0, 0, 0};
    for (index_t a = 0; a < n; ++a) {
      const Vec3<double> fa = {f.f[a], f.f[n + a], f.f[2 * n + a]};
      total = total + fa;
      double& worst = interior(m, a) ? f_interior : f_boundary;
      worst = std::max(worst, norm(fa));
    }
    ASSERT_GT(f_boundary, 0);
    EXPECT_LT(f_interior, tol() * f_boundary) << "largest interior force " << f_interior << " N, boundary "
                                              << f_boundary << " N";
    // the internal forces of a free body balance
    EXPECT_LT(norm(total), tol() * f_boundary * n);
    // pass 1 and pass 2 see the homogeneous state: J_e = det G, p_a = K (det G - 1)
    const double J = det(c.G), K = m.K[0];
    for (index_t e = 0; e < m.n_elems; ++e) ASSERT_NEAR(f.elem_J[e], J, tol()) << "element " << e;
    if (GetParam().ianp) {
      for (index_t a = 0; a < n; ++a) ASSERT_NEAR(f.node_p[a], K * (J - 1), tol() * K) << "node " << a;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Cpu, PatchTest,
                         ::testing::Values(Param{Precision::Double, true, false}, Param{Precision::Double, false, false},
                                           Param{Precision::Double, true, true}, Param{Precision::Double, false, true},
                                           Param{Precision::Float, true, true}, Param{Precision::Float, false, true}),
                         param_name);

// A non-homogeneous deformation does load interior nodes: the patch test
// above can fail (guards against a force pass that zeroes everything).
TEST(PatchTestControl, InhomogeneousDeformationLoadsInteriorNodes) {
  const auto m = patch_model(true, true);
  const index_t n = m.n_nodes;
  auto be = create_backend("cpu", Precision::Double);
  be->upload(m);
  std::vector<double> u(3 * n, 0.0);
  for (index_t a = 0; a < n; ++a) {
    const double x = m.X[a] / kL[0];
    u[a] = 0.002 * x * x;  // u_x = c x^2: non-uniform stretch
  }
  be->set_displacements(u);
  be->advance(1);
  const Fields f = be->download();
  double f_boundary = 0, f_interior = 0;
  for (index_t a = 0; a < n; ++a) {
    const double fa = std::hypot(f.f[a], f.f[n + a], f.f[2 * n + a]);
    double& worst = interior(m, a) ? f_interior : f_boundary;
    worst = std::max(worst, fa);
  }
  EXPECT_GT(f_interior, 1e-3 * f_boundary);
}

}  // namespace
}  // namespace tissue
