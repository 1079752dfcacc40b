// The kidney convergence study's parts (accuracy/convergence.hpp): the
// focused surface (a conformal map of the sphere, checked against its
// closed-form scale factors) and Richardson extrapolation (checked on
// values of a known power law), the largest change of slope along a
// force-depth curve (on curves whose kinks are known) and the slow press
// that gives the curve (the built-in kidney's, against its relaxed force).
// The study itself relaxes meshes of up to 130,000 tets: it runs as
// `tissue converge` (docs/contact.md section 5).
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "accuracy/convergence.hpp"
#include "io/kidney.hpp"
#include "scene/validate.hpp"

using namespace tissue;

namespace {

Vec3<double> vertex(const io::SurfaceMesh& s, index_t i) {
  return {s.vertices[3 * i], s.vertices[3 * i + 1], s.vertices[3 * i + 2]};
}

/// The unit sphere as a KidneyShape (no bean, no hilum).
io::KidneyShape unit_sphere() {
  io::KidneyShape k;
  k.a = k.b = k.c = 1;
  k.bean = k.hilum = 0;
  return k;
}

/// Mean edge of the triangles whose centroid direction lies within `angle`
/// (rad) of the unit direction e.
double mean_edge_near(const io::SurfaceMesh& s, Vec3<double> e, double angle) {
  double sum = 0;
  int n = 0;
  for (index_t t = 0; t < s.n_triangles(); ++t) {
    const Vec3<double> p[3] = {vertex(s, s.triangles[3 * t]), vertex(s, s.triangles[3 * t + 1]),
                               vertex(s, s.triangles[3 * t + 2])};
    const Vec3<double> c = p[0] + p[1] + p[2];
    if (dot(c, e) < std::cos(angle) * norm(c)) continue;
    for (int k = 0; k < 3; ++k) sum += norm(p[k] - p[(k + 1) % 3]);
    n += 3;
  }
  EXPECT_GT(n, 0);
  return sum / n;
}

/// Smallest interior angle over the triangles (rad).
double min_angle(const io::SurfaceMesh& s) {
  double m = std::numbers::pi;
  for (index_t t = 0; t < s.n_triangles(); ++t)
    for (int k = 0; k < 3; ++k) {
      const Vec3<double> a = vertex(s, s.triangles[3 * t + k]), b = vertex(s, s.triangles[3 * t + (k + 1) % 3]),
                         c = vertex(s, s.triangles[3 * t + (k + 2) % 3]);
      m = std::min(m, std::acos(dot(b - a, c - a) / (norm(b - a) * norm(c - a))));
    }
  return m;
}

}  // namespace

// The stereographic scaling z -> s z about the pole e is the Moebius map
// with length scale factor (1 + |z|^2) s / (1 + s^2 |z|^2): s at the pole
// (z = 0), 1 / s at the antipode (|z| -> infinity). Measured on a unit
// sphere of frequency 32: the mean edge within 20 degrees of each, against
// the uniform sphere's over the cap that maps there.
TEST(SurfaceFocus, EdgesScaleByTheFocusAtThePoleAndItsInverseOpposite) {
  const Vec3<double> e = {0.6, 0.0, 0.8};
  const io::SurfaceMesh uniform = io::kidney_surface(32, unit_sphere());
  for (double s : {0.5, 0.25}) {
    const io::SurfaceMesh focused = io::kidney_surface(32, unit_sphere(), {e, s});
    ASSERT_EQ(focused.n_vertices(), uniform.n_vertices());
    ASSERT_EQ(focused.triangles, uniform.triangles);
    const double angle = 20 * std::numbers::pi / 180;
    EXPECT_NEAR(mean_edge_near(focused, e, angle * s) / mean_edge_near(uniform, e, angle), s, 0.08 * s) << s;
    EXPECT_NEAR(mean_edge_near(focused, -1.0 * e, angle) / mean_edge_near(uniform, -1.0 * e, angle * s), 1 / s,
                0.08 / s)
        << s;
    for (index_t i = 0; i < focused.n_vertices(); ++i) ASSERT_NEAR(norm(vertex(focused, i)), 1.0, 1e-12) << i;
  }
}

// A conformal map keeps angles: the smallest triangle angle of the focused
// sphere stays within 3 degrees of the uniform one's even at focus 1/4 (a
// non-conformal pull towards the pole, such as moving every point along its
// great circle by the same fraction of its angle, squeezes the triangles
// around the pole radially and fails this).
TEST(SurfaceFocus, IsConformalNoSliversAppear) {
  const io::SurfaceMesh uniform = io::kidney_surface(16, unit_sphere());
  const io::SurfaceMesh focused = io::kidney_surface(16, unit_sphere(), {{0, 1, 0}, 0.25});
  EXPECT_GT(min_angle(focused), min_angle(uniform) - 3 * std::numbers::pi / 180);
}

