// Tests of the per-element TLED math in core/tet.hpp (docs/design.md section 2):
// shape gradients and volumes, the characteristic length, Neo-Hookean PK2
// stress against its closed form, element forces against finite differences
// of the discrete energy, invariance under rigid motion, the IANP element
// and the central-difference constants. Segment-triangle is tested elsewhere.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include "core/tet.hpp"

namespace tissue {
namespace {

constexpr double kPi = 3.14159265358979323846;

/// Neo-Hookean parameters of brain-like tissue (E = 3000 Pa, nu = 0.45).
constexpr double kE = 3000.0, kNu = 0.45;
constexpr double kMu = kE / (2 * (1 + kNu));      // Pa
constexpr double kK = kE / (3 * (1 - 2 * kNu));   // Pa

/// Rotation by `angle` (rad) about the unit axis n (Rodrigues).
Mat3<double> rotation(Vec3<double> n, double angle) {
  const double c = std::cos(angle), s = std::sin(angle), t = 1 - c;
  return {{t * n.x * n.x + c, t * n.x * n.y - s * n.z, t * n.x * n.z + s * n.y,  //
           t * n.x * n.y + s * n.z, t * n.y * n.y + c, t * n.y * n.z - s * n.x,  //
           t * n.x * n.z - s * n.y, t * n.y * n.z + s * n.x, t * n.z * n.z + c}};
}

Vec3<double> unit(Vec3<double> v) { return (1.0 / norm(v)) * v; }

template <class T>
Vec3<T> cast(Vec3<double> v) {
  return {T(v.x), T(v.y), T(v.z)};
}

template <class T>
Mat3<T> cast(const Mat3<double>& a) {
  Mat3<T> r;
  for (int k = 0; k < 9; ++k) r.m[k] = T(a.m[k]);
  return r;
}

/// The unit corner tet (0, e_x, e_y, e_z): V = 1/6.
template <class T>
void corner_tet(Vec3<T> X[4]) {
  X[0] = {0, 0, 0};
  X[1] = {1, 0, 0};
  X[2] = {0, 1, 0};
  X[3] = {0, 0, 1};
}

/// A generic, positively oriented tet of centimetre size (m).
void generic_tet(Vec3<double> X[4]) {
  X[0] = {0.010, -0.002, 0.003};
  X[1] = {0.031, 0.001, 0.000};
  X[2] = {0.012, 0.024, 0.005};
  X[3] = {0.008, 0.006, 0.027};
}

double max_abs(const Mat3<double>& a) {
  double r = 0;
  for (double v : a.m) r = std::max(r, std::fabs(v));
  return r;
}

template <class T>
double max_abs(const Vec3<T> f[4]) {
  double r = 0;
  for (int a = 0; a < 4; ++a)
    for (int i = 0; i < 3; ++i) r = std::max(r, std::fabs(double(f[a][i])));
  return r;
}

/// Corner displacements u_a = (G - I) X_a + t of the homogeneous map x = G X + t.
template <class T>
void homogeneous_displacement(const Vec3<double> X[4], const Mat3<double>& G, Vec3<double> t, Vec3<T> u[4]) {
  for (int a = 0; a < 4; ++a) u[a] = cast<T>(G * X[a] - X[a] + t);
}

// ---------------------------------------------------------------- geometry

TEST(TetGeometry, UnitCornerTetVolumeAndGradients) {
  Vec3<double> X[4];
  corner_tet(X);
  double dN[12];
  const double V = tet_shape_gradients(X, dN);
  EXPECT_NEAR(V, 1.0 / 6.0, 1e-15);
  const double expected[12] = {-1, -1, -1, 1, 0, 0, 0, 1, 0, 0, 0, 1};
  for (int k = 0; k < 12; ++k) EXPECT_NEAR(dN[k], expected[k], 1e-15) << "dN[" << k << "]";
}

TEST(TetGeometry, UnitCornerTetFloat) {
  Vec3<float> X[4];
  corner_tet(X);
  float dN[12];
  const float V = tet_shape_gradients(X, dN);
  EXPECT_NEAR(V, 1.0f / 6.0f, 1e-7f);
  const float expected[12] = {-1, -1, -1, 1, 0, 0, 0, 1, 0, 0, 0, 1};
  for (int k = 0; k < 12; ++k) EXPECT_NEAR(dN[k], expected[k], 1e-6f) << "dN[" << k << "]";
}

TEST(TetGeometry, InvertedTetHasNegativeVolume) {
  Vec3<double> X[4];
  corner_tet(X);
  std::swap(X[1], X[2]);
  double dN[12];
  EXPECT_NEAR(tet_shape_gradients(X, dN), -1.0 / 6.0, 1e-15);
}

TEST(TetGeometry, DegenerateTetReturnsZeroAndLeavesGradients) {
  Vec3<double> X[4] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}};  // coplanar
  double dN[12];
  std::fill(dN, dN + 12, 42.0);
  EXPECT_EQ(tet_shape_gradients(X, dN), 0.0);
  for (double v : dN) EXPECT_EQ(v, 42.0);
}

