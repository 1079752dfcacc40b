// Segment vs triangle: the shared core math (core/tet.hpp segment_triangle)
// on hand-made cases, and the cpu backend's Embree query (cpu/
// embree_surface.hpp) on a box mesh: nearest hit, misses, the hit following
// the deformed surface, and agreement with a brute-force scan of every
// surface triangle through segment_triangle.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "core/box_mesh.hpp"
#include "core/tet.hpp"
#include "cpu/cpu_backend.hpp"
#include "cpu/host_backend.hpp"

namespace tissue {
namespace {

// ---------------------------------------------------------------- segment_triangle

template <class T>
class SegmentTriangle : public ::testing::Test {
 protected:
  // the unit right triangle in the plane z = 0
  const Vec3<T> P0{0, 0, 0}, P1{1, 0, 0}, P2{0, 1, 0};
  T bary[2] = {-9, -9};
  T hit(Vec3<T> a, Vec3<T> b) { return segment_triangle(a, b, P0, P1, P2, bary); }
  static constexpr T tol() { return std::is_same_v<T, float> ? T(1e-6) : T(1e-14); }
};
using Scalars = ::testing::Types<float, double>;
TYPED_TEST_SUITE(SegmentTriangle, Scalars);

TYPED_TEST(SegmentTriangle, HitInsideGivesFractionAndBarycentrics) {
  using T = TypeParam;
  const T t = this->hit({T(0.2), T(0.3), T(1)}, {T(0.2), T(0.3), T(-3)});
  EXPECT_NEAR(t, T(0.25), this->tol());
  EXPECT_NEAR(this->bary[0], T(0.2), this->tol());
  EXPECT_NEAR(this->bary[1], T(0.3), this->tol());
  // both sides of the triangle count
  EXPECT_NEAR(this->hit({T(0.2), T(0.3), T(-1)}, {T(0.2), T(0.3), T(1)}), T(0.5), this->tol());
  // an oblique segment
  EXPECT_NEAR(this->hit({T(0), T(0), T(1)}, {T(0.5), T(0.2), T(-1)}), T(0.5), this->tol());
  EXPECT_NEAR(this->bary[0], T(0.25), this->tol());
  EXPECT_NEAR(this->bary[1], T(0.1), this->tol());
}

TYPED_TEST(SegmentTriangle, MissBesideTheTriangle) {
  using T = TypeParam;
  EXPECT_LT(this->hit({T(0.6), T(0.6), T(1)}, {T(0.6), T(0.6), T(-1)}), T(0));    // past the hypotenuse
  EXPECT_LT(this->hit({T(-0.1), T(0.5), T(1)}, {T(-0.1), T(0.5), T(-1)}), T(0));  // left of the y edge
  EXPECT_LT(this->hit({T(2), T(2), T(1)}, {T(2), T(2), T(-1)}), T(0));
}

TYPED_TEST(SegmentTriangle, ThroughAnEdgeCounts) {
  using T = TypeParam;
  EXPECT_NEAR(this->hit({T(0.5), T(0), T(1)}, {T(0.5), T(0), T(-1)}), T(0.5), this->tol());  // edge P0 P1
  EXPECT_NEAR(this->bary[0], T(0.5), this->tol());
  EXPECT_EQ(this->bary[1], T(0));
  EXPECT_NEAR(this->hit({T(0.5), T(0.5), T(1)}, {T(0.5), T(0.5), T(-1)}), T(0.5), this->tol());  // hypotenuse
  EXPECT_NEAR(this->bary[0] + this->bary[1], T(1), this->tol());
}

TYPED_TEST(SegmentTriangle, ThroughAVertexCounts) {
  using T = TypeParam;
  EXPECT_NEAR(this->hit({T(1), T(0), T(1)}, {T(1), T(0), T(-1)}), T(0.5), this->tol());
  EXPECT_NEAR(this->bary[0], T(1), this->tol());
  EXPECT_NEAR(this->hit({T(0), T(0), T(2)}, {T(0), T(0), T(-2)}), T(0.5), this->tol());
  EXPECT_NEAR(this->bary[0], T(0), this->tol());
  EXPECT_NEAR(this->bary[1], T(0), this->tol());
}

TYPED_TEST(SegmentTriangle, ParallelSegmentsMiss) {
  using T = TypeParam;
  EXPECT_LT(this->hit({T(0.1), T(0.1), T(1)}, {T(0.8), T(0.1), T(1)}), T(0));  // above the plane
  EXPECT_LT(this->hit({T(0.1), T(0.1), T(0)}, {T(0.8), T(0.1), T(0)}), T(0));  // in the plane
}

TYPED_TEST(SegmentTriangle, SegmentEndingBeforeOrStartingAfterMisses) {
  using T = TypeParam;
  EXPECT_LT(this->hit({T(0.2), T(0.3), T(2)}, {T(0.2), T(0.3), T(1)}), T(0));    // stops above
  EXPECT_LT(this->hit({T(0.2), T(0.3), T(-1)}, {T(0.2), T(0.3), T(-2)}), T(0));  // starts below, goes away
  // ending exactly on the triangle is a hit at t = 1
  EXPECT_NEAR(this->hit({T(0.2), T(0.3), T(1)}, {T(0.2), T(0.3), T(0)}), T(1), this->tol());
}

// ---------------------------------------------------------------- cpu backend collide

constexpr double kL = 0.02;  // box edge (m)

TissueModel<double> box_model() {
  ModelInput in;
  box_mesh(in, 3, 3, 3, kL, kL, kL);
  const double E = 3000, nu = 0.45;
  in.materials = {{E / (2 * (1 + nu)), E / (3 * (1 - 2 * nu)), 1000}};
  in.source = "box";
  return build_model(in);
}

/// Brute force: every surface triangle through segment_triangle in double;
/// smallest t wins, ties to the lowest index. Returns (tri, t).
std::pair<index_t, double> brute_force(const TissueModel<double>& m, const std::vector<double>& u, Vec3<double> a,
                                       Vec3<double> b) {
  const index_t n = m.n_nodes, nt = m.n_tris;
  auto pos = [&](index_t i) {
    return Vec3<double>{m.X[i] + u[i], m.X[n + i] + u[n + i], m.X[2 * n + i] + u[2 * n + i]};
  };
  index_t best = -1;
  double best_t = std::numeric_limits<double>::infinity();
  for (index_t t = 0; t < nt; ++t) {
    double bary[2];
    const double s = segment_triangle(a, b, pos(m.tris[t]), pos(m.tris[nt + t]), pos(m.tris[2 * nt + t]), bary);
    if (s >= 0 && s < best_t) {
      best = t;
      best_t = s;
    }
  }
  return {best, best_t};
}

class Collide : public ::testing::TestWithParam<Precision> {
 protected:
  void SetUp() override {
    model = box_model();
    backend = make_cpu_backend(GetParam());
    backend->upload(model);
  }
  double tol() const { return GetParam() == Precision::Float ? 1e-6 : 1e-12; }  // in units of |AB| or m
  void expect_vec(Vec3<double> v, Vec3<double> want, double tol) const {
    EXPECT_NEAR(v.x, want.x, tol);
    EXPECT_NEAR(v.y, want.y, tol);
    EXPECT_NEAR(v.z, want.z, tol);
  }
  TissueModel<double> model;
  std::unique_ptr<Backend> backend;
};

INSTANTIATE_TEST_SUITE_P(Precisions, Collide, ::testing::Values(Precision::Float, Precision::Double),
                         [](const auto& info) { return std::string(to_string(info.param)); });

TEST_P(Collide, SegmentThroughTheBoxHitsTheNearFace) {
  const Vec3<double> top{0.0073, 0.0121, 0.05}, bottom{0.0073, 0.0121, -0.03};
  const Hit h = backend->collide(top, bottom);
  ASSERT_TRUE(h.hit());
  EXPECT_NEAR(h.t, (0.05 - kL) / 0.08, tol());
  expect_vec(h.point, {0.0073, 0.0121, kL}, tol());
  expect_vec(h.normal, {0, 0, 1}, tol());
  const index_t n = model.n_nodes;
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(h.nodes[k], model.tris[k * model.n_tris + h.tri]);
    EXPECT_EQ(model.X[2 * n + h.nodes[k]], kL);  // a top-face triangle
    expect_vec(h.u[k], {0, 0, 0}, 0);
  }
  // the barycentrics reproduce the point
  const Vec3<double> P0{model.X[h.nodes[0]], model.X[n + h.nodes[0]], model.X[2 * n + h.nodes[0]]};
  const Vec3<double> P1{model.X[h.nodes[1]], model.X[n + h.nodes[1]], model.X[2 * n + h.nodes[1]]};
  const Vec3<double> P2{model.X[h.nodes[2]], model.X[n + h.nodes[2]], model.X[2 * n + h.nodes[2]]};
  expect_vec(P0 + h.bary[0] * (P1 - P0) + h.bary[1] * (P2 - P0), h.point, tol());