// On the kidney shape every focused vertex still lies on the shape: x =
// s(p) (a p_x, b p_y, c p_z) with p its sphere direction.
TEST(SurfaceFocus, VerticesStayOnTheKidney) {
  const io::KidneyShape k;
  const io::SurfaceMesh s = io::kidney_surface(12, k, {{0, 1, 0}, 1.0 / 3.0});
  for (index_t i = 0; i < s.n_vertices(); ++i) {
    const Vec3<double> x = vertex(s, i), p = io::kidney_sphere_direction(k, x);
    const double r = io::kidney_radial_scale(k, p);
    ASSERT_NEAR(norm(x - Vec3<double>{r * k.a * p.x, r * k.b * p.y, r * k.c * p.z}), 0, 1e-12) << i;
  }
}

TEST(SurfaceFocus, BadFocusIsRefused) {
  for (double s : {0.0, -0.5, 1.5, std::nan("")})
    EXPECT_THROW(io::kidney_surface(6, io::KidneyShape{}, {{0, 1, 0}, s}), std::invalid_argument) << s;
  EXPECT_THROW(io::kidney_surface(6, io::KidneyShape{}, {{0, 0, 0}, 0.5}), std::invalid_argument);
}

TEST(Richardson, RecoversTheLimitAndOrderOfAPowerLaw) {
  for (const std::vector<double>& h : {std::vector<double>{8, 4, 2, 1}, std::vector<double>{8, 4.5, 2, 0.9}}) {
    std::vector<double> f;
    for (double x : h) f.push_back(0.08 + 0.01 * std::pow(x, 1.5));
    const accuracy::Extrapolation e = accuracy::richardson(h, f);
    EXPECT_TRUE(e.monotone);
    EXPECT_NEAR(e.value, 0.08, 1e-9);
    EXPECT_NEAR(e.order, 1.5, 1e-6);
  }
}

TEST(Richardson, NonMonotoneValuesGiveNoOrder) {
  const accuracy::Extrapolation e = accuracy::richardson({4, 2, 1}, {0.10, 0.08, 0.09});
  EXPECT_FALSE(e.monotone);
  EXPECT_EQ(e.value, 0.09);
  EXPECT_THROW(accuracy::richardson({1, 2, 4}, {1, 2, 3}), std::invalid_argument);
  EXPECT_THROW(accuracy::richardson({2, 1}, {1, 2}), std::invalid_argument);
}

// The focused kidney re-mesh: faces under the probe finer than the default
// mesh's, those on the far side no finer; another scene refuses a focus.
TEST(KidneyConvergence, FocusedRemeshRefinesUnderTheProbeOnly) {
  const scene::Scene base = io::default_kidney_scene();
  const scene::Scene s = accuracy::remesh_scene(base, io::KidneyScene::target_tets, {12, 0.5});
  const TissueModel<double> a = scene::load_model(base), b = scene::load_model(s);
  auto mean_edge = [](const TissueModel<double>& m, Vec3<double> dir) {
    auto X = [&](index_t i) { return Vec3<double>{m.X[i], m.X[m.n_nodes + i], m.X[2 * size_t(m.n_nodes) + i]}; };
    double sum = 0;
    int n = 0;
    for (index_t t = 0; t < m.n_tris; ++t) {
      const Vec3<double> p[3] = {X(m.tris[t]), X(m.tris[m.n_tris + t]), X(m.tris[2 * size_t(m.n_tris) + t])};
      const Vec3<double> c = p[0] + p[1] + p[2];
      if (dot(c, dir) < 0.95 * norm(c)) continue;
      for (int k = 0; k < 3; ++k) sum += norm(p[k] - p[(k + 1) % 3]);
      n += 3;
    }
    return sum / n;
  };
  // the probe presses the lateral side (+y); the far side is -y (the hilum)
  EXPECT_LT(mean_edge(b, {0, 1, 0}), 0.35 * mean_edge(a, {0, 1, 0}));
  EXPECT_GT(mean_edge(b, {0, -1, 0}), 0.7 * mean_edge(a, {0, -1, 0}));
  EXPECT_FALSE(s.constraints.front().nodes.empty());  // the hilum stays fixed
  scene::Scene other = base;
  other.source = "box.xml";
  EXPECT_THROW(accuracy::remesh_scene(other, 1000, {0, 0.5}), std::invalid_argument);
}