// x = s R X + t: V' = s^3 V and dN'_a = (1/s) R dN_a (gradients are covectors).
TEST(TetGeometry, ScaledRotatedTranslatedTet) {
  Vec3<double> X[4];
  generic_tet(X);
  double dN[12];
  const double V = tet_shape_gradients(X, dN);
  ASSERT_GT(V, 0);
  const double s = 2.5;
  const Mat3<double> R = rotation(unit({1, 2, -0.5}), 1.1);
  const Vec3<double> t = {0.3, -0.7, 1.2};
  Vec3<double> Y[4];
  for (int a = 0; a < 4; ++a) Y[a] = s * (R * X[a]) + t;
  double dM[12];
  const double W = tet_shape_gradients(Y, dM);
  EXPECT_NEAR(W / V, s * s * s, 1e-12 * s * s * s);
  double gmax = 0;
  for (double v : dN) gmax = std::max(gmax, std::fabs(v));
  for (int a = 0; a < 4; ++a) {
    const Vec3<double> expect = (1.0 / s) * (R * Vec3<double>{dN[3 * a], dN[3 * a + 1], dN[3 * a + 2]});
    for (int j = 0; j < 3; ++j) EXPECT_NEAR(dM[3 * a + j], expect[j], 1e-12 * gmax) << "corner " << a << " axis " << j;
  }
}

// Partition of unity and linear completeness: sum_a dN_a = 0 and
// sum_a X_a (x) dN_a = I, for a generic and a transformed tet.
TEST(TetGeometry, GradientsSumToZeroAndReproduceIdentity) {
  Vec3<double> X[4];
  generic_tet(X);
  const Mat3<double> R = rotation(unit({-0.3, 0.2, 1}), 2.0);
  for (int variant = 0; variant < 2; ++variant) {
    if (variant == 1)
      for (auto& x : X) x = 0.7 * (R * x) + Vec3<double>{5, 6, 7};
    double dN[12];
    ASSERT_GT(tet_shape_gradients(X, dN), 0);
    double gmax = 0;
    for (double v : dN) gmax = std::max(gmax, std::fabs(v));
    for (int j = 0; j < 3; ++j) EXPECT_NEAR(dN[j] + dN[3 + j] + dN[6 + j] + dN[9 + j], 0.0, 1e-13 * gmax);
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) {
        double sum = 0;
        for (int a = 0; a < 4; ++a) sum += X[a][i] * dN[3 * a + j];
        EXPECT_NEAR(sum, i == j ? 1.0 : 0.0, 1e-12) << "variant " << variant << " (" << i << "," << j << ")";
      }
  }
}

TEST(TetGeometry, MinAltitude) {
  // Unit corner tet: the largest face is the slanted one, area sqrt(3)/2, so
  // the smallest altitude is 3 (1/6) / (sqrt(3)/2) = 1/sqrt(3).
  Vec3<double> X[4];
  corner_tet(X);
  EXPECT_NEAR(tet_min_altitude(X, 1.0 / 6.0), 1.0 / std::sqrt(3.0), 1e-15);
  // Regular tet of edge a: every altitude is a sqrt(2/3).
  const double a = 0.004;
  Vec3<double> Y[4] = {{0, 0, 0}, {a, 0, 0}, {a / 2, a * std::sqrt(3.0) / 2, 0},
                       {a / 2, a * std::sqrt(3.0) / 6, a * std::sqrt(2.0 / 3.0)}};
  double dN[12];
  const double V = tet_shape_gradients(Y, dN);
  EXPECT_NEAR(V, a * a * a / (6 * std::sqrt(2.0)), 1e-15 * a * a * a);
  EXPECT_NEAR(tet_min_altitude(Y, V), a * std::sqrt(2.0 / 3.0), 1e-12 * a);
  // A flat tet: apex at height h over a unit right triangle; the base is the
  // largest face when h is small, so L = h. The sign of V does not matter.
  const double h = 0.01;
  Vec3<double> Z[4] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0.3, 0.3, h}};
  const double Vz = tet_shape_gradients(Z, dN);
  EXPECT_NEAR(tet_min_altitude(Z, Vz), h, 1e-14);
  EXPECT_NEAR(tet_min_altitude(Z, -Vz), h, 1e-14);
}