  // the reversed segment enters through the bottom face
  const Hit r = backend->collide(bottom, top);
  ASSERT_TRUE(r.hit());
  EXPECT_NEAR(r.t, 0.03 / 0.08, tol());
  expect_vec(r.normal, {0, 0, -1}, tol());
  // and a segment from the side enters through x = 0
  const Hit s = backend->collide({-0.01, 0.005, 0.013}, {0.03, 0.006, 0.012});
  ASSERT_TRUE(s.hit());
  EXPECT_NEAR(s.t, 0.25, tol());
  expect_vec(s.normal, {-1, 0, 0}, tol());
}

TEST_P(Collide, MissesAndDegenerateSegments) {
  EXPECT_FALSE(backend->collide({0.03, 0.01, 0.05}, {0.03, 0.01, -0.05}).hit());    // beside the box
  EXPECT_FALSE(backend->collide({0.01, 0.01, 0.05}, {0.01, 0.01, 0.021}).hit());    // stops above the top
  EXPECT_FALSE(backend->collide({0.01, 0.01, 0.01}, {0.012, 0.011, 0.009}).hit());  // inside, crossing nothing
  EXPECT_FALSE(backend->collide({0.01, 0.01, 0.05}, {0.01, 0.01, 0.05}).hit());     // A == B
  EXPECT_THROW(backend->collide({std::nan(""), 0, 0}, {0, 0, 0}), std::invalid_argument);
}

TEST_P(Collide, HitFollowsTheDeformedSurface) {
  const index_t n = model.n_nodes;
  std::vector<double> u(3 * n, 0.0);
  // lift everything by 5 mm, and tilt the top: u_z += 0.25 x
  for (index_t i = 0; i < n; ++i) u[2 * n + i] = 0.005 + 0.25 * model.X[i];
  backend->set_displacements(u);
  const double x = 0.0073, y = 0.0121;
  const Hit h = backend->collide({x, y, 0.05}, {x, y, -0.03});
  ASSERT_TRUE(h.hit());
  const double z = kL + 0.005 + 0.25 * x;
  EXPECT_NEAR(h.t, (0.05 - z) / 0.08, 10 * tol());
  expect_vec(h.point, {x, y, z}, 10 * tol());
  const double s = 1.0 / std::sqrt(1 + 0.25 * 0.25);
  expect_vec(h.normal, {-0.25 * s, 0, s}, 10 * tol());
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(h.u[k].z, 0.005 + 0.25 * model.X[h.nodes[k]], tol());
  // a segment that stopped short of the undeformed top now reaches the lifted one
  EXPECT_TRUE(backend->collide({x, y, 0.05}, {x, y, 0.0245}).hit());
}

TEST_P(Collide, MatchesBruteForceOnRandomSegments) {
  const index_t n = model.n_nodes;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> coord(-0.01, 0.03), bump(-0.002, 0.002);
  std::vector<double> u(3 * n, 0.0);
  for (int round = 0; round < 2; ++round) {
    if (round == 1) {  // a rough deformation of every node
      for (auto& v : u) v = bump(rng);
      backend->set_displacements(u);
    }
    int hits = 0;
    for (int k = 0; k < 300; ++k) {
      const Vec3<double> a{coord(rng), coord(rng), coord(rng)}, b{coord(rng), coord(rng), coord(rng)};
      const auto [tri, t] = brute_force(model, u, a, b);
      const Hit h = backend->collide(a, b);
      ASSERT_EQ(h.tri, tri) << "segment " << k << " round " << round;
      if (tri < 0) continue;
      ++hits;
      EXPECT_NEAR(h.t, t, GetParam() == Precision::Float ? 1e-4 : 1e-12);
    }
    EXPECT_GT(hits, 100);  // the sample exercises the hit path
  }
}

TEST(CollideRefit, SceneIsRefitOnlyAfterDisplacementsChange) {
  const auto model = box_model();
  cpu::CpuBackend<double> b;
  b.upload(model);
  const Vec3<double> a{0.0073, 0.0121, 0.05}, c{0.0073, 0.0121, -0.03};
  b.collide(a, c);
  b.collide(a, c);
  EXPECT_EQ(b.surface_refits(), 1);
  b.advance(1);  // u may change: refit on the next query
  b.collide(a, c);
  b.collide(a, c);
  EXPECT_EQ(b.surface_refits(), 2);
  std::vector<double> u(3 * model.n_nodes, 0.001);
  b.set_displacements(u);
  EXPECT_NEAR(b.collide(a, c).point.z, kL + 0.001, 1e-12);
  EXPECT_EQ(b.surface_refits(), 3);
}

}  // namespace
}  // namespace tissue