// The largest change of slope along a force-depth curve, on curves whose
// kinks are known: two straight pieces, a smooth power law, a first touch.
TEST(SlopeJump, FindsAKinkOfKnownSizeWhereItIs) {
  accuracy::PressCurve c;
  for (int k = 0; k <= 2500; ++k) {  // 2 um apart, as a 2 mm/s press read at 1 kHz
    const double d = 2e-6 * k;
    c.depth.push_back(d);
    // slope 10 N/m, then 13 from 2 mm (+30 %), then 13 x 0.58 from 3.25 mm (-42 %)
    c.force.push_back(1e-3 + (d < 2e-3 ? 10 * d : d < 3.25e-3 ? 0.02 + 13 * (d - 2e-3)
                                                               : 0.02 + 13 * 1.25e-3 + 13 * 0.58 * (d - 3.25e-3)));
  }
  const accuracy::SlopeJump j = accuracy::largest_slope_jump(c, 2.5e-4);
  EXPECT_NEAR(j.jump, -0.42, 1e-9);
  EXPECT_NEAR(j.depth, 3.25e-3, 2.1e-6);
  // without the second kink, the first
  c.force.resize(1626);
  c.depth.resize(1626);
  const accuracy::SlopeJump first = accuracy::largest_slope_jump(c, 2.5e-4);
  EXPECT_NEAR(first.jump, 0.30, 1e-9);
  EXPECT_NEAR(first.depth, 2e-3, 2.1e-6);
}

TEST(SlopeJump, ASmoothCurveHasOnlyItsOwnCurvatureAndTheFirstTouchIsNoKink) {
  // F = d^1.5 (Hertz): over windows w either side of d the slopes differ by about w / (2 d);
  // the largest where the force first reaches a tenth of its last, d = 5 mm x 0.1^(2/3)
  accuracy::PressCurve c;
  for (int k = 0; k <= 2500; ++k) {
    const double d = 2e-6 * k;
    c.depth.push_back(d);
    c.force.push_back(std::pow(d, 1.5));
  }
  const accuracy::SlopeJump j = accuracy::largest_slope_jump(c, 2.5e-4);
  const double d0 = 5e-3 * std::pow(0.1, 2.0 / 3.0);
  EXPECT_GT(j.jump, 0.0);
  EXPECT_NEAR(j.depth, d0, 2.5e-4 + 4e-6);
  EXPECT_NEAR(j.jump, 2.5e-4 / (2 * d0), 0.25 * 2.5e-4 / (2 * d0));
  // a press that first touches, at rest before: the rise from 0 is not counted
  accuracy::PressCurve touch;
  for (int k = 0; k <= 2500; ++k) {
    const double d = 2e-6 * k;
    touch.depth.push_back(d);
    touch.force.push_back(d < 1e-3 ? 0.0 : 10 * (d - 1e-3));
  }
  EXPECT_NEAR(accuracy::largest_slope_jump(touch, 2.5e-4).jump, 0.0, 1e-9);
  EXPECT_THROW(accuracy::largest_slope_jump(touch, 0), std::invalid_argument);
  touch.force.pop_back();
  EXPECT_THROW(accuracy::largest_slope_jump(touch, 2.5e-4), std::invalid_argument);
}

// The built-in kidney pressed slowly with its own solver: the curve ends at
// the relaxed reference force (0.09505 N, `tissue converge`'s default row,
// relaxed by another route), and its kinks, where nodes enter contact, are
// felt (measured: +59.9 % at 2.00 mm, docs/contact.md section 5).
TEST(SlowPress, TheDefaultKidneyEndsAtItsRelaxedForceAndItsMeshIsFelt) {
  const scene::Scene s = io::default_kidney_scene();
  const TissueModel<double> model = scene::load_model(s);
  const auto& path = s.tools.front().path;
  const accuracy::HeldTool held = accuracy::held_tool(model, scene::scheduler_settings(s).tools.front(), path,
                                                      s.solver.tick, accuracy::hold_start(path));
  const accuracy::PressCurve c = accuracy::slow_press(s, held, accuracy::kCurveSpeed);
  ASSERT_GT(c.depth.size(), 2000u);
  EXPECT_NEAR(c.depth.back(), 5e-3, 5e-5);
  EXPECT_NEAR(c.force.back(), 0.09505, 0.03 * 0.09505);
  for (std::size_t k = 100; k < c.force.size(); ++k) ASSERT_GT(c.force[k], c.force[k - 100]) << "at tick " << k;
  const accuracy::SlopeJump j = accuracy::largest_slope_jump(c, accuracy::kCurveWindow);
  RecordProperty("largest_slope_jump", std::to_string(j.jump));
  RecordProperty("at_mm", std::to_string(1e3 * j.depth));
  EXPECT_GT(std::fabs(j.jump), 0.3);
  EXPECT_THROW(accuracy::slow_press(s, held, 0), std::runtime_error);
}