// ---------------------------------------------------------------- stress and forces

template <class T>
class TetMath : public ::testing::Test {
 protected:
  /// Relative tolerance of rounding-level checks in this precision.
  static constexpr double eps = std::is_same_v<T, float> ? 2e-5 : 1e-12;
};
using Scalars = ::testing::Types<float, double>;
TYPED_TEST_SUITE(TetMath, Scalars);

TYPED_TEST(TetMath, ZeroStressAndForceAtRest) {
  using T = TypeParam;
  Vec3<double> Xd[4];
  generic_tet(Xd);
  Vec3<T> X[4];
  for (int a = 0; a < 4; ++a) X[a] = cast<T>(Xd[a]);
  T dN[12];
  const T V = tet_shape_gradients(X, dN);
  const Vec3<T> u[4] = {};
  const Mat3<T> F = deformation_gradient(u, dN);
  for (int k = 0; k < 9; ++k) EXPECT_EQ(F.m[k], Mat3<T>::identity().m[k]);
  const Mat3<T> S = neo_hookean_pk2(F, T(1), T(kMu), T(kK));
  for (int k = 0; k < 9; ++k) EXPECT_NEAR(double(S.m[k]), 0.0, this->eps * kK) << "S[" << k << "]";
  EXPECT_NEAR(double(neo_hookean_energy(F, T(kMu), T(kK))), 0.0, this->eps * kK);
  Vec3<T> f[4];
  EXPECT_EQ(plain_element_forces(u, dN, V, T(kMu), T(kK), f), T(1));
  EXPECT_LE(max_abs(f), this->eps * kK * double(V) * 100);
  EXPECT_EQ(ianp_element_forces(u, dN, V, T(kMu), T(kK), T(0), f), T(1));
  EXPECT_LE(max_abs(f), this->eps * kK * double(V) * 100);
}

// Rigid translation gives F = I exactly; a 60-degree rotation gives F = R up
// to rounding. Both must give S ~ 0 and f ~ 0, measured against the forces of
// a 10% stretch of the same tet.
TYPED_TEST(TetMath, RigidMotionGivesNoStressOrForce) {
  using T = TypeParam;
  Vec3<double> Xd[4];
  generic_tet(Xd);
  Vec3<T> X[4];
  for (int a = 0; a < 4; ++a) X[a] = cast<T>(Xd[a]);
  T dN[12];
  const T V = tet_shape_gradients(X, dN);
  Vec3<T> u[4], f[4];

  homogeneous_displacement(Xd, Mat3<double>{{1.1, 0, 0, 0, 1, 0, 0, 0, 1}}, {0, 0, 0}, u);
  plain_element_forces(u, dN, V, T(kMu), T(kK), f);
  const double f_ref = max_abs(f);
  ASSERT_GT(f_ref, 0);

  struct Case {
    const char* name;
    Mat3<double> G;
    Vec3<double> t;
  };
  const Case cases[] = {{"translation", Mat3<double>::identity(), {0.004, -0.01, 0.02}},
                        {"rotation 60 deg", rotation(unit({1, 1, 1}), kPi / 3), {0.001, 0.002, -0.003}},
                        {"rotation 60 deg about z", rotation({0, 0, 1}, kPi / 3), {0, 0, 0}}};
  for (const Case& c : cases) {
    homogeneous_displacement(Xd, c.G, c.t, u);
    const Mat3<T> F = deformation_gradient(u, dN);
    const T J = det(F);
    EXPECT_NEAR(double(J), 1.0, this->eps) << c.name;
    const Mat3<T> S = neo_hookean_pk2(F, J, T(kMu), T(kK));
    for (int k = 0; k < 9; ++k) EXPECT_NEAR(double(S.m[k]), 0.0, 10 * this->eps * kK) << c.name << " S[" << k << "]";
    plain_element_forces(u, dN, V, T(kMu), T(kK), f);
    EXPECT_LE(max_abs(f), 10 * this->eps * f_ref) << c.name << " plain";
    ianp_element_forces(u, dN, V, T(kMu), T(kK), T(0), f);
    EXPECT_LE(max_abs(f), 10 * this->eps * f_ref) << c.name << " IANP, pbar = 0";
  }
}

// Uniaxial stretch F = diag(l, lt, lt). With W(l1, l2, l3) =
// mu/2 (J^(-2/3) (l1^2 + l2^2 + l3^2) - 3) + K/2 (J - 1)^2, J = l1 l2 l3,
// S_ii = (1/l_i) dW/dl_i (diagonal F, principal stretches), and
// dJ/dl_i = J / l_i give, by hand,
//   S_11 = mu J^(-2/3) (1 - I1 / (3 l^2))  + K J (J - 1) / l^2,
//   S_22 = mu J^(-2/3) (1 - I1 / (3 lt^2)) + K J (J - 1) / lt^2 = S_33,
// I1 = l^2 + 2 lt^2, off-diagonal S = 0.
TYPED_TEST(TetMath, NeoHookeanUniaxialClosedForm) {
  using T = TypeParam;
  const double stretches[][2] = {{1.2, 0.95}, {0.8, 1.07}, {1.5, 1.0 / std::sqrt(1.5)}, {1.0, 1.0}};
  for (const auto& s : stretches) {
    const double l = s[0], lt = s[1];
    const double J = l * lt * lt, I1 = l * l + 2 * lt * lt;
    const double a = kMu * std::pow(J, -2.0 / 3.0), vol = kK * J * (J - 1);
    const double S11 = a * (1 - I1 / (3 * l * l)) + vol / (l * l);
    const double S22 = a * (1 - I1 / (3 * lt * lt)) + vol / (lt * lt);
    const Mat3<T> F = {{T(l), 0, 0, 0, T(lt), 0, 0, 0, T(lt)}};
    const Mat3<T> S = neo_hookean_pk2(F, det(F), T(kMu), T(kK));
    const double scale = std::max({std::fabs(S11), std::fabs(S22), kMu});
    EXPECT_NEAR(double(S(0, 0)), S11, this->eps * scale) << "l = " << l << ", lt = " << lt;
    EXPECT_NEAR(double(S(1, 1)), S22, this->eps * scale) << "l = " << l << ", lt = " << lt;
    EXPECT_NEAR(double(S(2, 2)), S22, this->eps * scale) << "l = " << l << ", lt = " << lt;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        if (i != j) {
          EXPECT_NEAR(double(S(i, j)), 0.0, this->eps * scale);
        }
  }
}

// The stress is the derivative of the energy, S = 2 dW/dC, checked through
// P = F S = dW/dF by central differences on a general F.
TEST(TetMathDouble, Pk2IsEnergyGradient) {
  const Mat3<double> F = {{1.08, 0.12, -0.05, -0.07, 0.93, 0.1, 0.04, -0.11, 1.15}};
  const Mat3<double> P = F * neo_hookean_pk2(F, det(F), kMu, kK);
  const double h = 1e-6;
  for (int k = 0; k < 9; ++k) {
    Mat3<double> Fp = F, Fm = F;
    Fp.m[k] += h;
    Fm.m[k] -= h;
    const double dW = (neo_hookean_energy(Fp, kMu, kK) - neo_hookean_energy(Fm, kMu, kK)) / (2 * h);
    EXPECT_NEAR(P.m[k], dW, 1e-7 * max_abs(P)) << "P[" << k << "]";
  }
}

/// Discrete energy V W(F(u)) of one plain tet (J).
double tet_energy(const Vec3<double> u[4], const double dN[12], double V) {
  return V * neo_hookean_energy(deformation_gradient(u, dN), kMu, kK);
}

// f_a = dE/du_a with E = V W(F(u)): each of the 12 components against a
// central difference (h = 1e-7 of the tet size: truncation ~h^2, rounding
// ~1e-16 / h, both far below the 1e-6 asked).
TEST(TetMathDouble, PlainForcesMatchEnergyFiniteDifferences) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> uni(-1, 1);
  Vec3<double> X[4];
  generic_tet(X);
  double dN[12];
  const double V = tet_shape_gradients(X, dN);
  const double size = 0.02;
  for (int trial = 0; trial < 5; ++trial) {
    Vec3<double> u[4];
    for (auto& v : u) v = {0.15 * size * uni(rng), 0.15 * size * uni(rng), 0.15 * size * uni(rng)};
    Vec3<double> f[4];
    const double J = plain_element_forces(u, dN, V, kMu, kK, f);
    ASSERT_GT(J, 0.5);
    ASSERT_NE(J, 1.0);
    const double fmax = max_abs(f);
    const double h = 1e-7 * size;
    for (int a = 0; a < 4; ++a)
      for (int i = 0; i < 3; ++i) {
        Vec3<double> up[4], um[4];
        std::copy(u, u + 4, up);
        std::copy(u, u + 4, um);
        up[a][i] += h;
        um[a][i] -= h;
        const double fd = (tet_energy(up, dN, V) - tet_energy(um, dN, V)) / (2 * h);
        EXPECT_LT(std::fabs(f[a][i] - fd), 1e-6 * fmax)
            << "trial " << trial << " corner " << a << " axis " << i << ": f = " << f[a][i] << ", FD = " << fd;
      }
  }
}

// Element forces balance: sum_a f_a = 0 (translation invariance) and
// sum_a x_a x f_a = 0 (rotation invariance, x_a = X_a + u_a deformed).
TYPED_TEST(TetMath, ElementForcesAreBalanced) {
  using T = TypeParam;
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> uni(-1, 1);
  Vec3<double> Xd[4];
  generic_tet(Xd);
  Vec3<T> X[4];
  for (int a = 0; a < 4; ++a) X[a] = cast<T>(Xd[a]);
  T dN[12];
  const T V = tet_shape_gradients(X, dN);
  Vec3<T> u[4], f[4];
  for (auto& v : u) v = cast<T>(Vec3<double>{0.003 * uni(rng), 0.003 * uni(rng), 0.003 * uni(rng)});
  for (int ianp = 0; ianp < 2; ++ianp) {
    if (ianp) {
      ianp_element_forces(u, dN, V, T(kMu), T(kK), T(0.3 * kK * 0.02), f);
    } else {
      plain_element_forces(u, dN, V, T(kMu), T(kK), f);
    }
    const double fmax = max_abs(f);
    ASSERT_GT(fmax, 0);
    Vec3<double> sum = {0, 0, 0}, moment = {0, 0, 0};
    for (int a = 0; a < 4; ++a) {
      const Vec3<double> fa = {double(f[a].x), double(f[a].y), double(f[a].z)};
      const Vec3<double> xa = Xd[a] + Vec3<double>{double(u[a].x), double(u[a].y), double(u[a].z)};
      sum = sum + fa;
      moment = moment + cross(xa, fa);
    }
    EXPECT_LT(norm(sum), 10 * this->eps * fmax) << (ianp ? "IANP" : "plain");
    EXPECT_LT(norm(moment), 10 * this->eps * fmax * 0.05) << (ianp ? "IANP" : "plain");
  }
}

// With pbar = K (J - 1) of the element itself, Jbar = J and Fbar = F, so the
// IANP element reproduces the plain one (up to the rounding of J -> p -> Jbar).
TYPED_TEST(TetMath, IanpWithOwnPressureEqualsPlain) {
  using T = TypeParam;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> uni(-1, 1);
  Vec3<double> Xd[4];
  generic_tet(Xd);
  Vec3<T> X[4];
  for (int a = 0; a < 4; ++a) X[a] = cast<T>(Xd[a]);
  T dN[12];
  const T V = tet_shape_gradients(X, dN);
  for (int trial = 0; trial < 5; ++trial) {
    Vec3<T> u[4], fp[4], fi[4];
    for (auto& v : u) v = cast<T>(Vec3<double>{0.004 * uni(rng), 0.004 * uni(rng), 0.004 * uni(rng)});
    const T J = det(deformation_gradient(u, dN));
    const T pbar = volumetric_pressure(J, T(kK));
    EXPECT_EQ(plain_element_forces(u, dN, V, T(kMu), T(kK), fp), J);
    EXPECT_EQ(ianp_element_forces(u, dN, V, T(kMu), T(kK), pbar, fi), J);
    const double fmax = max_abs(fp);
    // J - 1 is a difference of O(1) numbers: the rounding of Jbar = 1 + p/K
    // is amplified by K / (mu J^(2/3)) in the stress; allow for it in float.
    const double tol = (std::is_same_v<T, float> ? 5e-4 : 1e-11) * fmax;
    for (int a = 0; a < 4; ++a)
      for (int i = 0; i < 3; ++i) EXPECT_NEAR(double(fi[a][i]), double(fp[a][i]), tol) << "corner " << a << " axis " << i;
  }
}

// Under a pure dilation F = s I the deviatoric part vanishes, so IANP with a
// neighbourhood pressure of zero gives no force at all, while the plain
// element pushes back with its own pressure.
TEST(TetMathDouble, IanpPureDilationWithZeroAveragePressure) {
  Vec3<double> X[4];
  generic_tet(X);
  double dN[12];
  const double V = tet_shape_gradients(X, dN);
  Vec3<double> u[4], f[4];
  homogeneous_displacement(X, 1.05 * Mat3<double>::identity(), {0, 0, 0}, u);
  plain_element_forces(u, dN, V, kMu, kK, f);
  const double f_plain = max_abs(f);
  EXPECT_GT(f_plain, 0);
  ianp_element_forces(u, dN, V, kMu, kK, 0.0, f);
  EXPECT_LT(max_abs(f), 1e-12 * f_plain);
}

TEST(TetMathDouble, BadElementsGiveZeroForceAndReportJ) {
  Vec3<double> X[4];
  corner_tet(X);
  double dN[12];
  const double V = tet_shape_gradients(X, dN);
  Vec3<double> u[4] = {{0, 0, 0}, {-2, 0, 0}, {0, 0, 0}, {0, 0, 0}};  // corner 1 pushed through: J = -1
  Vec3<double> f[4];
  EXPECT_NEAR(plain_element_forces(u, dN, V, kMu, kK, f), -1.0, 1e-15);
  EXPECT_EQ(max_abs(f), 0.0);
  EXPECT_NEAR(ianp_element_forces(u, dN, V, kMu, kK, 0.0, f), -1.0, 1e-15);
  EXPECT_EQ(max_abs(f), 0.0);
  // a good element with an averaged pressure that would need Jbar <= 0
  const Vec3<double> u0[4] = {};
  EXPECT_LE(ianp_element_forces(u0, dN, V, kMu, kK, -2 * kK, f), 0.0);
  EXPECT_EQ(max_abs(f), 0.0);
  // NaN displacement is reported, not hidden
  Vec3<double> un[4] = {{NAN, 0, 0}, {0, 0, 0}, {0, 0, 0}, {0, 0, 0}};
  EXPECT_TRUE(std::isnan(plain_element_forces(un, dN, V, kMu, kK, f)));
}

// ---------------------------------------------------------------- central difference

// core/cube_root.hpp: within 4 ulp of std::cbrt over the whole normal range
// (log-uniform samples, plus every value near 1 where J lives), exact on
// cubes of powers of two, and inputs below the smallest normal number are
// treated as that number (never NaN or Inf).
TYPED_TEST(TetMath, CubeRootMatchesStdCbrt) {
  using T = TypeParam;
  const double lo = std::log(double(std::numeric_limits<T>::min())), hi = std::log(double(std::numeric_limits<T>::max()));
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> unit_interval(0, 1);
  double worst = 0;
  for (int i = 0; i < 200000; ++i) {
    const T x = i < 2000 ? T(1) + T(i - 1000) * std::numeric_limits<T>::epsilon()
                         : T(std::exp(lo + (hi - lo) * unit_interval(rng)));
    const double want = std::cbrt(double(x));
    worst = std::max(worst, std::fabs(double(cube_root(x)) - want) / (want * std::numeric_limits<T>::epsilon()));
  }
  EXPECT_LE(worst, 4.0) << "worst error in ulp";
  EXPECT_EQ(cube_root(T(8)), T(2));
  EXPECT_EQ(cube_root(T(0.125)), T(0.5));
  EXPECT_EQ(cube_root(T(1)), T(1));
  const T tiny = std::numeric_limits<T>::min();
  EXPECT_EQ(cube_root(T(0)), cube_root(tiny));
  EXPECT_EQ(cube_root(tiny / T(1024)), cube_root(tiny));
  EXPECT_TRUE(std::isfinite(cube_root(T(0))));
}

TEST(CentralDifference, UndampedConstants) {
  const double m = 0.003, dt = 2e-4;
  const auto k = central_difference_constants(m, dt, 0.0);
  EXPECT_NEAR(k.A, dt * dt / m, 1e-15 * dt * dt / m);
  EXPECT_NEAR(k.B, 2.0, 1e-15);
  EXPECT_NEAR(k.C, -1.0, 1e-15);
}

// A free particle under a constant force, started on the parabola
// (u^0 = 0, u^{-1} = f dt^2 / (2m), i.e. v(0) = 0), samples u = f/m t^2/2
// exactly: the second difference of a quadratic is exact. Rounding of the
// two-term recursion accumulates like n^2 eps, hence 1e-10 after 1000 steps.
TEST(CentralDifference, ConstantForceSamplesParabola) {
  const double m = 0.002, dt = 1e-4, force = 0.05;
  const auto k = central_difference_constants(m, dt, 0.0);
  double u_prev = force / m * dt * dt / 2, u = 0;
  for (int n = 1; n <= 1000; ++n) {
    const double next = central_difference_update(k, force, u, u_prev);
    u_prev = u;
    u = next;
    const double t = n * dt;
    ASSERT_NEAR(u, force / m * t * t / 2, 1e-10 * force / m * t * t / 2) << "step " << n;
  }
}

// A damped oscillator m u'' + alpha m u' + k u = 0 (residual R - f = -k u)
// follows the exact solution to O(dt^2) and its amplitude decays.
TEST(CentralDifference, DampedOscillatorDecays) {
  const double m = 1.0, stiff = 4 * kPi * kPi, alpha = 0.8, dt = 1e-3;
  const double w0 = std::sqrt(stiff / m), zeta = alpha / (2 * w0), wd = w0 * std::sqrt(1 - zeta * zeta);
  auto exact = [&](double t) {
    return std::exp(-zeta * w0 * t) * (std::cos(wd * t) + zeta * w0 / wd * std::sin(wd * t));
  };
  const auto k = central_difference_constants(m, dt, alpha);
  EXPECT_GT(k.C, -1.0);  // damping shrinks the weight of u^{n-1}
  double u_prev = exact(-dt), u = exact(0);
  double max_err = 0, peak_late = 0;
  const int n_steps = 4000;  // 4 periods
  for (int n = 1; n <= n_steps; ++n) {
    const double next = central_difference_update(k, -stiff * u, u, u_prev);
    u_prev = u;
    u = next;
    max_err = std::max(max_err, std::fabs(u - exact(n * dt)));
    if (n > n_steps - 1000) peak_late = std::max(peak_late, std::fabs(u));
  }
  EXPECT_LT(max_err, 1e-3);
  // the envelope after 3..4 s is exp(-alpha t / 2) <= exp(-1.2) ~ 0.30
  EXPECT_LT(peak_late, std::exp(-alpha * 3.0 / 2) * 1.05);
  EXPECT_GT(peak_late, std::exp(-alpha * 4.0 / 2) * 0.95);
}

// Without force, damping turns an initial velocity v0 into a finite drift
// v0 / alpha (the velocity decays geometrically); undamped it never stops.
TEST(CentralDifference, DampedFreeParticleStops) {
  const double m = 1e-3, dt = 1e-4, alpha = 50, v0 = 0.01;
  const auto k = central_difference_constants(m, dt, alpha);
  double u_prev = -v0 * dt, u = 0;
  for (int n = 0; n < 20000; ++n) {
    const double next = central_difference_update(k, 0.0, u, u_prev);
    u_prev = u;
    u = next;
  }
  EXPECT_LT(std::fabs(u - u_prev) / dt, 1e-6 * v0);
  EXPECT_NEAR(u, v0 / alpha, 0.01 * v0 / alpha);
}

}  // namespace
}  // namespace tissue
