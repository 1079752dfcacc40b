// Tool contact, checked against brute force and hand-computed values:
// core/tool.hpp (interpolate_pose, contact_substeps), core/contact.hpp (the
// closest-point queries, node and face contact, the per-triangle sweep,
// grasp rotation, the contact reaction), core/node_rules.hpp (merge of the
// corner proposals, the per-node update and reduction terms), and
// segment_triangle (core/tet.hpp).
//
// Conventions of this file:
//  * typed over float and double where the header is a template;
//    std::mt19937 with fixed seeds, so every run sees the same cases;
//  * references are computed in long double by independent formulas
//    (projection onto the plane + clamped edge distances, the 2x2 system of
//    two lines), and checked again by brute force (dense sampling of both shapes);
//  * tolerances are multiples of the scalar's epsilon times the size of the
//    coordinates (the named helpers below say why each multiple);
//  * tests marked "FINDING" fail on the code as it stands: each reveals a bug
//    in the headers, with the exact inputs in its comment; they are left
//    failing on purpose until the header is fixed.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <type_traits>
#include <vector>

#include "core/contact.hpp"
#include "core/node_rules.hpp"
#include "core/tet.hpp"
#include "core/tool.hpp"
#include "tests/merge_lists.hpp"

namespace tissue {
namespace {

using Scalars = ::testing::Types<float, double>;

// ---------------------------------------------------------------- helpers

using LD = long double;
using VL = Vec3<LD>;
using VD = Vec3<double>;

template <class T>
constexpr double kEps = std::numeric_limits<T>::epsilon();

/// Round-off tolerance for a result of scale `scale` (the size of the
/// coordinates involved) after a short chain of dot/cross products: each
/// operation adds at most half an ulp, the closest-point formulas chain
/// about 10 of them and divide once, and differences of nearly equal
/// products double the relative error at most a few times. 64 ulps of the
/// scale is a safe margin for all of it and still 2e6 times smaller than
/// any geometric error these tests look for (float: 64 eps = 8e-6).
template <class T>
double tol(double scale, double ulps = 64) {
  return ulps * kEps<T> * scale;
}

template <class T>
VL L(Vec3<T> v) {
  return {LD(v.x), LD(v.y), LD(v.z)};
}
template <class T, class U>
Vec3<T> as(Vec3<U> v) {
  return {T(v.x), T(v.y), T(v.z)};
}
template <class T>
std::string str(Vec3<T> v) {
  std::ostringstream s;
  s.precision(std::is_same_v<T, float> ? 9 : 17);
  s << "{" << v.x << ", " << v.y << ", " << v.z << "}";
  return s.str();
}
template <class T>
double dist(Vec3<T> a, Vec3<T> b) {
  return double(norm(L(a) - L(b)));
}
template <class T>
double vmax(Vec3<T> v) {
  return std::max({std::fabs(double(v.x)), std::fabs(double(v.y)), std::fabs(double(v.z))});
}

struct Rng {
  std::mt19937 g;
  explicit Rng(unsigned seed) : g(seed) {}
  double uni(double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(g); }
  int integer(int lo, int hi) { return std::uniform_int_distribution<int>(lo, hi)(g); }
  VD vec(double lo = -1, double hi = 1) { return {uni(lo, hi), uni(lo, hi), uni(lo, hi)}; }
  VD unit() {
    for (;;) {
      const VD v = vec();
      const double n = norm(v);
      if (n > 0.1 && n <= 1) return (1.0 / n) * v;
    }
  }
  /// Barycentric weights, each >= lo.
  void weights(double w[3], double lo) {
    for (;;) {
      w[0] = uni(lo, 1);
      w[1] = uni(lo, 1);
      w[2] = 1 - w[0] - w[1];
      if (w[2] >= lo) return;
    }
  }
};

// ---- long double references (independent of the code under test)

LD ref_point_segment(VL a, VL b, VL x) {
  const VL d = b - a;
  const LD dd = dot(d, d);
  LD s = dd > 0 ? dot(x - a, d) / dd : 0;
  s = std::clamp<LD>(s, 0, 1);
  return norm(x - (a + s * d));
}

/// Point-triangle distance: the foot of the perpendicular if it falls in
/// the triangle, else the nearest of the three edges (also right for
/// degenerate triangles, which have no interior).
LD ref_point_triangle(VL x, VL P0, VL P1, VL P2) {
  LD best = std::min({ref_point_segment(P0, P1, x), ref_point_segment(P1, P2, x), ref_point_segment(P2, P0, x)});
  const VL n = cross(P1 - P0, P2 - P0);
  const LD nn = dot(n, n);
  if (nn > 0) {
    const VL p = x - (dot(x - P0, n) / nn) * n;
    const LD a0 = dot(cross(P1 - p, P2 - p), n) / nn, a1 = dot(cross(P2 - p, P0 - p), n) / nn;
    if (a0 >= 0 && a1 >= 0 && 1 - a0 - a1 >= 0) best = std::min(best, norm(x - p));
  }
  return best;
}

/// Segment-segment distance: the four end points against the other
/// segment, and the interior critical point of the two lines when both of
/// its parameters are inside (0, 1).
LD ref_segment_segment(VL p1, VL q1, VL p2, VL q2) {
  LD best = std::min({ref_point_segment(p2, q2, p1), ref_point_segment(p2, q2, q1), ref_point_segment(p1, q1, p2),
                      ref_point_segment(p1, q1, q2)});
  const VL d1 = q1 - p1, d2 = q2 - p2, r = p1 - p2;
  const LD a = dot(d1, d1), b = dot(d1, d2), e = dot(d2, d2), c = dot(d1, r), f = dot(d2, r);
  const LD den = a * e - b * b;
  if (den > 1e-30L * a * e) {
    const LD s = (b * f - c * e) / den, t = (a * f - b * c) / den;
    if (s > 0 && s < 1 && t > 0 && t < 1) best = std::min(best, norm((p1 + s * d1) - (p2 + t * d2)));
  }
  return best;
}

/// Segment-triangle distance: zero if the segment crosses the triangle,
/// else the least of the end points against the face and the edges against
/// the segment.
LD ref_segment_triangle(VL a, VL b, VL P0, VL P1, VL P2) {
  LD best =
      std::min({ref_point_triangle(a, P0, P1, P2), ref_point_triangle(b, P0, P1, P2), ref_segment_segment(a, b, P0, P1),
                ref_segment_segment(a, b, P1, P2), ref_segment_segment(a, b, P2, P0)});
  const VL n = cross(P1 - P0, P2 - P0);
  const LD da = dot(a - P0, n), db = dot(b - P0, n), nn = dot(n, n);
  if (nn > 0 && da != db && ((da <= 0 && db >= 0) || (da >= 0 && db <= 0))) {
    const VL x = a + (da / (da - db)) * (b - a);
    const LD a0 = dot(cross(P1 - x, P2 - x), n) / nn, a1 = dot(cross(P2 - x, P0 - x), n) / nn;
    if (a0 >= 0 && a1 >= 0 && 1 - a0 - a1 >= 0) best = 0;
  }
  return best;
}

// ---- brute force by sampling

/// Least distance from x to the points of a barycentric grid of n
/// intervals on the triangle. Every triangle point lies within
/// diameter / n of a grid point.
template <class T>
LD sampled_point_triangle(Vec3<T> x, const Vec3<T> P[3], int n) {
  LD best = INFINITY;
  for (int i = 0; i <= n; ++i)
    for (int j = 0; i + j <= n; ++j) {
      const LD u = LD(i) / n, v = LD(j) / n;
      const VL s = (1 - u - v) * L(P[0]) + u * L(P[1]) + v * L(P[2]);
      best = std::min(best, norm(L(x) - s));
    }
  return best;
}

/// Least distance between n + 1 samples of each segment; every point of a
/// segment lies within |d| / (2 n) of a sample.
template <class T>
LD sampled_segment_segment(Vec3<T> p1, Vec3<T> q1, Vec3<T> p2, Vec3<T> q2, int n) {
  LD best = INFINITY;
  for (int i = 0; i <= n; ++i) {
    const VL a = L(p1) + (LD(i) / n) * (L(q1) - L(p1));
    for (int j = 0; j <= n; ++j) best = std::min(best, norm(a - (L(p2) + (LD(j) / n) * (L(q2) - L(p2)))));
  }
  return best;
}

template <class T>
LD sampled_segment_triangle(Vec3<T> a, Vec3<T> b, const Vec3<T> P[3], int n_seg, int n_tri) {
  LD best = INFINITY;
  for (int i = 0; i <= n_seg; ++i) {
    const VL x = L(a) + (LD(i) / n_seg) * (L(b) - L(a));
    for (int p = 0; p <= n_tri; ++p)
      for (int q = 0; p + q <= n_tri; ++q) {
        const LD u = LD(p) / n_tri, v = LD(q) / n_tri;
        best = std::min(best, norm(x - ((1 - u - v) * L(P[0]) + u * L(P[1]) + v * L(P[2]))));
      }
  }
  return best;
}

/// Distance from x to the capsule's axis segment (long double).
template <class T>
double axis_distance(const Capsule<T>& cap, Vec3<T> x) {
  return double(ref_point_segment(L(cap.a), L(cap.b), L(x)));
}

template <class T>
double diameter(const Vec3<T> P[3]) {
  return std::max({dist(P[0], P[1]), dist(P[1], P[2]), dist(P[2], P[0])});
}

/// Smallest altitude over the longest edge: 1 for a fat triangle, 0 for a
/// degenerate one.
template <class T>
double flatness(const Vec3<T> P[3]) {
  const double d = diameter(P);
  const double area2 = double(norm(cross(L(P[1]) - L(P[0]), L(P[2]) - L(P[0]))));
  return d > 0 ? area2 / (d * d) : 0;
}

template <class T>
Vec3<T> outward(const Vec3<T> P[3]) {
  return unit_or(cross(P[1] - P[0], P[2] - P[0]), Vec3<T>{T(0), T(0), T(0)});
}

/// One tool over one advance of `steps` TLED steps.
template <class T>
ContactTools<T> one_tool(VD tip0, VD axis0, VD tip1, VD axis1, double r, double shaft, int substeps, int steps = 1,
                         int face = 1) {
  ContactTools<T> c{};
  c.n_tools = 1;
  c.steps = steps;
  c.face = face;
  ToolStep<T>& t = c.tool[0];
  t.tip0 = as<T>(tip0);
  t.axis0 = as<T>(axis0);
  t.tip1 = as<T>(tip1);
  t.axis1 = as<T>(axis1);
  t.radius = T(r);
  t.shaft = T(shaft);
  t.substeps = substeps;
  t.grasping = 0;
  t.grasp_tip = t.tip0;
  t.grasp_axis = t.axis0;
  return c;
}

/// A tool that stays at one pose for the whole advance.
template <class T>
ContactTools<T> static_tool(VD tip, VD axis, double r, double shaft, int substeps = 1) {
  return one_tool<T>(tip, axis, tip, axis, r, shaft, substeps);
}

/// Runs sweep_triangle and returns the corners after it in y.
template <class T>
void sweep(const ContactTools<T>& tools, int k, const Vec3<T> x[3], const std::uint8_t block[3],
           CornerContact<T> out[3], Vec3<T> y[3]) {
  sweep_triangle(tools, k, x, block, out);
  for (int i = 0; i < 3; ++i) y[i] = x[i] + out[i].dx;
}

/// The capsule of the last sub-check of the last step of an advance.
template <class T>
Capsule<T> last_capsule(const ContactTools<T>& tools, int t = 0) {
  return tool_capsule(tools.tool[t], tools.steps, tools.steps - 1, tools.tool[t].substeps);
}

/// Distance between the triangle and the capsule axis (the deepest point's).
template <class T>
double deepest_distance(const Capsule<T>& cap, const Vec3<T> P[3]) {
  T w[3];
  Vec3<T> c;
  const Vec3<T> q = triangle_deepest_point(cap, P, w, c);
  return dist(q, c);
}

/// The face allowance of face contact (face_allowance in core/contact.hpp,
/// docs: the sagitta of the face's circumcircle on a sphere of radius r,
/// at most 5 % of r), computed independently in long double from the edge
/// lengths: circumradius rho = a b c / (4 area), 16 area^2 by Heron's
/// formula in Kahan's ordering (a >= b >= c, stable for thin faces); the
/// sagitta r - sqrt(r^2 - rho^2) (64 bits of mantissa: no cancellation
/// worth the name for rho >= 1e-6 r); the cap 0.05 r where that is larger,
/// where rho >= r, or for a degenerate face.
template <class T>
double ref_allowance(const Vec3<T> P[3], double r) {
  LD e[3] = {norm(L(P[1]) - L(P[0])), norm(L(P[2]) - L(P[1])), norm(L(P[0]) - L(P[2]))};
  std::sort(e, e + 3, [](LD u, LD v) { return u > v; });
  const LD a = e[0], b = e[1], c = e[2], R = r, cap = LD(0.05) * R;
  const LD area16 = (a + (b + c)) * (c - (a - b)) * (c + (a - b)) * (a + (b - c));  // 16 area^2
  if (!(area16 > 0)) return double(cap);
  const LD rho = a * b * c / std::sqrt(area16);
  if (!(rho < R)) return double(cap);
  return double(std::min(R - std::sqrt(R * R - rho * rho), cap));
}

/// How close face contact lets the face come to the axis: r - the allowance.
template <class T>
double ref_reach(const Vec3<T> P[3], double r) {
  return r - ref_allowance(P, r);
}

// ---------------------------------------------------------------- segment_triangle (core/tet.hpp)

template <class T>
class SegmentTriangle : public ::testing::Test {
 protected:
  // the unit right triangle in the plane z = 0
  const Vec3<T> P0{0, 0, 0}, P1{1, 0, 0}, P2{0, 1, 0};
  T bary[2] = {-9, -9};
  T hit(Vec3<T> a, Vec3<T> b) { return segment_triangle(a, b, P0, P1, P2, bary); }
  static constexpr T tol() { return std::is_same_v<T, float> ? T(1e-6) : T(1e-14); }
};
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

// ---------------------------------------------------------------- closest_on_triangle

enum class Shape { Generic, Obtuse, Thin };

/// A random triangle in [-1, 1]^3. Generic: flatness >= 0.05. Obtuse: one
/// angle between about 100 and 175 degrees (flatness 0.03 to 0.3). Thin:
/// altitude / longest edge = rel (a sliver along P0 P1; the third corner
/// may lie beyond either end, so it is obtuse too).
template <class T>
void random_triangle(Rng& rng, Shape shape, Vec3<T> P[3], double rel = 0.01) {
  for (;;) {
    const VD a = rng.vec(), b = rng.vec(), e = b - a;
    VD c = rng.vec();
    const VD perp = unit_or(cross(e, rng.unit()), VD{0, 0, 1});
    if (shape == Shape::Obtuse) c = a + rng.uni(0.15, 0.85) * e + (rng.uni(0.03, 0.3) * norm(e)) * perp;
    if (shape == Shape::Thin) c = a + rng.uni(-0.5, 1.5) * e + (rel * norm(e)) * perp;
    const int k = rng.integer(0, 2);  // the special corner is any of the three
    const VD v[3] = {a, b, c};
    for (int i = 0; i < 3; ++i) P[i] = as<T>(v[(i + k) % 3]);
    if (shape == Shape::Thin || (norm(e) > 0.2 && flatness(P) >= (shape == Shape::Generic ? 0.05 : 0.02))) return;
  }
}

/// A query point: anywhere around the triangle, or just off its plane
/// (the face region, where the answer is the foot of the perpendicular).
template <class T>
Vec3<T> random_query(Rng& rng, const Vec3<T> P[3]) {
  if (rng.uni(0, 1) < 0.5) return as<T>(rng.vec(-2, 2));
  double w[3];
  rng.weights(w, -0.2);
  const VD p = w[0] * as<double>(P[0]) + w[1] * as<double>(P[1]) + w[2] * as<double>(P[2]);
  return as<T>(p + rng.uni(-0.3, 0.3) * as<double>(outward(P)));
}

/// The common start of the sweep's random cases: a generic face P, a tool
/// radius r in [r_lo, r_hi], and the face point q0 at barycentric weights w0
/// (each >= w_min), with the face's outward normal N.
template <class T>
struct FacePoint {
  Vec3<T> P[3];
  double r;
  double w0[3];
  VD N, q0;
};

template <class T>
FacePoint<T> random_face_point(Rng& rng, double r_lo, double r_hi, double w_min) {
  FacePoint<T> f;
  random_triangle(rng, Shape::Generic, f.P);
  f.r = rng.uni(r_lo, r_hi);
  rng.weights(f.w0, w_min);
  f.N = as<double>(outward(f.P));
  f.q0 = f.w0[0] * as<double>(f.P[0]) + f.w0[1] * as<double>(f.P[1]) + f.w0[2] * as<double>(f.P[2]);
  return f;
}

template <class T>
class ClosestOnTriangle : public ::testing::Test {};
TYPED_TEST_SUITE(ClosestOnTriangle, Scalars);

/// The rounding of the region tests and of the face weights (ratios of
/// differences of products over den ~ (2 area)^2) grows like
/// 1 / flatness^2 (measured: 0.7 eps x scale x (0.1 / flatness)^2 for
/// flatness 0.1 .. 0.001); 64 times that, and 64 ulps at least.
template <class T>
double triangle_tol(double scale, const Vec3<T> P[3]) {
  const double f = flatness(P);
  return tol<T>(scale) * std::max(1.0, (0.1 / f) * (0.1 / f));
}

TYPED_TEST(ClosestOnTriangle, MatchesBruteForceOnRandomTriangles) {
  using T = TypeParam;
  Rng rng(11);
  int sampled = 0;
  for (int it = 0; it < 6000; ++it) {
    Vec3<T> P[3];
    const Shape shape = it % 3 == 0 ? Shape::Generic : (it % 3 == 1 ? Shape::Obtuse : Shape::Thin);
    random_triangle(rng, shape, P, std::pow(10.0, rng.uni(-2, -1)));
    const Vec3<T> x = random_query(rng, P);
    T w[3] = {-9, -9, -9};
    const Vec3<T> q = closest_on_triangle(x, P[0], P[1], P[2], w);
    const double scale = std::max({vmax(x), vmax(P[0]), vmax(P[1]), vmax(P[2]), 1.0});
    const std::string where = "triangle " + str(P[0]) + " " + str(P[1]) + " " + str(P[2]) + " x " + str(x);
    // the weights are barycentric and reproduce the point
    for (int k = 0; k < 3; ++k) {
      EXPECT_GE(double(w[k]), -tol<T>(1)) << where;
      EXPECT_LE(double(w[k]), 1 + tol<T>(1)) << where;
    }
    EXPECT_NEAR(double(w[0]) + double(w[1]) + double(w[2]), 1.0, tol<T>(1)) << where;
    EXPECT_LE(dist(w[0] * P[0] + w[1] * P[1] + w[2] * P[2], q), tol<T>(scale)) << where;
    // its distance is the least distance (long double reference)
    const double d = dist(x, q);
    const double ref = double(ref_point_triangle(L(x), L(P[0]), L(P[1]), L(P[2])));
    ASSERT_NEAR(d, ref, triangle_tol(scale, P)) << where;
    // and no sample of a dense barycentric grid is closer; the nearest
    // sample is within diameter / n of it
    if (it % 20 == 0) {
      const int n = 60;
      const double sampled_min = double(sampled_point_triangle(x, P, n));
      EXPECT_LE(d, sampled_min + triangle_tol(scale, P)) << where;
      EXPECT_LE(sampled_min, d + diameter(P) / n) << where;
      ++sampled;
    }
  }
  EXPECT_EQ(sampled, 300);
}

TYPED_TEST(ClosestOnTriangle, VertexEdgeAndFaceRegions) {
  using T = TypeParam;
  const Vec3<T> P0{0, 0, 0}, P1{2, 0, 0}, P2{0, 2, 0};
  const double t = tol<T>(2);
  T w[3];
  // vertex regions
  EXPECT_LE(dist(closest_on_triangle(Vec3<T>{-1, -1, 1}, P0, P1, P2, w), P0), t);
  EXPECT_EQ(w[0], T(1));
  EXPECT_LE(dist(closest_on_triangle(Vec3<T>{3, -1, 0}, P0, P1, P2, w), P1), t);
  EXPECT_EQ(w[1], T(1));
  EXPECT_LE(dist(closest_on_triangle(Vec3<T>{-1, 3, -2}, P0, P1, P2, w), P2), t);
  EXPECT_EQ(w[2], T(1));
  // edge regions
  EXPECT_LE(dist(closest_on_triangle(Vec3<T>{T(0.5), -1, 1}, P0, P1, P2, w), Vec3<T>{T(0.5), 0, 0}), t);
  EXPECT_NEAR(double(w[0]), 0.75, t);
  EXPECT_NEAR(double(w[1]), 0.25, t);
  EXPECT_EQ(w[2], T(0));
  EXPECT_LE(dist(closest_on_triangle(Vec3<T>{2, 2, 1}, P0, P1, P2, w), Vec3<T>{1, 1, 0}), t);  // hypotenuse
  EXPECT_NEAR(double(w[1]), 0.5, t);
  EXPECT_NEAR(double(w[2]), 0.5, t);
  EXPECT_EQ(w[0], T(0));
  // face: the foot of the perpendicular
  EXPECT_LE(dist(closest_on_triangle(Vec3<T>{T(0.5), T(0.25), -3}, P0, P1, P2, w), Vec3<T>{T(0.5), T(0.25), 0}), t);
  EXPECT_NEAR(double(w[0]), 0.625, t);
  EXPECT_NEAR(double(w[1]), 0.25, t);
  EXPECT_NEAR(double(w[2]), 0.125, t);
}

// FINDING (closest_on_triangle, both precisions): "Works on degenerate
// triangles" does not hold once a triangle is flat to within rounding
// (altitude / longest edge below about 1e-5 in float, 1e-13 in double, and
// exactly collinear corners given as rounded coordinates): the region tests
// (vc, vb, va) then have signs that are pure rounding noise, the code falls
// through to the face branch with den = va + vb + vc a tiny positive noise
// value, and v = vb / den, u = vc / den are arbitrary weights in [0, 1]. The
// returned point is a valid point of the triangle but can be the triangle's
// size away from the closest one. Before that the accuracy already decays
// like eps / flatness^2 (float: 1e-3 of the size at altitude / edge = 1e-3;
// MatchesBruteForceOnRandomTriangles allows for it down to 1e-2). Float
// repro (the second case below):
//   P0 {-0.645369947f, -0.238590643f, 0.821449041f}
//   P1 { 0.594521463f,  0.743571401f, 0.508604109f}
//   P2 {-1.70432103f,  -1.07742333f,  1.08863974f}   (on line P0 P1 to 1e-7)
//   x  {-1.20364833f,  -0.510977924f, 1.79831135f}
//   expected |x - q| = 0.851053 (edge P2 P0), got 1.572438 with
//   w = (2/3, 1/3, 0), i.e. the face branch.
// A fix: accept the face branch only when den is not negligible against
// |ab|^2 |ac|^2 (say den > 1e3 eps |ab|^2 |ac|^2), else return the nearest
// of the three edge points (closest_on_segment on each edge).
TYPED_TEST(ClosestOnTriangle, NearlyDegenerateTrianglesGiveTheNearestEdgePoint) {
  using T = TypeParam;
  const auto check = [](Vec3<T> x, const Vec3<T> P[3], const std::string& what) {
    T w[3];
    const Vec3<T> q = closest_on_triangle(x, P[0], P[1], P[2], w);
    const double scale = std::max({vmax(x), vmax(P[0]), vmax(P[1]), vmax(P[2]), 1.0});
    // a flat triangle's closest point is (to within its altitude) on an edge
    const double edges =
        double(std::min({ref_point_segment(L(P[0]), L(P[1]), L(x)), ref_point_segment(L(P[1]), L(P[2]), L(x)),
                         ref_point_segment(L(P[2]), L(P[0]), L(x))}));
    const std::string where = what + ": triangle " + str(P[0]) + " " + str(P[1]) + " " + str(P[2]) + " x " + str(x) +
                              " w " + std::to_string(double(w[0])) + " " + std::to_string(double(w[1])) + " " +
                              std::to_string(double(w[2]));
    EXPECT_NEAR(double(w[0]) + double(w[1]) + double(w[2]), 1.0, tol<T>(1)) << where;
    EXPECT_LE(dist(w[0] * P[0] + w[1] * P[1] + w[2] * P[2], q), tol<T>(scale)) << where;
    EXPECT_LE(dist(x, q), edges + tol<T>(scale)) << where;
    return dist(x, q) <= edges + tol<T>(scale);
  };
  // exactly degenerate, with exactly representable coordinates: coincident
  // corners and a corner on the line, between or beyond the others
  {
    const Vec3<T> P[3] = {{0, 0, 0}, {1, 0, 0}, {-1, 0, 0}};
    check(Vec3<T>{T(-0.5), 1, 0}, P, "collinear, P2 beyond P0");
    check(Vec3<T>{T(0.5), 1, 0}, P, "collinear, over edge P0 P1");
    const Vec3<T> Q[3] = {{0, 0, 0}, {1, 1, 0}, {0, 0, 0}};
    check(Vec3<T>{1, 0, 0}, Q, "two coincident corners");
    const Vec3<T> R[3] = {{1, 2, 3}, {1, 2, 3}, {1, 2, 3}};
    check(Vec3<T>{0, 0, 0}, R, "a point");
  }
  if constexpr (std::is_same_v<T, float>) {  // the two repro cases of the comment above
    const Vec3<T> A[3] = {{0.573548913f, 0.488350898f, -0.896698534f},
                          {0.897429109f, -0.432841748f, 0.824708641f},
                          {0.252454877f, 1.40161717f, -2.6032877f}};
    check(Vec3<T>{0.455551207f, 0.911185205f, -1.57017672f}, A, "repro 1");  // 0.0567 expected, 0.160 returned
    const Vec3<T> B[3] = {{-0.645369947f, -0.238590643f, 0.821449041f},
                          {0.594521463f, 0.743571401f, 0.508604109f},
                          {-1.70432103f, -1.07742333f, 1.08863974f}};
    check(Vec3<T>{-1.20364833f, -0.510977924f, 1.79831135f}, B, "repro 2");  // 0.851 expected, 1.572 returned
  }
  // random slivers flat to within rounding
  Rng rng(12);
  const int k_lo = std::is_same_v<T, float> ? 6 : 14, k_hi = std::is_same_v<T, float> ? 9 : 17;
  int wrong = 0, n = 0;
  for (int it = 0; it < 4000; ++it, ++n) {
    Vec3<T> P[3];
    random_triangle(rng, Shape::Thin, P, std::pow(10.0, -rng.uni(k_lo, k_hi)));
    if (!check(as<T>(rng.vec(-2, 2)), P, "random sliver " + std::to_string(it))) {
      if (++wrong >= 5) break;  // enough to show it
    }
  }
  EXPECT_EQ(wrong, 0) << "of " << n << " random slivers";
}

// ---------------------------------------------------------------- closest_segment_segment

template <class T>
class ClosestSegmentSegment : public ::testing::Test {};
TYPED_TEST_SUITE(ClosestSegmentSegment, Scalars);

/// Tolerance on the distance at (s, t): 64 ulps of the scale, plus the
/// conditioning of the two-line solution. den = |d1|^2 |d2|^2 sin^2(angle)
/// carries an absolute rounding of eps |d1|^2 |d2|^2, so s has an error of
/// about eps / sin^2; along s the distance between two lines changes at the
/// rate |d1| sin, so the distance is off by eps |d1| / sin. Once sin^2 <
/// eps, den is noise and s may be anything in [0, 1]: the error is then at
/// most the lines' divergence over a segment, L sin < L sqrt(eps). Hence
/// 4 eps L / max(sin, sqrt(eps)), L = |d1| + |d2|.
template <class T>
double segment_tol(Vec3<T> p1, Vec3<T> q1, Vec3<T> p2, Vec3<T> q2) {
  const VL d1 = L(q1) - L(p1), d2 = L(q2) - L(p2);
  const double l1 = double(norm(d1)), l2 = double(norm(d2));
  const double scale = std::max({vmax(p1), vmax(q1), vmax(p2), vmax(q2), 1.0});
  const double sine = l1 > 0 && l2 > 0 ? double(norm(cross(d1, d2))) / (l1 * l2) : 1.0;
  return tol<T>(scale) + 4 * kEps<T> * (l1 + l2) / std::max(sine, std::sqrt(kEps<T>));
}

template <class T>
double pair_distance(Vec3<T> p1, Vec3<T> q1, Vec3<T> p2, Vec3<T> q2, T s, T t) {
  return double(norm((L(p1) + LD(s) * (L(q1) - L(p1))) - (L(p2) + LD(t) * (L(q2) - L(p2)))));
}

TYPED_TEST(ClosestSegmentSegment, MatchesBruteForceOnRandomSegments) {
  using T = TypeParam;
  Rng rng(21);
  for (int it = 0; it < 4000; ++it) {
    const Vec3<T> p1 = as<T>(rng.vec()), q1 = as<T>(rng.vec());
    Vec3<T> p2 = as<T>(rng.vec()), q2 = as<T>(rng.vec());
    if (it % 4 == 3) {  // nearly parallel, angle 1e-1 .. 1e-8
      const VD d = as<double>(q1) - as<double>(p1);
      q2 = as<T>(as<double>(p2) + rng.uni(-2, 2) * d + std::pow(10.0, -rng.uni(1, 8)) * norm(d) * rng.unit());
    }
    T s = -9, t = -9;
    closest_segment_segment(p1, q1, p2, q2, s, t);
    const std::string where = str(p1) + " " + str(q1) + " / " + str(p2) + " " + str(q2);
    ASSERT_TRUE(s >= T(0) && s <= T(1) && t >= T(0) && t <= T(1)) << where;
    const double d = pair_distance(p1, q1, p2, q2, s, t);
    const double ref = double(ref_segment_segment(L(p1), L(q1), L(p2), L(q2)));
    ASSERT_NEAR(d, ref, segment_tol(p1, q1, p2, q2)) << where;
    if (it % 20 == 0) {  // brute force: no pair of samples is closer; the nearest pair is within the spacing
      const int n = 150;
      const double sampled = double(sampled_segment_segment(p1, q1, p2, q2, n));
      EXPECT_LE(d, sampled + segment_tol(p1, q1, p2, q2)) << where;
      EXPECT_LE(sampled, d + (dist(p1, q1) + dist(p2, q2)) / (2 * n)) << where;
    }
  }
}

TYPED_TEST(ClosestSegmentSegment, ParallelCrossingAndZeroLength) {
  using T = TypeParam;
  const double e = tol<T>(4);
  T s, t;
  const auto run = [&](Vec3<T> p1, Vec3<T> q1, Vec3<T> p2, Vec3<T> q2) {
    closest_segment_segment(p1, q1, p2, q2, s, t);
    EXPECT_TRUE(s >= T(0) && s <= T(1) && t >= T(0) && t <= T(1));
    return pair_distance(p1, q1, p2, q2, s, t);
  };
  // parallel, overlapping in x over [0.5, 1]: any pair over the overlap is closest
  EXPECT_NEAR(run({0, 0, 0}, {1, 0, 0}, {T(0.5), 1, 0}, {2, 1, 0}), 1.0, e);
  EXPECT_NEAR(run({0, 0, 0}, {1, 0, 0}, {2, 1, 0}, {T(0.5), 1, 0}), 1.0, e);  // antiparallel
  // collinear and disjoint: the facing end points
  EXPECT_NEAR(run({0, 0, 0}, {1, 0, 0}, {3, 0, 0}, {2, 0, 0}), 1.0, e);
  EXPECT_NEAR(double(s), 1.0, e);
  EXPECT_NEAR(double(t), 1.0, e);
  // collinear and overlapping: distance 0
  EXPECT_NEAR(run({0, 0, 0}, {2, 0, 0}, {1, 0, 0}, {3, 0, 0}), 0.0, e);
  // parallel, side by side without overlap: end point to end point
  EXPECT_NEAR(run({0, 0, 0}, {1, 0, 0}, {2, 1, 0}, {3, 1, 0}), std::sqrt(2.0), e);
  // crossing: distance 0 at the crossing point
  EXPECT_NEAR(run({-1, 0, 0}, {1, 0, 0}, {T(0.2), -1, 0}, {T(0.2), 1, 0}), 0.0, e);
  EXPECT_NEAR(double(s), 0.6, e);
  EXPECT_NEAR(double(t), 0.5, e);
  // skew, crossing in projection: the common perpendicular
  EXPECT_NEAR(run({-1, 0, 0}, {1, 0, 0}, {T(0.2), -1, T(0.7)}, {T(0.2), 1, T(0.7)}), 0.7, e);
  EXPECT_NEAR(double(s), 0.6, e);
  // skew, the perpendicular's foot beyond an end: clamped
  EXPECT_NEAR(run({-1, 0, 0}, {1, 0, 0}, {3, -1, 1}, {3, 1, 1}), std::sqrt(5.0), e);
  EXPECT_EQ(s, T(1));
  // both of zero length: the two points
  EXPECT_NEAR(run({1, 2, 3}, {1, 2, 3}, {1, 2, 5}, {1, 2, 5}), 2.0, e);
  EXPECT_EQ(s, T(0));
  EXPECT_EQ(t, T(0));
  // the first of zero length: the point against the second segment
  EXPECT_NEAR(run({T(0.5), 1, 0}, {T(0.5), 1, 0}, {0, 0, 0}, {2, 0, 0}), 1.0, e);
  EXPECT_NEAR(double(t), 0.25, e);
  EXPECT_NEAR(run({-1, 1, 0}, {-1, 1, 0}, {0, 0, 0}, {2, 0, 0}), std::sqrt(2.0), e);
  EXPECT_EQ(t, T(0));
  // the second of zero length
  EXPECT_NEAR(run({0, 0, 0}, {2, 0, 0}, {T(1.5), 0, -1}, {T(1.5), 0, -1}), 1.0, e);
  EXPECT_NEAR(double(s), 0.75, e);
  EXPECT_EQ(t, T(0));
  EXPECT_NEAR(run({0, 0, 0}, {2, 0, 0}, {5, 0, 4}, {5, 0, 4}), 5.0, e);
  EXPECT_EQ(s, T(1));
}

// ---------------------------------------------------------------- triangle_deepest_point

template <class T>
class TriangleDeepestPoint : public ::testing::Test {};
TYPED_TEST_SUITE(TriangleDeepestPoint, Scalars);

/// segment_tol against the edge nearest to parallel with the axis (the
/// deepest point may come from the segment-segment query of any edge).
template <class T>
double deepest_tol(const Capsule<T>& cap, const Vec3<T> P[3]) {
  double t = 0;
  for (int e = 0; e < 3; ++e) t = std::max(t, segment_tol(cap.a, cap.b, P[e], P[(e + 1) % 3]));
  return t + triangle_tol(std::max({vmax(cap.a), vmax(cap.b), 1.0}), P);
}

TYPED_TEST(TriangleDeepestPoint, DistanceIsTheBruteForceAxisTriangleDistance) {
  using T = TypeParam;
  Rng rng(31);
  int pierced = 0;
  for (int it = 0; it < 3000; ++it) {
    Vec3<T> P[3];
    random_triangle(rng, it % 2 ? Shape::Generic : Shape::Obtuse, P);
    Capsule<T> cap{as<T>(rng.vec(-1.5, 1.5)), as<T>(rng.vec(-1.5, 1.5)), T(0.1)};
    if (it % 5 == 0) cap.b = cap.a;  // a sphere
    T w[3];
    Vec3<T> c;
    const Vec3<T> q = triangle_deepest_point(cap, P, w, c);
    const double scale = std::max({vmax(cap.a), vmax(cap.b), vmax(P[0]), vmax(P[1]), vmax(P[2]), 1.0});
    const std::string where =
        "triangle " + str(P[0]) + " " + str(P[1]) + " " + str(P[2]) + " axis " + str(cap.a) + " " + str(cap.b);
    // q is the triangle point of weights w, c a point of the axis
    EXPECT_NEAR(double(w[0]) + double(w[1]) + double(w[2]), 1.0, tol<T>(1)) << where;
    for (int k = 0; k < 3; ++k) EXPECT_GE(double(w[k]), -tol<T>(1)) << where;
    EXPECT_LE(dist(w[0] * P[0] + w[1] * P[1] + w[2] * P[2], q), tol<T>(scale)) << where;
    EXPECT_LE(axis_distance(cap, c), tol<T>(scale)) << where;
    // |q - c| is the least distance between the axis segment and the triangle
    const double d = dist(q, c);
    const double ref = double(ref_segment_triangle(L(cap.a), L(cap.b), L(P[0]), L(P[1]), L(P[2])));
    ASSERT_NEAR(d, ref, deepest_tol(cap, P)) << where;
    if (ref == 0) ++pierced;
    if (it % 30 == 0) {  // sampling both: none closer; the nearest samples within the spacings
      const int ns = 40, nt = 30;
      const double sampled = double(sampled_segment_triangle(cap.a, cap.b, P, ns, nt));
      EXPECT_LE(d, sampled + deepest_tol(cap, P)) << where;
      EXPECT_LE(sampled, d + dist(cap.a, cap.b) / (2 * ns) + diameter(P) / nt) << where;
    }
  }
  EXPECT_GT(pierced, 100);  // the sample covers the axis piercing the face
}

TYPED_TEST(TriangleDeepestPoint, AxisPiercingTheFaceGivesZeroAtThePiercingPoint) {
  using T = TypeParam;
  {
    const Vec3<T> P[3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
    const Capsule<T> cap{{T(0.2), T(0.3), -1}, {T(0.2), T(0.3), 1}, T(0.1)};
    T w[3];
    Vec3<T> c;
    const Vec3<T> q = triangle_deepest_point(cap, P, w, c);
    EXPECT_LE(dist(q, Vec3<T>{T(0.2), T(0.3), 0}), tol<T>(1));
    EXPECT_LE(dist(c, q), tol<T>(1));
    EXPECT_NEAR(double(w[0]), 0.5, tol<T>(1));
    EXPECT_NEAR(double(w[1]), 0.2, tol<T>(1));
    EXPECT_NEAR(double(w[2]), 0.3, tol<T>(1));
  }
  Rng rng(32);
  for (int it = 0; it < 1000; ++it) {
    Vec3<T> P[3];
    random_triangle(rng, Shape::Generic, P);
    double wx[3];
    rng.weights(wx, 0.05);
    const VD x = wx[0] * as<double>(P[0]) + wx[1] * as<double>(P[1]) + wx[2] * as<double>(P[2]);
    VD d = rng.unit();
    const double sine = std::fabs(dot(d, as<double>(outward(P))));
    if (sine < 0.2) continue;  // the piercing point of a grazing axis is ill-conditioned
    const Capsule<T> cap{as<T>(x - rng.uni(0.1, 1) * d), as<T>(x + rng.uni(0.1, 1) * d), T(0.1)};
    T w[3];
    Vec3<T> c;
    const Vec3<T> q = triangle_deepest_point(cap, P, w, c);
    const std::string where =
        "triangle " + str(P[0]) + " " + str(P[1]) + " " + str(P[2]) + " axis " + str(cap.a) + " " + str(cap.b);
    EXPECT_LE(dist(q, c), tol<T>(2)) << where;
    // the piercing point moves by (rounding of the corners) / sine
    EXPECT_LE(dist(q, as<T>(x)), tol<T>(2) / sine) << where;
  }
}

TYPED_TEST(TriangleDeepestPoint, SphereAndParallelAxis) {
  using T = TypeParam;
  const Vec3<T> P[3] = {{0, 0, 0}, {2, 0, 0}, {0, 2, 0}};
  T w[3], wt[3];
  Vec3<T> c;
  // a sphere (zero-length axis): the triangle point closest to its centre
  const Capsule<T> sphere{{T(0.3), T(-0.5), T(0.4)}, {T(0.3), T(-0.5), T(0.4)}, T(0.1)};
  const Vec3<T> q = triangle_deepest_point(sphere, P, w, c);
  const Vec3<T> qt = closest_on_triangle(sphere.a, P[0], P[1], P[2], wt);
  EXPECT_LE(dist(q, qt), tol<T>(2));
  EXPECT_LE(dist(c, sphere.a), tol<T>(2));
  // an axis parallel to the face over its interior (no piercing test possible): its height
  const Capsule<T> flat{{T(0.2), T(0.5), T(0.3)}, {T(1.2), T(0.5), T(0.3)}, T(0.1)};
  EXPECT_NEAR(deepest_distance(flat, P), 0.3, tol<T>(2));
  // an axis parallel to the face beyond its hypotenuse: to the hypotenuse
  const Capsule<T> beside{{T(2), T(1), T(-1)}, {T(2), T(1), T(1)}, T(0.1)};
  EXPECT_NEAR(deepest_distance(beside, P), std::sqrt(0.5), tol<T>(2));
}

// ---------------------------------------------------------------- push_out_of_capsule

template <class T>
class PushOutOfCapsule : public ::testing::Test {};
TYPED_TEST_SUITE(PushOutOfCapsule, Scalars);

TYPED_TEST(PushOutOfCapsule, InsidePointsEndOnTheSurfaceOutsidePointsStay) {
  using T = TypeParam;
  Rng rng(41);
  int inside = 0, outside = 0;
  for (int it = 0; it < 20000; ++it) {
    const double r = rng.uni(0.05, 0.5);
    Capsule<T> cap{as<T>(rng.vec()), as<T>(rng.vec()), T(r)};
    if (it % 4 == 0) cap.b = cap.a;  // spheres too
    const Vec3<T> x0 = as<T>(as<double>(cap.a) + rng.uni(0, 1) * (as<double>(cap.b) - as<double>(cap.a)) +
                             rng.uni(0, 2 * r) * rng.unit());
    const double d0 = axis_distance(cap, x0);
    if (std::fabs(d0 - r) < 1e-3 * r) continue;  // leave the boundary to the exact test below
    Vec3<T> x = x0, n{T(7), T(7), T(7)};
    const bool pushed = push_out_of_capsule(cap, x, n);
    const std::string where = "axis " + str(cap.a) + " " + str(cap.b) + " r " + std::to_string(r) + " x " + str(x0);
    if (d0 > r) {
      ++outside;
      EXPECT_FALSE(pushed) << where;
      EXPECT_TRUE(x.x == x0.x && x.y == x0.y && x.z == x0.z) << where;  // untouched, bit for bit
      EXPECT_EQ(n.x, T(7)) << where;
      continue;
    }
    ++inside;
    ASSERT_TRUE(pushed) << where;
    EXPECT_NEAR(double(norm(n)), 1.0, tol<T>(1)) << where;
    EXPECT_NEAR(axis_distance(cap, x), r, tol<T>(2)) << where;  // exactly on the surface
    // radially: it moved by r - d0 along n, away from its axis point
    EXPECT_LE(dist(x, x0 + T(r - d0) * n), tol<T>(2)) << where;
  }
  EXPECT_GT(inside, 5000);
  EXPECT_GT(outside, 5000);
}

TYPED_TEST(PushOutOfCapsule, OnTheSurfaceIsNotInside) {
  using T = TypeParam;
  const Capsule<T> cap{{0, 0, 0}, {0, 0, 1}, T(0.5)};
  Vec3<T> x{T(0.5), 0, T(0.5)}, n{};
  EXPECT_FALSE(push_out_of_capsule(cap, x, n));  // distance == r exactly
  Vec3<T> tip{0, 0, T(-0.5)};
  EXPECT_FALSE(push_out_of_capsule(cap, tip, n));
}

TYPED_TEST(PushOutOfCapsule, PointOnTheAxisGetsADeterministicDirection) {
  using T = TypeParam;
  const Capsule<T> cap{{0, 0, 0}, {0, 0, 2}, T(0.5)};  // axis +z
  // on the shaft: perpendicular to the axis (any_perpendicular(-z) = -y)
  Vec3<T> x{0, 0, 1}, n{};
  ASSERT_TRUE(push_out_of_capsule(cap, x, n));
  EXPECT_EQ(dot(n, Vec3<T>{0, 0, 1}), T(0));
  EXPECT_NEAR(double(n.y), -1.0, tol<T>(1));
  EXPECT_LE(dist(x, Vec3<T>{0, T(-0.5), 1}), tol<T>(1));
  Vec3<T> x2{0, 0, 1}, n2{};
  push_out_of_capsule(cap, x2, n2);
  EXPECT_TRUE(n2.x == n.x && n2.y == n.y && n2.z == n.z && x2.x == x.x && x2.y == x.y && x2.z == x.z);
  // at the tip: straight ahead, away from the handle
  Vec3<T> a{0, 0, 0};
  ASSERT_TRUE(push_out_of_capsule(cap, a, n));
  EXPECT_LE(dist(n, Vec3<T>{0, 0, -1}), tol<T>(1));
  EXPECT_LE(dist(a, Vec3<T>{0, 0, T(-0.5)}), tol<T>(1));
  // at the handle end: perpendicular
  Vec3<T> b{0, 0, 2};
  ASSERT_TRUE(push_out_of_capsule(cap, b, n));
  EXPECT_NEAR(double(dot(n, Vec3<T>{0, 0, 1})), 0.0, tol<T>(1));
  EXPECT_NEAR(axis_distance(cap, b), 0.5, tol<T>(1));
  // a sphere's centre: the fixed fallback -z
  const Capsule<T> sphere{{1, 1, 1}, {1, 1, 1}, T(0.5)};
  Vec3<T> s{1, 1, 1};
  ASSERT_TRUE(push_out_of_capsule(sphere, s, n));
  EXPECT_LE(dist(n, Vec3<T>{0, 0, -1}), 0.0);
  EXPECT_LE(dist(s, Vec3<T>{1, 1, T(0.5)}), tol<T>(1));
  // a slanted axis: the shaft direction is perpendicular and unit
  const Capsule<T> slant{{0, 0, 0}, {T(0.6), T(0.8), 0}, T(0.25)};
  Vec3<T> m{T(0.3), T(0.4), 0};
  ASSERT_TRUE(push_out_of_capsule(slant, m, n));
  EXPECT_NEAR(double(dot(n, Vec3<T>{T(0.6), T(0.8), 0})), 0.0, tol<T>(1));
  EXPECT_NEAR(double(norm(n)), 1.0, tol<T>(1));
  EXPECT_NEAR(axis_distance(slant, m), 0.25, tol<T>(1));
}

// ---------------------------------------------------------------- sweep_triangle

template <class T>
class SweepTriangle : public ::testing::Test {};
TYPED_TEST_SUITE(SweepTriangle, Scalars);

const std::uint8_t kFree[3] = {0, 0, 0};

TEST(CornerBlock, TruthTable) {
  for (int inner = 0; inner < 2; ++inner)
    for (int held = 0; held < 2; ++held)
      for (int grasped = 0; grasped < 2; ++grasped) {
        const std::uint8_t b = corner_block(inner, held, grasped);
        if (!inner)
          EXPECT_EQ(b, kOutsideRegion);
        else if (held || grasped)
          EXPECT_EQ(b, kRigidContact);
        else
          EXPECT_EQ(b, 0);
      }
}

/// Gradient length of beta(p) = sum_k lambda_k(p) w_k / sum_j w_j^2 over
/// the triangle's plane (lambda_k the barycentric coordinate functions):
/// the face-contact correction moves a point of the face by beta delta n.
template <class T>
double spread_gradient(const Vec3<T> P[3], const T w[3]) {
  const VL p[3] = {L(P[0]), L(P[1]), L(P[2])};
  const VL m = cross(p[1] - p[0], p[2] - p[0]);
  const LD area2 = norm(m);
  const VL N = (1 / area2) * m;
  LD wsum = 0;
  for (int k = 0; k < 3; ++k) wsum += LD(w[k]) * LD(w[k]);
  VL g{0, 0, 0};
  for (int k = 0; k < 3; ++k) g = g + (LD(w[k]) / wsum / area2) * cross(N, p[(k + 2) % 3] - p[(k + 1) % 3]);
  return double(norm(g));
}

TYPED_TEST(SweepTriangle, FarToolLeavesTheTriangleAlone) {
  using T = TypeParam;
  const Vec3<T> x[3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  const auto tools = one_tool<T>({0.3, 0.3, 2}, {0, 0, 1}, {0.3, 0.3, 0.6}, {0, 0, 1}, 0.5, 1, 4);
  CornerContact<T> out[3];
  Vec3<T> y[3];
  sweep(tools, 0, x, kFree, out, y);
  for (int i = 0; i < 3; ++i) {
    EXPECT_TRUE(out[i].dx.x == T(0) && out[i].dx.y == T(0) && out[i].dx.z == T(0));
    EXPECT_EQ(out[i].tool, -1);
    EXPECT_EQ(out[i].blocked, 0);
  }
}

TYPED_TEST(SweepTriangle, NodeContactPushesAnInsideCornerRadiallyToTheSurface) {
  using T = TypeParam;
  // corner P0 is inside a sphere above the face (outward normal +z)
  const Vec3<T> x[3] = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
  const VD centre{-0.1, -0.1, 0.2};
  const double r = 0.3;
  for (int face = 0; face < 2; ++face) {
    auto tools = static_tool<T>(centre, {0, 0, 1}, r, 0);
    tools.face = face;
    CornerContact<T> out[3];
    Vec3<T> y[3];
    sweep(tools, 0, x, kFree, out, y);
    const Capsule<T> cap = last_capsule(tools);
    // radially from the centre onto the sphere
    const VL radial = (LD(r) / norm(L(x[0]) - L(as<T>(centre)))) * (L(x[0]) - L(as<T>(centre)));
    if (face == 0) {
      EXPECT_LE(double(norm(L(y[0]) - (L(as<T>(centre)) + radial))), tol<T>(1));
    }
    EXPECT_NEAR(axis_distance(cap, y[0]), r, tol<T>(1));
    EXPECT_EQ(out[0].tool, 0);
    EXPECT_EQ(out[0].blocked, 0);
    if (face == 0)
      for (int i = 1; i < 3; ++i) {  // the others were outside: untouched
        EXPECT_TRUE(out[i].dx.x == T(0) && out[i].dx.y == T(0) && out[i].dx.z == T(0));
        EXPECT_EQ(out[i].tool, -1);
      }
    for (int i = 0; i < 3; ++i) EXPECT_GE(axis_distance(cap, y[i]), r - tol<T>(1));
  }
}

TYPED_TEST(SweepTriangle, FaceContactOffMeansNodeContactOnly) {
  using T = TypeParam;
  // a small sphere pressing into the middle of a big face, between its corners
  const Vec3<T> x[3] = {{-3, -3, 0}, {6, -3, 0}, {-3, 6, 0}};
  for (int face = 0; face < 2; ++face) {
    auto tools = static_tool<T>({0, 0, 0.2}, {0, 0, 1}, 0.5, 1);
    tools.face = face;
    CornerContact<T> out[3];
    Vec3<T> y[3];
    sweep(tools, 0, x, kFree, out, y);
    if (face == 0) {
      for (int i = 0; i < 3; ++i) EXPECT_TRUE(out[i].dx.x == T(0) && out[i].dx.y == T(0) && out[i].dx.z == T(0));
    } else {
      // the centroid (0, 0, 0) is the deepest point (0.2 from the tip, weights 1/3: the face translates). The face
      // is a right triangle with legs 9: circumradius = half the hypotenuse = 9 sqrt(2) / 2 = 6.36 >= r = 0.5, so
      // the allowance is the cap 0.05 r = 0.025 and the face stops 0.475 from the tip: down by 0.475 - 0.2 = 0.275
      for (int i = 0; i < 3; ++i) {
        EXPECT_LE(dist(out[i].dx, Vec3<T>{0, 0, T(-0.275)}), tol<T>(6));
        EXPECT_EQ(out[i].tool, 0);
      }
      EXPECT_NEAR(deepest_distance(last_capsule(tools), y), 0.475, tol<T>(6));
    }
  }
}

/// The tolerance of a spread correction dx_k = w_k delta n / sum w_j^2:
/// the rounding of w, delta and the positions, amplified by 1 / sum w^2
/// (large when only corners of small weight may move).
template <class T>
double spread_tol(double scale, double wsum) {
  return tol<T>(scale) * (1 + 1 / wsum);
}

TYPED_TEST(SweepTriangle, FaceContactMovesTheDeepestPointByExactlyDeltaAlongN) {
  using T = TypeParam;
  Rng rng(51);
  int cases = 0, with_blocked = 0, on_edge = 0;
  for (int it = 0; cases < 1500 && it < 200000; ++it) {
    Vec3<T> P[3];
    random_triangle(rng, Shape::Generic, P);
    const double r = rng.uni(0.03, 0.3);
    double w0[3];
    rng.weights(w0, 0.02);
    if (it % 5 == 0) {  // on an edge
      const int z = rng.integer(0, 2);
      w0[(z + 1) % 3] += w0[z];
      w0[z] = 0;
    }
    const VD N = as<double>(outward(P));
    const VD q0 = w0[0] * as<double>(P[0]) + w0[1] * as<double>(P[1]) + w0[2] * as<double>(P[2]);
    // the tool above q0 with its handle away from the face: its tip is the closest axis point
    VD axis = unit_or(N + 0.6 * rng.unit(), N);
    if (dot(axis, N) < 0.3) continue;
    const double depth = rng.uni(0.1, 0.9) * r;
    const auto tools = static_tool<T>(q0 + (r - depth) * N, axis, r, it % 3 ? rng.uni(0, 1) : 0);
    const Capsule<T> cap = last_capsule(tools);
    bool corner_inside = false;
    for (int i = 0; i < 3; ++i) corner_inside |= axis_distance(cap, P[i]) < r * 1.001;
    if (corner_inside) continue;  // node contact would act first
    std::uint8_t block[3] = {0, 0, 0};
    if (it % 3 == 0) {  // one or two corners blocked, either kind
      const int b0 = rng.integer(0, 2);
      block[b0] = rng.integer(0, 1) ? kRigidContact : kOutsideRegion;
      if (rng.integer(0, 1)) block[(b0 + 1) % 3] = kOutsideRegion;
    }
    T w[3];
    Vec3<T> c;
    const Vec3<T> q = triangle_deepest_point(cap, P, w, c);
    double wsum = 0;
    for (int i = 0; i < 3; ++i) wsum += block[i] ? 0.0 : double(w[i]) * double(w[i]);
    if (wsum < 0.01) continue;  // corrections 100 times the depth: not a useful check
    ++cases;
    with_blocked += block[0] || block[1] || block[2];
    on_edge += w0[0] == 0 || w0[1] == 0 || w0[2] == 0;
    // no corner is inside (node contact leaves the face as it is): the face comes back to reach = r - its
    // allowance (at least 0.95 r > the deepest point's 0.9 r at most, so face contact always acts here)
    const double reach = ref_reach(P, r);
    const double d = dist(q, c), delta = reach - d;
    const VL n = (LD(1) / norm(L(q) - L(c))) * (L(q) - L(c));
    CornerContact<T> out[3];
    Vec3<T> y[3];
    sweep(tools, 0, P, block, out, y);
    const double scale = std::max({vmax(P[0]), vmax(P[1]), vmax(P[2]), 1.0});
    const std::string where = "triangle " + str(P[0]) + " " + str(P[1]) + " " + str(P[2]) + " tip " + str(cap.a) +
                              " axis end " + str(cap.b) + " r " + std::to_string(r) + " block " +
                              std::to_string(block[0]) + std::to_string(block[1]) + std::to_string(block[2]);
    ASSERT_LT(d, reach) << where;
    EXPECT_LE(double(norm(n + L(outward(P)))), tol<T>(scale) / (r - depth)) << where;  // straight down the normal
    VL moved{0, 0, 0};
    for (int i = 0; i < 3; ++i) {
      moved = moved + LD(w[i]) * L(out[i].dx);
      if (block[i]) {  // a blocked corner never moves
        EXPECT_TRUE(out[i].dx.x == T(0) && out[i].dx.y == T(0) && out[i].dx.z == T(0)) << where;
        EXPECT_EQ(out[i].tool, -1) << where;
        continue;
      }
      // the spread: dx_k = w_k delta n / sum_j w_j^2 over the movable corners
      const VL want = LD(double(w[i]) * delta / wsum) * n;
      EXPECT_LE(double(norm(L(out[i].dx) - want)), spread_tol<T>(scale, wsum)) << where << " corner " << i;
      if (w[i] > T(0)) {
        EXPECT_EQ(out[i].tool, 0) << where;
      }
    }
    // sum_k w_k dx_k: the deepest point moved by exactly delta along n ...
    EXPECT_LE(double(norm(moved - LD(delta) * n)), spread_tol<T>(scale, wsum)) << where;
    // ... to the face's allowance inside the capsule's surface
    EXPECT_NEAR(axis_distance(cap, w[0] * y[0] + w[1] * y[1] + w[2] * y[2]), reach, spread_tol<T>(scale, wsum))
        << where;
  }
  EXPECT_EQ(cases, 1500);
  EXPECT_GT(with_blocked, 300);
  EXPECT_GT(on_edge, 200);
}

TYPED_TEST(SweepTriangle, FaceContactWithEveryCornerBlockedReportsThem) {
  using T = TypeParam;
  const Vec3<T> x[3] = {{-3, -3, 0}, {6, -3, 0}, {-3, 6, 0}};
  const auto tools = static_tool<T>({0, 0, 0.2}, {0, 0, 1}, 0.5, 0);
  const std::uint8_t block[3] = {kRigidContact, kOutsideRegion, kRigidContact};
  CornerContact<T> out[3];
  Vec3<T> y[3];
  sweep(tools, 0, x, block, out, y);
  for (int i = 0; i < 3; ++i) {
    EXPECT_TRUE(out[i].dx.x == T(0) && out[i].dx.y == T(0) && out[i].dx.z == T(0));
    EXPECT_EQ(out[i].blocked, block[i]);
    EXPECT_EQ(out[i].tool, 0);
  }
  // a blocked corner inside the tool is reported by node contact as well
  const Vec3<T> small[3] = {{0, 0, 0}, {2, 0, 0}, {0, 2, 0}};
  const auto poke = static_tool<T>({0, 0, 0.1}, {0, 0, 1}, 0.3, 1);
  const std::uint8_t b0[3] = {kOutsideRegion, 0, 0};
  sweep(poke, 0, small, b0, out, y);
  EXPECT_EQ(out[0].blocked, kOutsideRegion);
  EXPECT_EQ(out[0].tool, 0);
  EXPECT_TRUE(out[0].dx.x == T(0) && out[0].dx.y == T(0) && out[0].dx.z == T(0));
  EXPECT_EQ(out[1].blocked, 0);
}

/// A random tool moving near a random triangle over one step (any
/// direction, either side), with contact_substeps checks.
template <class T>
ContactTools<T> random_motion(Rng& rng, const Vec3<T> P[3], int n_tools = 1) {
  ContactTools<T> tools{};
  tools.n_tools = n_tools;
  tools.steps = 1;
  tools.face = 1;
  const VD centre = (1.0 / 3) * (as<double>(P[0]) + as<double>(P[1]) + as<double>(P[2]));
  for (int t = 0; t < n_tools; ++t) {
    const double r = rng.uni(0.1, 0.6), shaft = rng.uni(0, 1) < 0.3 ? 0 : rng.uni(0, 2);
    const VD tip0 = centre + 1.5 * rng.vec(), tip1 = tip0 + rng.uni(0.2, 2) * rng.vec();
    const VD axis0 = rng.unit(), axis1 = unit_or(axis0 + 0.3 * rng.vec(), axis0);
    const int n = contact_substeps({tip0, axis0}, {tip1, axis1}, r, shaft, 1);
    tools.tool[t] = one_tool<T>(tip0, axis0, tip1, axis1, r, shaft, n).tool[0];
  }
  return tools;
}

TYPED_TEST(SweepTriangle, BlockedCornersNeverMove) {
  using T = TypeParam;
  Rng rng(52);
  int reported = 0, moved = 0;
  for (int it = 0; it < 6000; ++it) {
    Vec3<T> P[3];
    random_triangle(rng, it % 2 ? Shape::Generic : Shape::Obtuse, P);
    const auto tools = random_motion(rng, P, it % 4 == 0 ? 2 : 1);
    std::uint8_t block[3];
    for (auto& b : block) {
      const double u = rng.uni(0, 1);
      b = u < 0.3 ? kRigidContact : (u < 0.6 ? kOutsideRegion : 0);
    }
    CornerContact<T> out[3];
    Vec3<T> y[3];
    sweep(tools, 0, P, block, out, y);
    for (int i = 0; i < 3; ++i) {
      if (block[i]) {
        EXPECT_TRUE(out[i].dx.x == T(0) && out[i].dx.y == T(0) && out[i].dx.z == T(0)) << "case " << it;
        EXPECT_TRUE(out[i].blocked == 0 || out[i].blocked == block[i]) << "case " << it;
        reported += out[i].blocked != 0;
      } else {
        EXPECT_EQ(out[i].blocked, 0) << "case " << it;
        moved += out[i].tool >= 0;
      }
    }
  }
  EXPECT_GT(reported, 300);  // the sample exercises both paths
  EXPECT_GT(moved, 300);
}

TYPED_TEST(SweepTriangle, FastToolDoesNotTunnelThroughTheFace) {
  using T = TypeParam;
  // a big face at z = 5 cm, outward +z, centroid on the z axis; a 2 mm tool,
  // handle up (away from the face), crossing it from 3 r above to 3 r below
  // within one step
  const double r = 2e-3, z0 = 0.05;
  const Vec3<T> x[3] = {as<T>(VD{-10 * r, -10 * r, z0}), as<T>(VD{20 * r, -10 * r, z0}),
                        as<T>(VD{-10 * r, 20 * r, z0})};
  for (const double shaft : {0.0, 5 * r}) {
    const ToolPose from{{0, 0, z0 + 3 * r}, {0, 0, 1}}, to{{0, 0, z0 - 3 * r}, {0, 0, 1}};
    const int n = contact_substeps(from, to, r, shaft, 1);
    ASSERT_EQ(n, 12);  // 6 r of travel, r / 2 per check
    CornerContact<T> out[3];
    Vec3<T> y[3];
    // one check per step is too coarse, which is why contact_substeps
    // exists: the tool is checked only 3 r below the face. The tip sphere is
    // 3 r from it (no contact); a shaft pierces the face 3 r up from the tip,
    // so the face's nearest axis point is not the tip: it is the rim of the
    // shaft's hole, which gets no face correction, and no corner is inside.
    // Nothing moves either way.
    sweep(one_tool<T>(from.tip, from.axis, to.tip, to.axis, r, shaft, 1), 0, x, kFree, out, y);
    for (int i = 0; i < 3; ++i)
      EXPECT_TRUE(out[i].dx.x == T(0) && out[i].dx.y == T(0) && out[i].dx.z == T(0) && out[i].tool == -1)
          << "shaft " << shaft << " corner " << i;
    // contact_substeps checks: the face is pushed ahead of the tip all the
    // way (a translation: the deepest point is the centroid, weights 1/3;
    // the face stays ahead of the tip, so the tool never passes it) and
    // ends its allowance short of r below the tip's final position: the
    // face is a right triangle with legs 30 r, circumradius 15 sqrt(2) r
    // = 21.2 r >= r, so the allowance is the cap 0.05 r and the face stops
    // 0.95 r below the tip at z0 - 3 r: it moved by -3.95 r
    const auto tools = one_tool<T>(from.tip, from.axis, to.tip, to.axis, r, shaft, n);
    sweep(tools, 0, x, kFree, out, y);
    for (int i = 0; i < 3; ++i) {
      EXPECT_LE(dist(out[i].dx, as<T>(VD{0, 0, -3.95 * r})), tol<T>(z0)) << "shaft " << shaft << " corner " << i;
      EXPECT_EQ(out[i].tool, 0);
    }
    EXPECT_NEAR(deepest_distance(last_capsule(tools), y), 0.95 * r, tol<T>(z0));
  }
  // A tip sphere that crosses the face's plane between two checks and ends
  // 0.6 r past it (inside the tissue, within r of the face): at the check
  // the tip is behind the face and was on its outer side at the previous
  // check (here the start of the step), so it went through: the face goes
  // along -N to the tip sphere's far side, not radially out through it (up
  // to z0 + 0.35 r, leaving the tool inside the tissue). The exit of the
  // face point q over the tip along -z is 0.6 r + r = 1.6 r: the face ends
  // r below the tip.
  {  // q the centroid: w = 1/3 each, a translation by -1.6 r
    const auto tools = one_tool<T>({0, 0, z0 + 3 * r}, {0, 0, 1}, {0, 0, z0 - 0.6 * r}, {0, 0, 1}, r, 0, 1);
    CornerContact<T> out[3];
    Vec3<T> y[3];
    sweep(tools, 0, x, kFree, out, y);
    for (int i = 0; i < 3; ++i) {
      EXPECT_LE(dist(out[i].dx, as<T>(VD{0, 0, -1.6 * r})), tol<T>(z0)) << "corner " << i;
      EXPECT_NEAR(double(y[i].z), z0 - 1.6 * r, tol<T>(z0)) << "corner " << i;
      EXPECT_EQ(out[i].tool, 0);
    }
    EXPECT_NEAR(deepest_distance(last_capsule(tools), y), r, tol<T>(z0));
  }
  {  // a slanted path ending under q = (4 r, -3 r, z0): barycentric w = (9, 14, 7) / 30, sum w^2 = 326 / 900;
     // the corners move by w_k 1.6 r / sum w^2 along -z and q itself by exactly 1.6 r
    const auto tools = one_tool<T>({0, 0, z0 + 3 * r}, {0, 0, 1}, {4 * r, -3 * r, z0 - 0.6 * r}, {0, 0, 1}, r, 0, 1);
    CornerContact<T> out[3];
    Vec3<T> y[3];
    sweep(tools, 0, x, kFree, out, y);
    const double w[3] = {9.0 / 30, 14.0 / 30, 7.0 / 30}, wsum = 326.0 / 900;
    VD moved{0, 0, 0};
    for (int i = 0; i < 3; ++i) {
      EXPECT_LE(dist(out[i].dx, as<T>(VD{0, 0, -w[i] * 1.6 * r / wsum})), tol<T>(z0)) << "corner " << i;
      moved = moved + w[i] * as<double>(out[i].dx);
    }
    EXPECT_NEAR(moved.z, -1.6 * r, tol<T>(z0));
  }
}

TYPED_TEST(SweepTriangle, ToolBehindTheFacePushesItInwardOnlyWhereTheTipWentThrough) {
  using T = TypeParam;
  // A face (0,-2,0), (2,0,0), (0,2,0), outward N = +z (a right triangle, circumradius 2 >= r: allowance 0.05 r,
  // reach 0.475), and a tool of radius r = 0.5 with its tip at A = (-0.2, 0, -0.1): 0.2 r behind the face's plane
  // (past kThrough) and beyond its edge P0 P2 (x = 0), whose midpoint q = (0, 0, 0) is the face's point nearest
  // to A (w = (1/2, 0, 1/2): on the edge, not inside the face) at |A - q| = sqrt(0.05) = 0.2236 < r. Every shaft
  // below leaves A away from the face ((shaft direction) . (A - q) > 0), so the tip is the nearest axis point, and
  // no corner is inside any of the tools.
  //  * through: the face goes along -N to the tip sphere's far side: the exit of q from the sphere about A along
  //    -z is 0.1 + sqrt(r^2 - 0.2^2) = 0.1 + sqrt(0.21) = 0.55826; spread by w / sum w^2 (sum 1/2), P0 and P2
  //    move by that along -z and P1 (w = 0) stays;
  //  * radial: the face point moves away from A along (q - A) / |q - A| = (2, 0, 1) / sqrt(5) by reach - |q - A|
  //    = 0.475 - sqrt(0.05) = 0.25139, P0 and P2 by the same.
  const Vec3<T> x[3] = {{0, -2, 0}, {2, 0, 0}, {0, 2, 0}};
  const VD A{-0.2, 0, -0.1}, above{-0.2, 0, 0.2};
  const double r = 0.5;
  const double through = 0.1 + std::sqrt(0.21), radial = 0.475 - std::sqrt(0.05);
  const VD down{0, 0, -through}, out_of_tool = (radial / std::sqrt(5.0)) * VD{2, 0, 1};
  const double c04 = std::sqrt(1 - 0.4 * 0.4);
  struct Case {
    const char* what;
    VD tip0, axis;  // the pose at the start of the step (the end is A with the same axis; one check)
    double shaft;
    VD expected;    // the motion of P0 and P2
  };
  const Case cases[] = {
      // (a) the tip crossed the face's plane since the previous check (the tool came down from above in one
      //     check: the tip was 0.2 on the outer side of the plane through q)
      {"sphere that crossed the plane", above, {0, 0, 1}, 0, down},
      {"shaft along the face that crossed the plane", above, {-1, 0, 0}, 1, down},
      {"shaft up and away that crossed the plane", above, {-0.8, 0, 0.6}, 1, down},
      // (c) a still tool past whose tip the tissue tilted the face's edge: rounded off radially, continuously
      //     (no flip at kThrough), whatever the shaft
      {"still sphere", A, {0, 0, 1}, 0, out_of_tool},
      {"still shaft along the face", A, {-1, 0, 0}, 1, out_of_tool},
      {"still shaft up and away, 53 degrees off N", A, {-0.8, 0, 0.6}, 1, out_of_tool},
      {"still shaft up and away, 66 degrees off N", A, {-c04, 0, 0.4}, 1, out_of_tool},
  };
  for (const Case& k : cases) {
    const auto tools = one_tool<T>(k.tip0, k.axis, A, k.axis, r, k.shaft, 1);
    CornerContact<T> out[3];
    Vec3<T> y[3];
    sweep(tools, 0, x, kFree, out, y);
    for (const int i : {0, 2}) {
      EXPECT_LE(dist(out[i].dx, as<T>(k.expected)), tol<T>(4)) << k.what << ", corner " << i;
      EXPECT_EQ(out[i].tool, 0) << k.what;
    }
    EXPECT_TRUE(out[1].dx.x == T(0) && out[1].dx.y == T(0) && out[1].dx.z == T(0) && out[1].tool == -1) << k.what;
  }
  // (b) the tip behind the middle of a face, over its inside (the face cuts the tip sphere beyond its centre):
  // through whether the tool came from the outer side within the check or was there still. A big face (-3,-3,0),
  // (6,-3,0), (-3,6,0) (outward +z, centroid (0,0,0): w = 1/3 each, the face translates), a tool r = 0.5 with its
  // tip at (0, 0, -0.1): the exit of the centroid along -z is 0.1 + r = 0.6 (the face ends r below the tip; a
  // radial push would have moved it up by reach - 0.1 = 0.475 - 0.1, out through the tool). Shafts go away from the
  // face (into the tissue): one up would pierce the face, which is a rim (see ShaftThroughARimFace...).
  {
    const Vec3<T> big[3] = {{-3, -3, 0}, {6, -3, 0}, {-3, 6, 0}};
    const struct {
      const char* what;
      double z0;
      VD axis;
      double shaft;
    } under[] = {
        {"sphere come down", 0.2, {0, 0, 1}, 0},
        {"still sphere", -0.1, {0, 0, 1}, 0},
        {"still shaft, into the tissue", -0.1, {0.8, 0, -0.6}, 1},
        {"shaft into the tissue, come down", 0.2, {0.8, 0, -0.6}, 1},
    };
    for (const auto& k : under) {
      const auto tools = one_tool<T>({0, 0, k.z0}, k.axis, {0, 0, -0.1}, k.axis, r, k.shaft, 1);
      CornerContact<T> out[3];
      Vec3<T> y[3];
      sweep(tools, 0, big, kFree, out, y);
      for (int i = 0; i < 3; ++i) {
        EXPECT_LE(dist(out[i].dx, as<T>(VD{0, 0, -0.6})), tol<T>(6)) << k.what << ", corner " << i;
        EXPECT_EQ(out[i].tool, 0) << k.what;
      }
    }
  }
  // random: a tool (sphere, or a shaft pointing away from the face, into the
  // tissue) whose tip comes from the face's outer side and ends behind it
  // over its inside (crossed and under) within one check; every corner moves
  // along -N only, and where no corner is inside the tool the face point over
  // the tip goes exactly to the tip sphere's far side: the exit of q0 along -N
  // is the tip's depth behind the plane + r, spread by w / sum w^2.
  Rng rng(53);
  int cases_n = 0, exact = 0;
  for (int it = 0; cases_n < 1500 && it < 100000; ++it) {
    const FacePoint<T> face = random_face_point<T>(rng, 0.05, 0.5, 0.05);
    const auto& [P, r, w0, N, q0] = face;
    const VD axis = unit_or(-1.0 * N + 0.6 * rng.unit(), -1.0 * N);
    if (dot(axis, N) > -0.3) continue;
    const double behind = rng.uni(0.15, 0.9) * r;  // past kThrough
    const double shaft = it % 2 ? 0.0 : rng.uni(0, 1);
    const VD tip0 = q0 + rng.uni(0.05, 2) * r * N + rng.uni(0, 1) * r * rng.vec();
    const auto tools = one_tool<T>(tip0, axis, q0 - behind * N, axis, r, shaft, 1);
    const Capsule<T> cap = last_capsule(tools);
    const VL a = L(cap.a), b = L(cap.b), n = L(outward(P));
    if (!(dot(L(tools.tool[0].tip0) - L(P[0]), n) > 0)) continue;  // the start is on the outer side
    // a corner inside the shaft but not the tip sphere is pushed radially out of the shaft: not this test's
    bool sphere_corner = false, shaft_corner = false;
    for (int i = 0; i < 3; ++i) {
      const LD to_tip = norm(L(P[i]) - a), to_axis = ref_point_segment(a, b, L(P[i]));
      if (to_axis < LD(1.001) * r && to_tip > LD(0.999) * r) shaft_corner = true;
      if (to_tip < LD(1.001) * r) sphere_corner = true;
    }
    if (shaft_corner) continue;
    ++cases_n;
    CornerContact<T> out[3];
    Vec3<T> y[3];
    sweep(tools, 0, P, kFree, out, y);
    const std::string where = "triangle " + str(P[0]) + " " + str(P[1]) + " " + str(P[2]) + " tip " +
                              str(tools.tool[0].tip0) + " -> " + str(cap.a) + " axis " + str(tools.tool[0].axis0) +
                              " r " + std::to_string(r) + " shaft " + std::to_string(shaft);
    for (int i = 0; i < 3; ++i) {
      const VL dx = L(out[i].dx);
      const LD along = dot(dx, n);
      EXPECT_LE(double(along), tol<T>(2)) << where << " corner " << i;                          // inward
      EXPECT_LE(double(norm(dx - along * n)), tol<T>(2) * (1 + 3 * vmax(out[i].dx))) << where;  // only inward
    }
    if (sphere_corner) continue;
    ++exact;
    // the tip's depth behind the plane (of the rounded positions) and the exit of its foot q0 along -N
    const LD depth = -dot(a - L(P[0]), n), delta = depth + LD(r);
    const double wsum = w0[0] * w0[0] + w0[1] * w0[1] + w0[2] * w0[2];
    VL moved{0, 0, 0};
    for (int i = 0; i < 3; ++i) {
      const VL want = LD(-w0[i] / wsum) * delta * n;
      EXPECT_LE(double(norm(L(out[i].dx) - want)), 1e3 * tol<T>(2)) << where << " corner " << i;
      moved = moved + LD(w0[i]) * L(out[i].dx);
    }
    // q0 ends r below the tip, on its far side
    EXPECT_LE(double(norm(L(q0) + moved - (a - LD(r) * n))), 1e3 * tol<T>(2)) << where;
  }
  EXPECT_EQ(cases_n, 1500);
  EXPECT_GT(exact, 300);
}

// A face whose point is the tip's centre (the axis pierces it at the tip,
// within kPierced r) has been passed through by the tip whatever the motion:
// it goes along -N to the far side of the tip sphere (tip_exit), r below the
// tip -- never along the shaft (see ShaftThroughARimFace...).
TYPED_TEST(SweepTriangle, FacePiercedByTheTipIsMovedToTheFarSideOfTheTip) {
  using T = TypeParam;
  // face (-3,-3,0), (3,-3,0), (-3,3,0), outward +z, centroid (-1,-1,0); a still tool of r = 1 with its tip a at
  // the centroid, on the plane or 0.5e-4 r above or below it (pierced: within kPierced r), handle up (the shaft
  // rises away from the face), no corner inside (the nearest is 2 sqrt(2) from a). The face point q nearest the
  // axis is the foot of a, or, for a shaft rising from below the plane, the point where the axis crosses it,
  // t = -z_a / u_z up the axis (at most 0.83e-4 r from the tip: still the tip). q goes along -z by its exit from
  // the tip sphere, e = -b + sqrt(b^2 - |m|^2 + r^2) with m = q - a, b = -m_z (r - z_a where q is a's foot), the
  // corners by w_k e / sum w^2 (w = q's barycentric weights; 1/3 each for the foot: a translation), and q lands on
  // the tip sphere's far side
  const Vec3<T> x[3] = {{-3, -3, 0}, {3, -3, 0}, {-3, 3, 0}};
  for (const double tip_z : {0.0, 0.5e-4, -0.5e-4})
    for (const VD axis : {VD{0, 0, 1}, VD{0.6, 0, 0.8}, VD{0, -0.8, 0.6}})
      for (const double shaft : {0.0, 2.0}) {
        const VD a{-1, -1, tip_z};
        const double t = shaft > 0 && tip_z < 0 ? -tip_z / axis.z : 0.0;
        const VD q{a.x + t * axis.x, a.y + t * axis.y, 0}, m = q - a;
        const double b = -m.z, e = -b + std::sqrt(b * b - dot(m, m) + 1);
        const double v = (q.x + 3) / 6, u = (q.y + 3) / 6, w[3] = {1 - v - u, v, u};
        const double wsum = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
        const auto tools = static_tool<T>(a, axis, 1, shaft);
        CornerContact<T> out[3];
        Vec3<T> y[3];
        sweep(tools, 0, x, kFree, out, y);
        const std::string where = "tip z " + std::to_string(tip_z) + " axis " + str(axis) + " shaft " +
                                  std::to_string(shaft);
        VD moved{0, 0, 0};
        for (int i = 0; i < 3; ++i) {
          EXPECT_LE(dist(out[i].dx, as<T>(VD{0, 0, -w[i] * e / wsum})), tol<T>(3)) << where << " corner " << i;
          EXPECT_EQ(out[i].tool, 0) << where;
          moved = moved + w[i] * as<double>(out[i].dx);
        }
        // q moved by e along -z, onto the tip sphere's far side: r from a, below it
        EXPECT_LE(dist(moved, VD{0, 0, -e}), tol<T>(3)) << where;
        EXPECT_NEAR(dist(q + moved, a), 1, tol<T>(3)) << where;
        EXPECT_LT((q + moved).z, tip_z - 0.99) << where;
      }
  // random: a still tool with its tip on a random face's interior point q0 and
  // its handle on the face's outer side (or a sphere), no corner inside it:
  // dx_k = -w_k delta N / sum w^2, delta = r - (the tip's height over the
  // plane, rounding), and q0 ends r below the tip
  Rng rng(56);
  int cases = 0;
  for (int it = 0; cases < 1500 && it < 100000; ++it) {
    const FacePoint<T> face = random_face_point<T>(rng, 0.05, 0.3, 0.05);
    const auto& [P, r, w0, N, q0] = face;
    const VD axis = unit_or(N + 0.8 * rng.unit(), N);
    if (dot(axis, N) < 0.3) continue;
    const auto tools = static_tool<T>(q0, axis, r, it % 3 ? rng.uni(0, 1) : 0);
    const Capsule<T> cap = last_capsule(tools);
    bool corner_inside = false;
    for (int i = 0; i < 3; ++i) corner_inside |= axis_distance(cap, P[i]) < r * 1.001;
    if (corner_inside) continue;  // node contact would act first
    ++cases;
    CornerContact<T> out[3];
    Vec3<T> y[3];
    sweep(tools, 0, P, kFree, out, y);
    const std::string where = "triangle " + str(P[0]) + " " + str(P[1]) + " " + str(P[2]) + " tip " + str(cap.a) +
                              " axis end " + str(cap.b) + " r " + std::to_string(r);
    const VL n = L(outward(P)), a = L(cap.a);
    const LD delta = LD(r) - dot(a - L(P[0]), n);
    const double wsum = w0[0] * w0[0] + w0[1] * w0[1] + w0[2] * w0[2];
    VL moved{0, 0, 0};
    for (int i = 0; i < 3; ++i) {
      const VL want = LD(-w0[i] / wsum) * delta * n;
      EXPECT_LE(double(norm(L(out[i].dx) - want)), 1e3 * tol<T>(2)) << where << " corner " << i;
      EXPECT_EQ(out[i].tool, 0) << where;
      moved = moved + LD(w0[i]) * L(out[i].dx);
    }
    EXPECT_LE(double(norm(L(q0) + moved - (a - LD(r) * n))), 1e3 * tol<T>(2)) << where;
  }
  EXPECT_EQ(cases, 1500);
}

// A shaft through the rim of the hole it makes: the face's nearest axis
// point is far up the shaft from the tip, so the tip has not passed the face:
// its corners inside the shaft go radially out of it and nothing moves along
// the shaft. (The rule before moved such faces along -N out of the whole
// capsule: for the surface face around a 10 mm shaft 9 mm in, a jump of
// 9 mm + r down the shaft; for a face the axis lies behind, a jump across
// the shaft.)
TYPED_TEST(SweepTriangle, ShaftThroughARimFacePushesItsCornersRadiallyNotAlongTheShaft) {
  using T = TypeParam;
  const double r = 1e-3;
  const auto tools = static_tool<T>({0, 0, -9 * r}, {0, 0, 1}, r, 10 * r);  // the tip 9 mm in, the shaft up to +1 mm
  const Capsule<T> cap = last_capsule(tools);
  {  // the surface face around the hole (outward +z, along the shaft), pierced by the shaft at its centroid 9 r up
     // from the tip: corners at 0.5 r from the axis go radially to r, in the plane z = 0; the face stays pierced (a
     // rim) and gets no face correction
    const double th[3] = {M_PI / 2, M_PI / 2 + 2 * M_PI / 3, M_PI / 2 + 4 * M_PI / 3};
    Vec3<T> x[3];
    for (int i = 0; i < 3; ++i) x[i] = as<T>(VD{0.5 * r * std::cos(th[i]), 0.5 * r * std::sin(th[i]), 0});
    ASSERT_GT(dot(outward(x), Vec3<T>{0, 0, 1}), T(0.99));
    CornerContact<T> out[3];
    Vec3<T> y[3];
    sweep(tools, 0, x, kFree, out, y);
    for (int i = 0; i < 3; ++i) {
      EXPECT_LE(dist(y[i], as<T>(VD{r * std::cos(th[i]), r * std::sin(th[i]), 0})), tol<T>(10 * r)) << "corner " << i;
      EXPECT_LE(std::fabs(double(out[i].dx.z)), tol<T>(10 * r)) << "corner " << i;  // not along the shaft
      EXPECT_EQ(out[i].tool, 0);
    }
  }
  {  // a face tilted 40 degrees off the shaft's normal plane, pierced by it at the centroid: each corner goes
     // radially out at its own height, (x, y) scaled to r / rho
    const double th[3] = {M_PI / 2, M_PI / 2 + 2 * M_PI / 3, M_PI / 2 + 4 * M_PI / 3}, tilt = 40 * M_PI / 180;
    VD p[3];
    Vec3<T> x[3];
    for (int i = 0; i < 3; ++i) {
      p[i] = {0.5 * r * std::cos(th[i]), 0.5 * r * std::sin(th[i]) * std::cos(tilt), 0.5 * r * std::sin(th[i]) * std::sin(tilt)};
      x[i] = as<T>(p[i]);
    }
    CornerContact<T> out[3];
    Vec3<T> y[3];
    sweep(tools, 0, x, kFree, out, y);
    // the expected positions keep the face pierced by the axis (so no face contact follows node contact)
    VD e[3];
    for (int i = 0; i < 3; ++i) {
      const double rho = std::hypot(p[i].x, p[i].y);
      e[i] = {p[i].x * r / rho, p[i].y * r / rho, p[i].z};
    }
    ASSERT_LT(double(ref_segment_triangle(L(cap.a), L(cap.b), L(e[0]), L(e[1]), L(e[2]))), 1e-12);
    for (int i = 0; i < 3; ++i) {
      EXPECT_LE(dist(y[i], as<T>(e[i])), tol<T>(10 * r)) << "corner " << i;
      EXPECT_LE(std::fabs(double(out[i].dx.z)), tol<T>(10 * r)) << "corner " << i;
    }
  }
  {  // a face lying along the shaft, its outward normal +x across it, the axis 0.5 r behind it under the face:
     // P = (0.5, -0.1, -0.3) r, (0.5, 0.1, -0.3) r, (0.5, -0.1, 0.3) r. The shaft is on the tissue's side of a
     // face it lies along: it has passed it (as a tool lying on the surface pressed through it would), so the
     // corners go along -N to the shaft's far side, x = -sqrt(r^2 - y^2) = -0.99499 r at y = +-0.1 r (not
     // radially out to x = +0.98 r, which leaves the shaft inside the tissue), and the face after them
    const VD p[3] = {{0.5 * r, -0.1 * r, -0.3 * r}, {0.5 * r, 0.1 * r, -0.3 * r}, {0.5 * r, -0.1 * r, 0.3 * r}};
    const Vec3<T> x[3] = {as<T>(p[0]), as<T>(p[1]), as<T>(p[2])};
    ASSERT_GT(dot(outward(x), Vec3<T>{1, 0, 0}), T(0.99));
    CornerContact<T> out[3];
    Vec3<T> y[3];
    sweep(tools, 0, x, kFree, out, y);
    for (int i = 0; i < 3; ++i) {
      EXPECT_LE(double(y[i].x), -std::sqrt(1 - 0.01) * r + tol<T>(10 * r)) << "corner " << i;
      EXPECT_LE(std::fabs(double(out[i].dx.y)) + std::fabs(double(out[i].dx.z)), tol<T>(10 * r)) << "corner " << i;
      EXPECT_EQ(out[i].tool, 0);
    }
    EXPECT_GE(deepest_distance(cap, y), ref_reach(y, r) - tol<T>(10 * r));
  }
  {  // a big face pierced by the shaft 0.5 r up from a tip 0.5 r behind it (the tip sphere reaches 0.5 r past the
     // face, the shaft through it): the nearest axis point is the piercing point, not the tip, so this is a rim
     // too -- no corner is inside, and the face is left as it is
    const Vec3<T> x[3] = {{-3, -3, 0}, {3, -3, 0}, {-3, 3, 0}};
    const auto deep = static_tool<T>({-1, -1, -0.5}, {0, 0, 1}, 1, 2);
    CornerContact<T> out[3];
    Vec3<T> y[3];
    sweep(deep, 0, x, kFree, out, y);
    for (int i = 0; i < 3; ++i)
      EXPECT_TRUE(out[i].dx.x == T(0) && out[i].dx.y == T(0) && out[i].dx.z == T(0) && out[i].tool == -1);
  }
}

// A horizontal capsule (shaft along +x) 0.5 r under a face larger than the
// tool, crossing it from edge to edge: the face (-3,-3,0), (3,-3,0),
// (-3,3,0), outward +z, r = 1, the axis from (-4,-1,-0.5) to (4,-1,-0.5).
// Its ends lie beyond the face, so the axis point nearest the face is where
// it passes under an edge, (1,-1,-0.5) under the hypotenuse, inside the
// shaft, not the tip. Only the tip passed faces before: this face went
// radially out from that point, up to 0.95 r over the axis, and the shaft
// was through the surface (a capsule pressed flat sank through the block's
// top). The shaft holds it as the tip does: the face goes along -N to the
// shaft's far side, its reach under the axis, no corner moving sideways.
TYPED_TEST(SweepTriangle, AShaftLyingUnderAFaceMovesItToTheShaftsFarSide) {
  using T = TypeParam;
  const Vec3<T> x[3] = {{-3, -3, 0}, {3, -3, 0}, {-3, 3, 0}};
  const auto tools = static_tool<T>({-4, -1, -0.5}, {1, 0, 0}, 1, 8);
  const Capsule<T> cap = last_capsule(tools);
  {
    T w[3];
    Vec3<T> c;
    triangle_deepest_point(cap, x, w, c);
    ASSERT_GT(norm(c - cap.a), T(1)) << "the nearest axis point is on the shaft, not the tip";
  }
  CornerContact<T> out[3];
  Vec3<T> y[3];
  sweep(tools, 0, x, kFree, out, y);
  for (int i = 0; i < 3; ++i) {
    EXPECT_LE(double(out[i].dx.z), 0.0) << "corner " << i << ": never up over the shaft";
    EXPECT_EQ(double(out[i].dx.x), 0.0) << "corner " << i;
    EXPECT_EQ(double(out[i].dx.y), 0.0) << "corner " << i;
  }
  // the face is now under the shaft, at least its reach from the axis: the shaft is back on its outer side
  {
    T w[3];
    Vec3<T> c;
    const Vec3<T> q = triangle_deepest_point(cap, y, w, c);
    EXPECT_LT(double(q.z), double(c.z));
    EXPECT_GE(double(norm(q - c)), ref_reach(y, 1.0) - tol<T>(10));
  }
  // a face in front of the shaft is pushed away from it (down) as before, and one at the shaft's level (the
  // axis within kThrough r behind its plane) radially: up, the level band where a hole's rim lies
  for (double z : {0.5, -0.05}) {
    const auto other = static_tool<T>({-4, -1, z}, {1, 0, 0}, 1, 8);
    sweep(other, 0, x, kFree, out, y);
    for (int i = 0; i < 3; ++i)
      EXPECT_GE((z > 0 ? -1 : 1) * double(out[i].dx.z), 0.0) << "z " << z << " corner " << i;
  }
}

// The exit along a direction crosswise to the shaft is its far side; along
// the shaft it is only the tip sphere's (a rim face is never carried the
// shaft's length).
TYPED_TEST(SweepTriangle, ThroughExitLeavesAcrossTheShaftNotAlongIt) {
  using T = TypeParam;
  const Capsule<T> cap{{0, 0, 0}, {10, 0, 0}, 1};
  // from (5, 0, 0.5) straight down: the cylinder's far side at z = -1, 1.5 away
  EXPECT_NEAR(double(through_exit(cap, Vec3<T>{5, 0, 0.5}, Vec3<T>{0, 0, -1})), 1.5, tol<T>(10));
  // from (5, 0.6, 0.5) down: z = -sqrt(1 - 0.36) = -0.8, 1.3 away
  EXPECT_NEAR(double(through_exit(cap, Vec3<T>{5, 0.6, 0.5}, Vec3<T>{0, 0, -1})), 1.3, tol<T>(10));
  // near the far end, level with it: the end's sphere, from (10.5, 0, 0.5) down to z = -sqrt(1 - 0.25)
  EXPECT_NEAR(double(through_exit(cap, Vec3<T>{10.5, 0, 0.5}, Vec3<T>{0, 0, -1})), 0.5 + std::sqrt(0.75), tol<T>(10));
  // along the shaft: the tip sphere only (0 here, far from it), never the shaft's length
  EXPECT_EQ(double(through_exit(cap, Vec3<T>{5, 0, 0.5}, Vec3<T>{1, 0, 0})), 0.0);
  EXPECT_NEAR(double(through_exit(cap, Vec3<T>{0.2, 0, 0}, Vec3<T>{-1, 0, 0})), 1.2, tol<T>(10));
  // outside the capsule: nothing to leave
  EXPECT_EQ(double(through_exit(cap, Vec3<T>{5, 0, 1.5}, Vec3<T>{0, 0, -1})), 0.0);
  // a sphere (no shaft): tip_exit
  const Capsule<T> ball{{0, 0, 0}, {0, 0, 0}, 1};
  EXPECT_EQ(through_exit(ball, Vec3<T>{0.3, 0.2, 0.1}, Vec3<T>{0, 0, -1}), tip_exit(ball, Vec3<T>{0.3, 0.2, 0.1}, Vec3<T>{0, 0, -1}));
}

// A tool at the surface's level beside a face (its centre 0.05 = 0.083 r
// below the face's plane, within kThrough, and beside the face): the tool
// has not gone through the face, so its corners are pushed radially out of
// it (as the rim's corners beside a shaft through a hole must be), and none
// is left inside.
TYPED_TEST(SweepTriangle, AToolAtTheSurfaceLevelPushesCornersRadially) {
  using T = TypeParam;
  const Vec3<T> x[3] = {{0, 0, 0}, {T(0.3), 0, 0}, {0, T(0.3), 0}};
  const auto tools = static_tool<T>({-0.2, -0.2, -0.05}, {0, 0, 1}, 0.6, 0);
  CornerContact<T> out[3];
  Vec3<T> y[3];
  sweep(tools, 0, x, kFree, out, y);
  const Capsule<T> cap = last_capsule(tools);
  for (int i = 0; i < 3; ++i) {
    EXPECT_GE(axis_distance(cap, y[i]), 0.6 - tol<T>(1)) << "corner " << i << " left inside";
    // radially: away from the centre
    EXPECT_GT(double(dot(out[i].dx, x[i] - Vec3<T>{T(-0.2), T(-0.2), T(-0.05)})), 0.0) << "corner " << i;
  }
}

// A repro of an earlier finding (a corner left inside): a capsule that starts clear of the
// face on its outer side (both axis ends at positive height over the plane)
// and moves down past the face's corner P0 within one step (contact_substeps
// = 3 checks). At the last check P1 is 0.8306 from the axis, inside (r =
// 0.9126): the axis point nearest P1 is behind the face there, so (a) skips
// it, and (b)'s deepest point is the corner P0 (w = (1,0,0)), pushed radially.
TEST(SweepTriangleRepro, ApproachFromOutsideLeavesACornerInside) {
  const VD x[3] = {{-2.8988612523876358, -0.75248003447414813, -0.0018449404022633509},
                   {-2.75563696333802, -0.83149702998266495, -0.31320377073778749},
                   {-0.55896260123563102, -2.3159699992209077, -1.5064982331921604}};
  const double r = 0.91258924868969427, shaft = 0.48353900284894397;
  const ToolPose from{{-3.6267834856925352, -1.0572413106968068, 1.296764780272343},
                      {-0.40622016034128805, -0.91212027906398929, 0.054970699945773978}};
  const ToolPose to{{-2.8831265861663589, -0.4752726495571129, 0.43811732614789278},
                    {-0.50172650366729488, -0.85327595522238253, 0.14209384137647468}};
  const int n = contact_substeps(from, to, r, shaft, 1);
  ASSERT_EQ(n, 3);
  const auto tools = one_tool<double>(from.tip, from.axis, to.tip, to.axis, r, shaft, n);
  // the start is clear and on the outer side
  const Capsule<double> cap0 = tool_capsule(tools.tool[0], 1, 0, 0);
  ASSERT_GT(deepest_distance(cap0, x), r);
  ASSERT_GT(dot(cap0.a - x[0], outward(x)), 0);
  ASSERT_GT(dot(cap0.b - x[0], outward(x)), 0);
  CornerContact<double> out[3];
  Vec3<double> y[3];
  sweep(tools, 0, x, kFree, out, y);
  const Capsule<double> cap = last_capsule(tools);
  for (int i = 0; i < 3; ++i) EXPECT_GE(axis_distance(cap, y[i]), r - 1e-12) << "corner " << i << " left inside";
}

/// A tool starting clear of a random face on its outer side (both axis
/// ends over the plane), handle away from the face, moving by up to 3 m /
/// s-ish steps in any direction; checks per contact_substeps.
template <class T>
bool random_approach(Rng& rng, Vec3<T> P[3], ContactTools<T>& tools, bool sphere) {
  random_triangle(rng, Shape::Generic, P);
  for (int i = 0; i < 3; ++i) P[i] = T(3) * P[i];
  const double r = rng.uni(0.2, 1), shaft = sphere ? 0 : rng.uni(0, 2), move = rng.uni(0.2, 3);
  const VD N = as<double>(outward(P));
  const VD centre = (1.0 / 3) * (as<double>(P[0]) + as<double>(P[1]) + as<double>(P[2]));
  const VD axis0 = unit_or(N + 0.7 * rng.unit(), N), axis1 = unit_or(axis0 + 0.3 * move * rng.unit(), axis0);
  const VD tip0 = centre + 2.0 * rng.vec() + N, tip1 = tip0 + move * rng.vec();
  const int n = contact_substeps({tip0, axis0}, {tip1, axis1}, r, shaft, 1);
  tools = one_tool<T>(tip0, axis0, tip1, axis1, r, shaft, n);
  const Capsule<T> cap0 = tool_capsule(tools.tool[0], 1, 0, 0);
  return deepest_distance(cap0, P) > r && dot(cap0.a - P[0], outward(P)) > T(0) &&
         dot(cap0.b - P[0], outward(P)) > T(0);
}

// After the sweep, at the step's last sub-check: (1) no corner is inside
// the tool; (2) the deepest point that the last check's face contact
// corrected is exactly at reach = r - the face's allowance (ref_allowance of
// the face before that check: no corner was inside, so node contact left it
// as it was) from the axis, and a deepest point already between reach and r
// is not moved at all; (3) for a sphere, no point of the face is deeper than
// the bound of one projection (below). What is
// NOT claimed: that the new deepest point is at reach to round-off. Face
// contact moves one point per check; the rest of the face follows by its
// barycentric share beta(p) = sum_k lambda_k(p) w_k / sum w^2 of delta n,
// delta = reach - dist, which is less than 1 on one side of the point, so a
// point next to it can stay deeper. For a sphere of centre c, with p' - c =
// (dist + beta delta) n + u and dist + delta = reach: |p' - c|^2 = (reach +
// delta g.u)^2 + 2 (dist + beta delta) u.n + |u|^2 >= (reach + delta g.u)^2
// + |u|^2 >= reach^2 / (1 + delta^2 |g|^2), u = p - q in the plane, g = grad
// beta, using u.n >= 0 (q closest to c) and beta >= 0; equality for a flat
// face region. For a
// capsule whose shaft lies along the face the residual is first order in
// delta (the far end of a shaft lying on the face stays in; measured: up to
// 13% of r on triangles with all angles over 40 degrees), and a sliver can
// leave an edge inside after its other edge was pushed (28% of r measured).
// That is the documented one-projection rule, so it is checked in this
// exact form; if face contact is ever iterated to convergence, (3) becomes
// "after >= reach - tolerance" and the last check below goes.
TYPED_TEST(SweepTriangle, RandomApproachLastCheckInvariants) {
  using T = TypeParam;
  Rng rng(54);
  int cases = 0, face_checks = 0, sphere_checks = 0, within_allowance = 0;
  double worst_ratio = 0;
  for (int it = 0; cases < 3000 && it < 200000; ++it) {
    Vec3<T> P[3];
    ContactTools<T> tools;
    const bool sphere = it % 2 == 0;
    if (!random_approach(rng, P, tools, sphere)) continue;
    CornerContact<T> out[3];
    Vec3<T> y[3];
    sweep(tools, 0, P, kFree, out, y);
    if (out[0].tool < 0 && out[1].tool < 0 && out[2].tool < 0) continue;  // no contact at all
    ++cases;
    const Capsule<T> cap = last_capsule(tools);
    const double r = double(cap.r);
    const double scale = std::max({vmax(P[0]), vmax(P[1]), vmax(P[2]), vmax(cap.a), vmax(cap.b), 1.0});
    const std::string where = "triangle " + str(P[0]) + " " + str(P[1]) + " " + str(P[2]) + " tip " +
                              str(tools.tool[0].tip0) + " -> " + str(tools.tool[0].tip1) + " axis " +
                              str(tools.tool[0].axis0) + " -> " + str(tools.tool[0].axis1) + " r " + std::to_string(r) +
                              " shaft " + std::to_string(double(tools.tool[0].shaft)) + " substeps " +
                              std::to_string(tools.tool[0].substeps);
    // (1)
    for (int i = 0; i < 3; ++i) EXPECT_GE(axis_distance(cap, y[i]), r - tol<T>(scale)) << where << " corner " << i;
    // the state before the last check: the first n - 1 checks as n - 1
    // steps of one check (tool_capsule gives the same capsules, see
    // SubChecksAreStepsOfOneCheck)
    const int m = tools.tool[0].substeps;
    ContactTools<T> split = tools;
    split.steps = m;
    split.tool[0].substeps = 1;
    Vec3<T> xb[3] = {P[0], P[1], P[2]};
    for (int k = 0; k + 1 < m; ++k) {
      Vec3<T> next[3];
      sweep(split, k, xb, kFree, out, next);
      for (int i = 0; i < 3; ++i) xb[i] = next[i];
    }
    bool node = false;
    for (int i = 0; i < 3; ++i) node |= axis_distance(cap, xb[i]) < r;
    if (node) continue;  // node contact acts in the last check: (2), (3) are about face contact alone
    T w[3];
    Vec3<T> c;
    const Vec3<T> q = triangle_deepest_point(cap, xb, w, c);
    const double d = dist(q, c);
    if (!(d < r)) continue;
    // (2) and (3) are about the radial push; a face the tool has gone
    // through is moved along -N instead (tested above)
    if (!(d > 0) || double(dot(c - q, outward(xb))) < -0.1 * r) continue;
    const double reach = ref_reach(xb, r);
    Vec3<T> xa[3];
    sweep(split, m - 1, xb, kFree, out, xa);
    double wsum = 0;
    for (int k = 0; k < 3; ++k) wsum += double(w[k]) * double(w[k]);
    // (2) within the allowance (by more than rounding: at reach either may happen, and (2), (3) below hold
    // either way): face contact leaves the face as it is, bit for bit
    if (d > reach + spread_tol<T>(scale, wsum)) {
      ++within_allowance;
      for (int i = 0; i < 3; ++i)
        EXPECT_TRUE(xa[i].x == xb[i].x && xa[i].y == xb[i].y && xa[i].z == xb[i].z) << where << " corner " << i;
      continue;
    }
    ++face_checks;
    // (2) the corrected point lands at reach
    const Vec3<T> q1 = w[0] * xa[0] + w[1] * xa[1] + w[2] * xa[2];
    EXPECT_NEAR(axis_distance(cap, q1), reach, spread_tol<T>(scale, wsum)) << where;
    // (3) the residual of one projection, for a sphere
    if (sphere) {
      ++sphere_checks;
      const double g = spread_gradient(xb, w), delta = reach - d;
      const double bound = reach / std::sqrt(1 + delta * delta * g * g);
      const double after = deepest_distance(cap, xa);
      EXPECT_GE(after, bound - spread_tol<T>(scale, wsum)) << where;
      // (a depth within rounding of reach makes the ratio one of rounding errors: only clear cases count)
      if (after < reach && reach - bound > 100 * spread_tol<T>(scale, wsum))
        worst_ratio = std::max(worst_ratio, (reach - after) / (reach - bound));
    }
  }
  EXPECT_EQ(cases, 3000);
  EXPECT_GT(face_checks, 300);
  EXPECT_GT(sphere_checks, 150);
  EXPECT_GT(within_allowance, 20);  // the band between reach and r is met
  // (3) is not vacuous: some faces come within a factor 2 of the bound
  EXPECT_GT(worst_ratio, 0.5);
}

TYPED_TEST(SweepTriangle, OneProjectionResidualOnAFlatFaceIsHandComputed) {
  using T = TypeParam;
  // face (0,0,0), (4,0,0), (0,4,0), outward +z; a sphere r = 1 whose centre
  // is 0.5 over q = (2, 1, 0), w = (0.25, 0.5, 0.25), sum w^2 = 0.375. The
  // face is a right triangle with legs 4: circumradius 2 sqrt(2) = 2.83 >= r,
  // so its allowance is the cap 0.05 r and reach = 0.95: delta = 0.95 - 0.5
  // = 0.45, the corners move by w_k delta / 0.375 = w_k 1.2 (P0, P2 by 0.3,
  // P1 by 0.6, down), the face points by beta delta, beta = (0.25 + 0.25 x /
  // 4) / 0.375, so the gradient is g = 1/6 along x. After the check q is
  // exactly reach = 0.95 below the centre, at (2, 1, -0.45), and the face's
  // deepest point is reach / sqrt(1 + delta^2 g^2) = 0.95 / sqrt(1.005625) =
  // 0.947339 from it, at x = 2 - 0.95 delta g / (1 + delta^2 g^2) = 2 - 0.0709
  // (deeper than reach: the projection's residual).
  const Vec3<T> x[3] = {{0, 0, 0}, {4, 0, 0}, {0, 4, 0}};
  const auto tools = static_tool<T>({2, 1, 0.5}, {0, 0, 1}, 1, 0);
  CornerContact<T> out[3];
  Vec3<T> y[3];
  sweep(tools, 0, x, kFree, out, y);
  const double g = 1.0 / 6, reach = 0.95, delta = reach - 0.5, s = delta / 0.375;
  EXPECT_LE(dist(out[0].dx, as<T>(VD{0, 0, -0.25 * s})), tol<T>(4));
  EXPECT_LE(dist(out[1].dx, as<T>(VD{0, 0, -0.5 * s})), tol<T>(4));
  EXPECT_LE(dist(out[2].dx, as<T>(VD{0, 0, -0.25 * s})), tol<T>(4));
  EXPECT_LE(dist(out[1].dx, Vec3<T>{0, 0, T(-0.6)}), tol<T>(4));  // the same by hand
  EXPECT_LE(dist(T(0.25) * y[0] + T(0.5) * y[1] + T(0.25) * y[2], Vec3<T>{2, 1, T(-0.45)}), tol<T>(4));
  EXPECT_NEAR(deepest_distance(last_capsule(tools), y), reach / std::sqrt(1 + delta * delta * g * g), tol<T>(4));
  EXPECT_NEAR(deepest_distance(last_capsule(tools), y), 0.947339, 1e-6);
}

TYPED_TEST(SweepTriangle, SubChecksAreStepsOfOneCheck) {
  using T = TypeParam;
  // the n checks of one step visit the same capsules as n steps of one
  // check each, so the two sweeps agree (to the rounding of adding the
  // partial corrections back onto the positions)
  Rng rng(55);
  int compared = 0, touched = 0;
  // 1200 cases: a face that comes within its allowance of the tool is not moved, so fewer cases touch than under
  // the old rule (98 of the first 1000)
  for (int it = 0; compared < 1200 && it < 100000; ++it) {
    Vec3<T> P[3];
    ContactTools<T> tools;
    if (!random_approach(rng, P, tools, it % 2 == 0) || tools.tool[0].substeps < 2) continue;
    ++compared;
    const int m = tools.tool[0].substeps;
    for (int j = 1; j <= m; ++j) {
      ContactTools<T> split = tools;
      split.steps = m;
      split.tool[0].substeps = 1;
      const Capsule<T> a = tool_capsule(tools.tool[0], 1, 0, j), b = tool_capsule(split.tool[0], m, j - 1, 1);
      ASSERT_TRUE(a.a.x == b.a.x && a.a.y == b.a.y && a.a.z == b.a.z && a.b.x == b.b.x && a.b.y == b.b.y &&
                  a.b.z == b.b.z);
    }
    CornerContact<T> out[3];
    Vec3<T> y[3];
    sweep(tools, 0, P, kFree, out, y);
    ContactTools<T> split = tools;
    split.steps = m;
    split.tool[0].substeps = 1;
    Vec3<T> xs[3] = {P[0], P[1], P[2]};
    for (int k = 0; k < m; ++k) {
      Vec3<T> next[3];
      CornerContact<T> o[3];
      sweep(split, k, xs, kFree, o, next);
      for (int i = 0; i < 3; ++i) xs[i] = next[i];
    }
    touched += out[0].tool >= 0 || out[1].tool >= 0 || out[2].tool >= 0;
    for (int i = 0; i < 3; ++i) EXPECT_LE(dist(y[i], xs[i]), 1e3 * tol<T>(3)) << "case " << it << " corner " << i;
  }
  EXPECT_EQ(compared, 1200);
  EXPECT_GT(touched, 100);
}

TYPED_TEST(SweepTriangle, EachCornerRecordsTheLastToolThatMovedIt) {
  using T = TypeParam;
  const Vec3<T> x[3] = {{0, 0, 0}, {4, 0, 0}, {0, 4, 0}};
  ContactTools<T> tools{};
  tools.n_tools = 2;
  tools.steps = 1;
  tools.face = 0;
  tools.tool[0] = static_tool<T>({4.1, 0, 0.1}, {0, 0, 1}, 0.3, 0).tool[0];  // on P1
  tools.tool[1] = static_tool<T>({0, 4.1, 0.1}, {0, 0, 1}, 0.3, 0).tool[0];  // on P2
  CornerContact<T> out[3];
  Vec3<T> y[3];
  sweep(tools, 0, x, kFree, out, y);
  EXPECT_EQ(out[0].tool, -1);
  EXPECT_EQ(out[1].tool, 0);
  EXPECT_EQ(out[2].tool, 1);
  EXPECT_NEAR(axis_distance(last_capsule(tools, 0), y[1]), 0.3, tol<T>(4));
  EXPECT_NEAR(axis_distance(last_capsule(tools, 1), y[2]), 0.3, tol<T>(4));
  // both on P0: the later tool's push is the one recorded, and P0 ends outside both
  tools.tool[0] = static_tool<T>({-0.1, 0, 0.2}, {0, 0, 1}, 0.3, 0).tool[0];
  tools.tool[1] = static_tool<T>({0, -0.1, 0.2}, {0, 0, 1}, 0.3, 0).tool[0];
  sweep(tools, 0, x, kFree, out, y);
  EXPECT_EQ(out[0].tool, 1);
  EXPECT_GE(axis_distance(last_capsule(tools, 1), y[0]), 0.3 - tol<T>(4));
}

TYPED_TEST(SweepTriangle, ToolCapsuleInterpolatesAcrossStepsAndSubChecks) {
  using T = TypeParam;
  const VD tip0{0, 0, 1}, tip1{1, 2, -1}, axis0{0, 0, 1}, axis1{1, 0, 0};
  const auto tools = one_tool<T>(tip0, axis0, tip1, axis1, 0.25, 2, 3, 4);
  for (int k = 0; k < 4; ++k)
    for (int j = 1; j <= 3; ++j) {
      const Capsule<T> cap = tool_capsule(tools.tool[0], 4, k, j);
      const double s = (k + j / 3.0) / 4;
      EXPECT_LE(dist(cap.a, as<T>(tip0 + s * (tip1 - tip0))), tol<T>(2));
      const VD axis = unit_or(axis0 + s * (axis1 - axis0), axis0);
      EXPECT_LE(dist(cap.b, as<T>(tip0 + s * (tip1 - tip0) + 2.0 * axis)), tol<T>(2));
      EXPECT_EQ(cap.r, T(0.25));
    }
  const Capsule<T> end = tool_capsule(tools.tool[0], 4, 3, 3);
  EXPECT_LE(dist(end.a, as<T>(tip1)), tol<T>(2));
  EXPECT_LE(dist(end.b, as<T>(tip1 + 2.0 * axis1)), tol<T>(2));
}

// ---------------------------------------------------------------- face_allowance

template <class T>
class FaceAllowance : public ::testing::Test {};
TYPED_TEST_SUITE(FaceAllowance, Scalars);

/// The equilateral triangle inscribed in the circle of radius rho about
/// `centre` in the plane of the orthonormal e1, e2 (circumradius rho, side
/// rho sqrt(3)); corners rounded to T.
template <class T>
void equilateral(VD centre, VD e1, VD e2, double rho, Vec3<T> P[3]) {
  for (int k = 0; k < 3; ++k) {
    const LD a = 2 * LD(3.14159265358979323846264338327950288L) * k / 3;
    const VL p = VL{centre.x, centre.y, centre.z} + (LD(rho) * std::cos(a)) * VL{e1.x, e1.y, e1.z} +
                 (LD(rho) * std::sin(a)) * VL{e2.x, e2.y, e2.z};
    P[k] = {T(p.x), T(p.y), T(p.z)};
  }
}

/// A tilted plane away from the origin (the sweep's faces are anywhere).
const VD kCentre{1, -2, 3};
const VD kE1 = unit_or(VD{1, 2, 2}, VD{1, 0, 0});
const VD kE2 = unit_or(cross(VD{1, 2, 2}, VD{0, 0, 1}), VD{0, 1, 0});

template <class T>
T allowance(const Vec3<T> P[3], double r) {
  return face_allowance(P, T(r));
}

TYPED_TEST(FaceAllowance, BelowTheCapItIsTheSagitta) {
  using T = TypeParam;
  // an equilateral triangle of circumradius rho = s / sqrt(3) on a sphere of
  // radius r reaches r - sqrt(r^2 - rho^2) into it. r = 1, rho = 0.28 (side
  // 0.28 sqrt(3) = 0.485): sqrt(1 - 0.0784) = sqrt(0.9216) = 0.96, sagitta
  // 0.04 < the cap 0.05. r = 2.5, rho = 0.7: sqrt(6.25 - 0.49) = sqrt(5.76) =
  // 2.4, sagitta 0.1 < the cap 0.125.
  struct Case {
    double r, rho, sagitta;
  };
  for (const Case k : {Case{1, 0.28, 0.04}, Case{2.5, 0.7, 0.1}}) {
    Vec3<T> P[3];
    equilateral(kCentre, kE1, kE2, k.rho, P);
    ASSERT_NEAR(dist(P[0], P[1]), k.rho * std::sqrt(3.0), tol<T>(4)) << "r " << k.r;
    const double a = double(allowance(P, k.r));
    // 64 ulps of the value (measured: under one ulp, float and double, the corners' rounding included)
    EXPECT_NEAR(a, k.sagitta, tol<T>(k.sagitta)) << "r " << k.r;
    EXPECT_NEAR(a, ref_allowance(P, k.r), tol<T>(k.sagitta)) << "r " << k.r;  // the same triangle, as rounded
    EXPECT_LT(a, 0.05 * k.r);
  }
}

TYPED_TEST(FaceAllowance, AboveTheCapItIsTheCap) {
  using T = TypeParam;
  // r = 1: rho = 0.6 has sagitta 1 - sqrt(0.64) = 0.2, rho = 0.32 just past
  // where the sagitta reaches the cap (rho = sqrt(1 - 0.95^2) = 0.3122) has
  // 1 - sqrt(0.8976) = 0.0526: both give 0.05 r. Scaled to r = 2e-3 (a 2 mm
  // tool): 1e-4.
  for (const double r : {1.0, 2e-3})
    for (const double rho : {0.6, 0.32}) {
      Vec3<T> P[3];
      equilateral(r * kCentre, kE1, kE2, rho * r, P);
      EXPECT_NEAR(double(allowance(P, r)), 0.05 * r, tol<T>(r, 2)) << "r " << r << " rho " << rho;
    }
}

TYPED_TEST(FaceAllowance, CircumradiusAtLeastTheToolsRadiusGivesTheCap) {
  using T = TypeParam;
  const double r = 1;
  for (const double rho : {1.0, 1.5, 40.0}) {  // rho = r exactly: sagitta r, and either side of it rounding
    Vec3<T> P[3];
    equilateral(kCentre, kE1, kE2, rho, P);
    EXPECT_NEAR(double(allowance(P, r)), 0.05, tol<T>(r, 2)) << "rho " << rho;
  }
  // a small sliver with a big circumcircle: (0,0,0), (1,0,0), (0.5,0.01,0):
  // edges 1 and 0.5001 twice, area 0.005, rho = 1 x 0.5001^2 / 0.02 =
  // 12.505 >= r although the face is 1 long
  const Vec3<T> sliver[3] = {{0, 0, 0}, {1, 0, 0}, {T(0.5), T(0.01), 0}};
  EXPECT_NEAR(double(allowance(sliver, r)), 0.05, tol<T>(r, 2));
  EXPECT_NEAR(ref_allowance(sliver, r), 0.05, 1e-15);
}

TYPED_TEST(FaceAllowance, DegenerateFaceGivesTheCapFinite) {
  using T = TypeParam;
  // rho is infinite (or 0 / 0): the cap, not a NaN or an infinity
  const Vec3<T> faces[][3] = {
      {{0, 0, 0}, {1, 0, 0}, {3, 0, 0}},                                               // collinear, exactly
      {{T(0.1), T(0.2), T(0.3)}, {T(0.2), T(0.4), T(0.6)}, {T(0.3), T(0.6), T(0.9)}},  // collinear to rounding
      {{1, 2, 3}, {1, 2, 3}, {2, 2, 3}},                                               // two corners on one point
      {{1, 2, 3}, {1, 2, 3}, {1, 2, 3}},                                               // a point
  };
  for (const double r : {1.0, 2e-3})
    for (const auto& P : faces) {
      const T a = allowance(P, r);
      EXPECT_TRUE(std::isfinite(double(a))) << "r " << r << " face " << str(P[0]) << str(P[1]) << str(P[2]);
      EXPECT_NEAR(double(a), 0.05 * r, tol<T>(r, 2)) << "r " << r << " face " << str(P[0]) << str(P[1]) << str(P[2]);
    }
}

TYPED_TEST(FaceAllowance, ContinuousWhereTheSagittaMeetsTheCap) {
  using T = TypeParam;
  // the sagitta equals the cap 0.05 r at rho* = r sqrt(1 - 0.95^2) =
  // 0.31225 r, where its slope d/drho (r - sqrt(r^2 - rho^2)) = rho / sqrt(r^2
  // - rho^2) = 0.31225 / 0.95 = 0.3287. Across rho* in steps h the allowance
  // changes by at most 0.33 h plus rounding: no jump, and it stays within
  // rounding of the independent value on both sides.
  const double r = 1, rho_star = std::sqrt(1 - 0.95 * 0.95), h = 1e-5;
  ASSERT_NEAR(rho_star, 0.31225, 1e-5);
  double prev = 0, worst_step = 0;
  int below = 0, above = 0;
  for (int i = -1000; i <= 1000; ++i) {
    const double rho = rho_star + i * h;
    Vec3<T> P[3];
    equilateral(VD{0, 0, 0}, kE1, kE2, rho, P);
    const double a = double(allowance(P, r));
    EXPECT_NEAR(a, ref_allowance(P, r), tol<T>(r)) << "rho " << rho;
    EXPECT_LE(a, 0.05 * r + tol<T>(r, 2)) << "rho " << rho;
    if (i > -1000) {
      EXPECT_LE(std::fabs(a - prev), 0.33 * h + tol<T>(r)) << "rho " << rho;
      worst_step = std::max(worst_step, std::fabs(a - prev));
    }
    below += a < 0.05 * r - 10 * h;
    above += std::fabs(a - 0.05 * r) <= tol<T>(r, 2);
    prev = a;
  }
  EXPECT_GT(worst_step, 0.3 * h);  // the sagitta side was sampled
  EXPECT_GT(below, 500);
  EXPECT_GT(above, 500);
}

TYPED_TEST(FaceAllowance, TinyFaceOnABigToolHasNoCancellation) {
  using T = TypeParam;
  // rho = 1e-4 r: the sagitta r - sqrt(r^2 - rho^2) = rho^2 / (2 r) (1 +
  // rho^2 / (4 r^2) + ...) = 5e-9 r; taken as a difference in float it is
  // lost (rho^2 / r^2 = 1e-8 < eps). The face near the origin, so that its
  // corners are exact to float's digits (measured: relative 2e-7 in float,
  // 2.5e-9 -- the series' next term -- in double).
  for (const double r : {5.0, 1.0, 2e-3}) {
    const double rho = 1e-4 * r;
    Vec3<T> P[3];
    equilateral(VD{0, 0, 0}, kE1, kE2, rho, P);
    const double a = double(allowance(P, r)), want = rho * rho / (2 * r);
    EXPECT_NEAR(a, want, 1e-3 * want) << "r " << r;
    EXPECT_GT(a, 0.0) << "r " << r;
  }
}

/// The faces of a patch around the lowest point of a sphere of radius r
/// centred at `centre`: an equilateral lattice of spacing h in x, y about
/// the centre's foot, lifted onto the sphere (z = centre.z - sqrt(r^2 - x^2
/// - y^2), long double), each corner rounded to T and then, while it is not
/// at least 4 eps r outside the sphere (long double), lowered by eps r: on
/// the surface to rounding, never inside as T sees it. Counterclockwise seen
/// from +z: the outward normals point up, toward the tool. All angles are
/// acute (about 60 degrees).
template <class T>
std::vector<std::array<Vec3<T>, 3>> sphere_patch(double r, VD centre, double h) {
  const int n = 3;
  const auto corner = [&](int i, int j) {
    const LD x = h * (i + 0.5L * j), y = h * (std::sqrt(3.0L) / 2 * j);
    Vec3<T> p{T(x + centre.x), T(y + centre.y), T(LD(centre.z) - std::sqrt(LD(r) * r - x * x - y * y))};
    while (norm(L(p) - L(as<T>(centre))) < LD(r) * (1 + 4 * LD(kEps<T>))) p.z = p.z - T(kEps<T> * r);
    return p;
  };
  std::vector<std::array<Vec3<T>, 3>> faces;
  for (int i = -n; i < n; ++i)
    for (int j = -n; j < n; ++j) {
      faces.push_back({corner(i, j), corner(i + 1, j), corner(i, j + 1)});
      faces.push_back({corner(i + 1, j), corner(i + 1, j + 1), corner(i, j + 1)});
    }
  return faces;
}

TYPED_TEST(FaceAllowance, SphereOnAPatchWithItsCornersOnItMovesNothing) {
  using T = TypeParam;
  // r = 5, centre (0.3, -0.2, 5): its lowest point is over (0.3, -0.2, 0).
  // Lattice spacing h = 0.25: the faces have circumradius about h / sqrt(3)
  // = 0.144, so their sagitta is about 0.144^2 / (2 r) = 2.1e-3, far below
  // the cap 0.25: the allowance is the sagitta itself. The sphere cuts the
  // plane of a face whose corners lie on it in the face's circumcircle, and
  // the face's deepest point, its circumcentre (inside: all angles acute),
  // lies sqrt(r^2 - rho^2) = r - sagitta = reach from the centre: face
  // contact has nothing to do (the old rule moved every face by its
  // sagitta, 2e-3). The corners lie 4 to 5 eps r outside the sphere
  // (sphere_patch), so node contact sees none inside, and the face's deepest
  // point is then as far outside its reach (measured: at least 4 eps r in
  // the scalar's own arithmetic; with the corners rounded to the nearest,
  // rounding alone decides both). Pushed 0.1 r = 0.5 further into the sphere (+z), the
  // corners are inside: node contact moves each radially back onto the
  // sphere, and the face is again within its allowance.
  const double r = 5, h = 0.25;
  const VD centre{0.3, -0.2, 5};
  const auto tools = static_tool<T>(centre, {0, 0, 1}, r, 0);
  auto node_only = tools;
  node_only.face = 0;
  const Capsule<T> cap = last_capsule(tools);
  const auto faces = sphere_patch<T>(r, centre, h);
  ASSERT_EQ(faces.size(), 72u);
  for (const auto& f : faces) {
    const Vec3<T> x[3] = {f[0], f[1], f[2]};
    const std::string where = "face " + str(x[0]) + " " + str(x[1]) + " " + str(x[2]);
    const double allow = ref_allowance(x, r);
    ASSERT_GT(allow, 1.5e-3) << where;  // what the old rule moved it by: 2500 eps r in float
    ASSERT_LT(allow, 2.5e-3) << where;
    for (int i = 0; i < 3; ++i) ASSERT_NEAR(axis_distance(cap, x[i]), r, tol<T>(r)) << where;
    ASSERT_NEAR(deepest_distance(cap, x), r - allow, tol<T>(r)) << where;  // its deepest point is at reach
    CornerContact<T> out[3];
    Vec3<T> y[3];
    sweep(tools, 0, x, kFree, out, y);
    for (int i = 0; i < 3; ++i) {  // nothing moves (the corners are not inside, the face within its allowance)
      EXPECT_TRUE(out[i].dx.x == T(0) && out[i].dx.y == T(0) && out[i].dx.z == T(0)) << where << " corner " << i;
      EXPECT_EQ(out[i].tool, -1) << where << " corner " << i;
      EXPECT_EQ(out[i].blocked, 0) << where << " corner " << i;
    }
    // pushed 0.1 r into the sphere: node contact moves every corner radially back onto it, by r - sqrt(r^2 -
    // r cos(theta) + 0.25) >= 5 - sqrt(25.25 - 5 x 0.9657) = 0.481 (theta, the corner's angle from the lowest
    // point, is at most asin(sqrt(27) h / r) = 15.1 degrees); face contact adds nothing but rounding (the
    // corners are on the sphere again, the face at its reach: either side of it by rounding)
    Vec3<T> in[3];
    for (int i = 0; i < 3; ++i) in[i] = x[i] + Vec3<T>{0, 0, T(0.1 * r)};
    CornerContact<T> o1[3], o0[3];
    Vec3<T> y1[3], y0[3];
    sweep(tools, 0, in, kFree, o1, y1);
    sweep(node_only, 0, in, kFree, o0, y0);
    for (int i = 0; i < 3; ++i) {
      EXPECT_GT(double(norm(o1[i].dx)), 0.48) << where << " corner " << i;
      EXPECT_EQ(o1[i].tool, 0) << where << " corner " << i;
      EXPECT_NEAR(axis_distance(cap, y1[i]), r, tol<T>(r)) << where << " corner " << i;
      EXPECT_LE(dist(y1[i], y0[i]), tol<T>(r)) << where << " corner " << i;
    }
    EXPECT_GE(deepest_distance(cap, y1), ref_reach(y1, r) - tol<T>(r)) << where;
  }
}

// ---------------------------------------------------------------- merge_corner (core/node_rules.hpp)

template <class T>
class MergeCorner : public ::testing::Test {};
TYPED_TEST_SUITE(MergeCorner, Scalars);

template <class T>
CornerContact<T> proposal(VD dx, int tool = 0, std::uint8_t blocked = 0) {
  return {as<T>(dx), static_cast<signed char>(tool), blocked};
}

/// The backends' merge: merge_proposals over the list (kMergePasses passes).
template <class T>
NodeContact<T> merged(std::initializer_list<CornerContact<T>> list) {
  const std::vector<CornerContact<T>> v(list);
  return merge_proposals<T>(int(v.size()), [&](int j) { return v[j]; });
}

TYPED_TEST(MergeCorner, SingleProposalIsTakenExactly) {
  using T = TypeParam;
  const auto p = proposal<T>({0.1, -0.2, 0.3}, 2);
  const NodeContact<T> a = merged<T>({p});
  EXPECT_TRUE(a.dx.x == p.dx.x && a.dx.y == p.dx.y && a.dx.z == p.dx.z);
  EXPECT_EQ(a.kind, kPushed);
  EXPECT_EQ(a.tool, 2);
  EXPECT_EQ(a.largest2, dot(p.dx, p.dx));
  // a pushed proposal after blocked ones is taken exactly too
  const NodeContact<T> b = merged<T>({proposal<T>({0, 0, 0}, 1, kRigidContact), p});
  EXPECT_TRUE(b.dx.x == p.dx.x && b.dx.y == p.dx.y && b.dx.z == p.dx.z);
  EXPECT_EQ(b.kind, kPushed);
  EXPECT_EQ(b.tool, 2);
}

TYPED_TEST(MergeCorner, SameDirectionGivesTheLargerAndOrthogonalGivesTheSum) {
  using T = TypeParam;
  const VD u = unit_or(VD{1, 2, -2}, VD{1, 0, 0}), v = unit_or(cross(u, VD{0, 0, 1}), VD{1, 0, 0});
  for (const auto& [a, b] : {std::pair{0.3, 0.7}, std::pair{0.7, 0.3}}) {
    const NodeContact<T> m = merged<T>({proposal<T>(a * u, 0), proposal<T>(b * u, 1)});
    EXPECT_LE(dist(m.dx, as<T>(std::max(a, b) * u)), tol<T>(1));
    EXPECT_EQ(m.tool, a > b ? 0 : 1);  // the tool of the largest proposal
    EXPECT_NEAR(double(m.largest2), std::max(a, b) * std::max(a, b), tol<T>(1));
  }
  const NodeContact<T> s = merged<T>({proposal<T>(0.3 * u, 0), proposal<T>(0.5 * v, 1)});
  EXPECT_LE(dist(s.dx, as<T>(0.3 * u + 0.5 * v)), tol<T>(1));
  EXPECT_EQ(s.tool, 1);
  // a smaller proposal along the same line adds nothing; a zero one neither
  const NodeContact<T> t = merged<T>({proposal<T>(0.5 * u), proposal<T>(0.2 * u), proposal<T>({0, 0, 0})});
  EXPECT_LE(dist(t.dx, as<T>(0.5 * u)), tol<T>(1));
  EXPECT_EQ(t.kind, kPushed);
}

TYPED_TEST(MergeCorner, ResultSatisfiesEveryProposalOfAnAcuteSet) {
  using T = TypeParam;
  // proposals within 45 degrees of a common direction (pairwise at most 90
  // degrees, as the faces around one node give against one tool): adding a
  // shortfall along p_j never lowers dx . p_i for i != j, so every proposal
  // stays satisfied
  Rng rng(61);
  for (int it = 0; it < 3000; ++it) {
    const VD axis = rng.unit();
    const int n = rng.integer(1, 6);
    NodeContact<T> acc;
    CornerContact<T> list[6];
    int largest = 0;
    double largest_len = -1;
    for (int i = 0; i < n; ++i) {
      VD d;
      do d = unit_or(axis + rng.uni(0, 1) * rng.unit(), axis);
      while (dot(d, axis) < std::cos(M_PI / 4));
      const double len = rng.uni(1e-4, 1e-2);
      list[i] = proposal<T>(len * d, i);
      merge_corner(acc, list[i]);
      if (double(dot(list[i].dx, list[i].dx)) > largest_len) {
        largest_len = double(dot(list[i].dx, list[i].dx));
        largest = i;
      }
    }
    for (int i = 0; i < n; ++i) {
      const VL p = L(list[i].dx);
      EXPECT_GE(double(dot(L(acc.dx), p) / norm(p)), double(norm(p)) - tol<T>(1e-2, 64 * n)) << "case " << it;
    }
    EXPECT_EQ(acc.tool, largest);
    EXPECT_EQ(acc.kind, kPushed);
  }
}

// Proposals more than 90 degrees apart (two tools squeezing a node, a node
// on a sharp ridge pushed by two faces): one pass satisfies only the later
// one; the passes of merge_proposals approach both, each pass shrinking the
// shortfall by cos(angle - 90 deg). p1 = (1, 0, 0), p2 = (-1, 1, 0) / sqrt 2
// (135 degrees): after 4 passes p2 is met and p1 within cos(45)^4 = 1/4.
TYPED_TEST(MergeCorner, ObtuseProposalsAreApproachedPassByPass) {
  using T = TypeParam;
  const VD p1{1, 0, 0}, p2 = (1 / std::sqrt(2.0)) * VD{-1, 1, 0};
  const NodeContact<T> m = merged<T>({proposal<T>(p1, 0), proposal<T>(p2, 1)});
  EXPECT_GE(double(dot(m.dx, as<T>(p2))), 1 - tol<T>(1)) << "dx = " << str(m.dx);
  const double shortfall = 1 - double(dot(m.dx, as<T>(p1)));
  EXPECT_LE(shortfall, std::pow(std::sqrt(0.5), kMergePasses) + tol<T>(1)) << "dx = " << str(m.dx);
  EXPECT_GT(shortfall, 0.0) << "the bound is reached from above: the passes are what meets it";
  // a single pass leaves p1's shortfall at 1.2: the passes matter
  NodeContact<T> one;
  merge_corner(one, proposal<T>(p1, 0));
  merge_corner(one, proposal<T>(p2, 1));
  EXPECT_GT(1 - double(dot(one.dx, as<T>(p1))), 1.0);
}

// merge_proposals ends its passes once one leaves the state's bits as they
// were. Against the passes written out in full (kMergePasses of them), on random proposal lists -- near-parallel ones,
// scattered ones with obtuse pairs, zero and blocked ones among them --
// the same bits, in both the looped and the unrolled merge; and a node
// pushed by proposals within 90 degrees of each other is nearly always done
// in two passes.
TYPED_TEST(MergeCorner, PassesEndOnceOneChangesNothingWithTheSameBits) {
  using T = TypeParam;
  std::mt19937 rng(20261126);
  int early = 0, near_parallel = 0, two_passes = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    const int count = 1 + trial % 12;
    const bool scattered = trial % 3 == 0;
    const std::vector<CornerContact<T>> v = test::random_proposal_list<T>(rng, count, scattered);
    int calls = 0;
    const NodeContact<T> a = merge_proposals<T>(count, [&](int j) {
      ++calls;
      return v[j];
    });
    const NodeContact<T> b = merge_proposals_unrolled<12, T>(count, [&](int j) { return v[j]; });
    const NodeContact<T> ref = test::merge_every_pass<T>(count, [&](int j) { return v[j]; });
    ASSERT_TRUE(same_bits(a, ref)) << "trial " << trial << ": dx " << str(a.dx) << " against " << str(ref.dx);
    ASSERT_TRUE(same_bits(b, ref)) << "trial " << trial << " (unrolled)";
    if (ref.kind == kPushed && calls < kMergePasses * count) ++early;
    if (!scattered && ref.kind == kPushed) {
      ++near_parallel;
      two_passes += calls == 2 * count;
    }
  }
  EXPECT_GT(early, 10000) << "most pushed nodes end their passes early";
  // (a later proposal's shortfall can move the sum by rounding in the second pass: 1 in 13,000 here)
  EXPECT_GT(two_passes, 0.99 * near_parallel) << two_passes << " of " << near_parallel;
  // and a state that differs only in the sign of a zero is not the same bits
  NodeContact<T> plus, minus;
  minus.dx.x = -T(0);
  EXPECT_FALSE(same_bits(plus, minus));
  EXPECT_TRUE(same_bits(plus, NodeContact<T>{}));
}

TYPED_TEST(MergeCorner, BlockedOnlyProposalsRigidWinsOverOutside) {
  using T = TypeParam;
  const auto rigid = proposal<T>({0, 0, 0}, 1, kRigidContact), outside = proposal<T>({0, 0, 0}, 2, kOutsideRegion);
  const auto none = proposal<T>({0, 0, 0}, 3, 0);
  {
    const NodeContact<T> a = merged<T>({none});
    EXPECT_EQ(a.kind, kNoContact);
    EXPECT_EQ(a.tool, -1);
  }
  {
    const NodeContact<T> a = merged<T>({outside});
    EXPECT_EQ(a.kind, kOutsideRegion);
    EXPECT_EQ(a.tool, 2);
  }
  {
    const NodeContact<T> a = merged<T>({outside, rigid});
    EXPECT_EQ(a.kind, kRigidContact);
    EXPECT_EQ(a.tool, 1);
  }
  {
    const NodeContact<T> a = merged<T>({rigid, outside, none});
    EXPECT_EQ(a.kind, kRigidContact);
    EXPECT_EQ(a.tool, 1);
    EXPECT_TRUE(a.dx.x == T(0) && a.dx.y == T(0) && a.dx.z == T(0));
  }
  {  // a pushed proposal wins over blocked ones, before or after
    const auto push = proposal<T>({0, 0, 1e-3}, 0);
    for (const NodeContact<T>& a : {merged<T>({rigid, push, outside}), merged<T>({push, rigid})}) {
      EXPECT_EQ(a.kind, kPushed);
      EXPECT_EQ(a.tool, 0);
      EXPECT_TRUE(a.dx.x == push.dx.x && a.dx.y == push.dx.y && a.dx.z == push.dx.z);
    }
  }
}

// ---------------------------------------------------------------- rotate_between, grasped_position

template <class T>
class Rotation : public ::testing::Test {};
TYPED_TEST_SUITE(Rotation, Scalars);

/// Checks that v -> rotate_between(a, b, v) is a rotation taking a to b,
/// to within `e`: R a = b, R preserves lengths and dot products, det +1.
template <class T>
void expect_rotation(Vec3<T> a, Vec3<T> b, double e, const std::string& where) {
  EXPECT_LE(dist(rotate_between(a, b, a), b), e) << where;
  const Vec3<T> u{T(0.3), T(-1.2), T(0.5)}, v{T(-0.7), T(0.1), T(0.9)};
  const Vec3<T> Ru = rotate_between(a, b, u), Rv = rotate_between(a, b, v);
  EXPECT_NEAR(double(norm(L(Ru))), double(norm(L(u))), 2 * e) << where;
  EXPECT_NEAR(double(norm(L(Rv))), double(norm(L(v))), 2 * e) << where;
  EXPECT_NEAR(double(dot(L(Ru), L(Rv))), double(dot(L(u), L(v))), 4 * e) << where;
  EXPECT_LE(dist(rotate_between(a, b, cross(u, v)), cross(Ru, Rv)), 8 * e) << where;  // not a reflection
}

TYPED_TEST(Rotation, RotatesAOntoBAndIsARotation) {
  using T = TypeParam;
  Rng rng(71);
  for (int it = 0; it < 3000; ++it) {
    const Vec3<T> a = unit_or(as<T>(rng.unit()), Vec3<T>{0, 0, 1}), b = unit_or(as<T>(rng.unit()), Vec3<T>{0, 0, 1});
    const double c = dot(as<double>(a), as<double>(b));
    if (c < -0.9) continue;  // near-opposite: see the next tests
    expect_rotation(a, b, tol<T>(4), "a " + str(a) + " b " + str(b));
    // the smallest rotation: a vector perpendicular to both stays put
    const Vec3<T> k = unit_or(cross(a, b), Vec3<T>{0, 0, 0});
    if (norm(cross(a, b)) > T(0.1)) {
      EXPECT_LE(dist(rotate_between(a, b, k), k), tol<T>(4));
    }
  }
}

TYPED_TEST(Rotation, IdentityWhenEqualHalfTurnWhenOpposite) {
  using T = TypeParam;
  Rng rng(72);
  for (int it = 0; it < 200; ++it) {
    const Vec3<T> a = unit_or(as<T>(rng.unit()), Vec3<T>{0, 0, 1});
    const Vec3<T> v = as<T>(rng.vec());
    EXPECT_LE(dist(rotate_between(a, a, v), v), tol<T>(1)) << str(a);
    const Vec3<T> b = T(-1) * a;
    expect_rotation(a, b, tol<T>(4), "opposite " + str(a));
    // a half turn: twice is the identity
    EXPECT_LE(dist(rotate_between(a, b, rotate_between(a, b, v)), v), tol<T>(4)) << str(a);
  }
  // the axis-aligned case by hand: +z to -z, a half turn about any_perpendicular(+z) = +y
  EXPECT_LE(dist(rotate_between(Vec3<T>{0, 0, 1}, Vec3<T>{0, 0, -1}, Vec3<T>{1, 2, 3}), Vec3<T>{-1, 2, -3}), 0.0);
}

// FINDING (rotate_between, near-opposite vectors): the Rodrigues form
// c v + k x v + (k.v) / (1 + c) k divides by 1 + c = 1 + dot(a, b), whose
// rounding (eps absolute) is a relative error eps / (1 + c); k k^T / (1 + c)
// is of size 1, so R stops being a rotation by about eps / (1 + c). In float
// that is 1e-4 at 175 degrees and up to 20% at 179.9 degrees. Repro
// (float): a = (0, 0, 1), b = (sin 0.002, 0, -cos 0.002) (179.89 degrees,
// above the -0.999999 snap): |R (0.3, -1.2, 0.5)| = 1.30595 instead of
// 1.33417 (2%); random directions at that angle give up to 20%. (double:
// 1e-9 there, still 1e4 ulps.) A fix: compute 1 + c as |a + b|^2 / 2, which is
// exact to a few ulps; the snap threshold then also need not be so coarse
// (it maps b to -a for angles within 0.08 degrees of opposite, an error of
// up to 1.4e-3 rad in the grasped offset's direction).
TYPED_TEST(Rotation, NearlyOppositeVectorsStillGiveARotation) {
  using T = TypeParam;
  Rng rng(73);
  for (const double from_pi : {0.3, 0.1, 0.03, 0.01, 0.003}) {
    for (int it = 0; it < 50; ++it) {
      const VD a = rng.unit(), perp = unit_or(cross(a, rng.unit()), any_perpendicular(a));
      const double th = M_PI - from_pi;
      const Vec3<T> af = unit_or(as<T>(a), Vec3<T>{0, 0, 1}),
                    bf = unit_or(as<T>(std::cos(th) * a + std::sin(th) * perp), Vec3<T>{0, 0, 1});
      // the smallest rotation's axis a x b / |a x b| is uncertain by eps /
      // |a x b|, which moves R a by as much: the inherent error
      const double e = tol<T>(4) / std::sin(from_pi);
      expect_rotation(af, bf, e, "pi - " + std::to_string(from_pi) + " a " + str(af) + " b " + str(bf));
      if (::testing::Test::HasFailure()) return;  // one case is enough to show it
    }
  }
}

TYPED_TEST(Rotation, GraspedPositionFollowsTheTool) {
  using T = TypeParam;
  Rng rng(74);
  for (int it = 0; it < 1000; ++it) {
    const Vec3<T> tip = as<T>(rng.vec()), axis0 = as<T>(rng.unit()), axis = as<T>(rng.unit());
    if (dot(as<double>(axis0), as<double>(axis)) < -0.9) continue;
    const Vec3<T> offset = as<T>(0.01 * rng.vec());
    const Vec3<T> x = grasped_position(tip, axis, axis0, offset);
    // at the same distance from the tip, and the part along the axis follows the axis
    EXPECT_NEAR(dist(x, tip), double(norm(L(offset))), tol<T>(1));
    const Vec3<T> along = grasped_position(tip, axis, axis0, T(0.01) * axis0);
    EXPECT_LE(dist(along, tip + T(0.01) * axis), tol<T>(1));
    // no rotation: a translation
    EXPECT_LE(dist(grasped_position(tip, axis0, axis0, offset), tip + offset), tol<T>(1));
  }
}

// ---------------------------------------------------------------- interpolate_pose, contact_substeps

template <class T>
class Poses : public ::testing::Test {};
TYPED_TEST_SUITE(Poses, Scalars);

TYPED_TEST(Poses, InterpolatePose) {
  using T = TypeParam;
  Rng rng(81);
  for (int it = 0; it < 1000; ++it) {
    const Vec3<T> tip0 = as<T>(rng.vec()), tip1 = as<T>(rng.vec());
    const Vec3<T> a0 = as<T>(rng.unit()), a1 = as<T>(rng.unit());
    if (dot(as<double>(a0), as<double>(a1)) < -0.99) continue;
    Vec3<T> tip, axis;
    interpolate_pose(tip0, a0, tip1, a1, T(0), tip, axis);
    EXPECT_TRUE(tip.x == tip0.x && tip.y == tip0.y && tip.z == tip0.z);
    EXPECT_LE(dist(axis, a0), tol<T>(1));
    interpolate_pose(tip0, a0, tip1, a1, T(1), tip, axis);
    EXPECT_LE(dist(tip, tip1), tol<T>(1));
    EXPECT_LE(dist(axis, a1), tol<T>(1));
    interpolate_pose(tip0, a0, tip1, a1, T(0.5), tip, axis);
    EXPECT_LE(dist(tip, T(0.5) * (tip0 + tip1)), tol<T>(1));
    EXPECT_LE(dist(axis, unit_or(a0 + a1, a0)), tol<T>(1));  // the bisector
    const T s = T(rng.uni(0, 1));
    interpolate_pose(tip0, a0, tip1, a1, s, tip, axis);
    EXPECT_NEAR(double(norm(L(axis))), 1.0, tol<T>(1));
    // along the chord's point a0 + s (a1 - a0)
    EXPECT_LE(double(norm(cross(L(axis), L(a0) + LD(s) * (L(a1) - L(a0))))), tol<T>(1));
  }
  // opposite axes half way: the chord passes through 0 -> a0 is kept
  Vec3<T> tip, axis;
  interpolate_pose(Vec3<T>{0, 0, 0}, Vec3<T>{0, 0, 1}, Vec3<T>{1, 0, 0}, Vec3<T>{0, 0, -1}, T(0.5), tip, axis);
  EXPECT_TRUE(axis.x == T(0) && axis.y == T(0) && axis.z == T(1));
}

/// Largest distance the tip or the shaft's end moves between two
/// consecutive checks of an advance (tool_capsule's poses).
double largest_travel(const ToolPose& from, const ToolPose& to, double r, double shaft, int steps, int n) {
  ContactTools<double> c = one_tool<double>(from.tip, from.axis, to.tip, to.axis, r, shaft, n, steps);
  double worst = 0;
  Capsule<double> prev = tool_capsule(c.tool[0], steps, 0, 0);
  for (int k = 0; k < steps; ++k)
    for (int j = 1; j <= n; ++j) {
      const Capsule<double> cap = tool_capsule(c.tool[0], steps, k, j);
      worst = std::max({worst, norm(cap.a - prev.a), norm(cap.b - prev.b)});
      prev = cap;
    }
  return worst;
}

TEST(ContactSubsteps, HandValues) {
  const double h = 0.5;  // radius; r / 2 = 0.25 per check, all ratios below exact in binary
  const ToolPose at{{0, 0, 0}, {0, 0, 1}};
  EXPECT_EQ(contact_substeps(at, at, h, 2, 1), 1);  // no motion: one check
  EXPECT_EQ(contact_substeps(at, {{0, 0, 1.5}, {0, 0, 1}}, h, 2, 1), 6);
  EXPECT_EQ(contact_substeps(at, {{0, 0, 1.5}, {0, 0, 1}}, h, 2, 3), 2);       // per step
  EXPECT_EQ(contact_substeps(at, {{0, 0, 1.5}, {0, 0, 1}}, h, 2, 1, 1.0), 3);  // max_travel
  EXPECT_EQ(contact_substeps(at, {{0, 0, 0.25}, {0, 0, 1}}, h, 2, 1), 1);      // exactly r / 2: one
  EXPECT_EQ(contact_substeps(at, {{0, 0, 0.3}, {0, 0, 1}}, h, 2, 1), 2);
  EXPECT_EQ(contact_substeps(at, {{0, 0, 0.3}, {0, 0, 1}}, h, 2, 0), 2);  // steps < 1 counts as 1
  // a rotation about the tip moves the shaft's end by 2 l sin(theta / 2) (14.94 r / 2)
  const double r = 2e-3, l = 0.05, th = 0.3;
  const ToolPose turned{{0, 0, 0}, {std::sin(th), 0, std::cos(th)}};
  EXPECT_EQ(contact_substeps(at, turned, r, l, 1), int(std::ceil(2 * l * std::sin(th / 2) / (0.5 * r))));
  EXPECT_EQ(contact_substeps(at, turned, r, 0, 1), 1);  // a sphere does not care
  // capped
  EXPECT_EQ(contact_substeps(at, {{0, 0, 1}, {0, 0, 1}}, r, 0, 1), kMaxSubsteps);
  // non-finite motion or radius: one check, not a loop
  EXPECT_EQ(contact_substeps(at, {{NAN, 0, 0}, {0, 0, 1}}, r, 0, 1), 1);
  EXPECT_EQ(contact_substeps(at, {{1, 0, 0}, {0, 0, 1}}, 0, 0, 1), 1);
}

TEST(ContactSubsteps, TravelPerCheckIsAtMostMaxTravelTimesRadius) {
  Rng rng(82);
  int capped = 0;
  for (int it = 0; it < 3000; ++it) {
    const double r = rng.uni(5e-4, 5e-3), shaft = rng.uni(0, 1) < 0.3 ? 0 : rng.uni(0, 0.1);
    const double mt = rng.uni(0, 1) < 0.5 ? 0.5 : rng.uni(0.1, 1);
    const int steps = rng.integer(1, 20);
    const ToolPose from{rng.vec(-0.05, 0.05), rng.unit()};
    const bool rotate = it % 2 == 0;
    const double reach = it % 10 == 0 ? 1.0 : 0.03;  // some far enough to be capped
    const ToolPose to{from.tip + rng.uni(0, reach) * rng.vec(),
                      rotate ? unit_or(from.axis + 0.2 * rng.vec(), from.axis) : from.axis};
    const int n = contact_substeps(from, to, r, shaft, steps, mt);
    ASSERT_GE(n, 1);
    ASSERT_LE(n, kMaxSubsteps);
    // the contract on the end points' straight-line motion, and n is the least such count
    const double chord =
        std::max(norm(to.tip - from.tip), norm((to.tip + shaft * to.axis) - (from.tip + shaft * from.axis)));
    if (n == kMaxSubsteps) {
      ++capped;
      EXPECT_GT(chord / steps / (n - 1), mt * r);
      continue;
    }
    EXPECT_LE(chord / steps / n, mt * r * (1 + 1e-12)) << "case " << it;
    if (n > 1) {
      EXPECT_GT(chord / steps / (n - 1), mt * r) << "case " << it;
    }
    // the interpolated poses of a translation: every point moves by exactly
    // the chord's share (rotations: the next test)
    if (!rotate) {
      EXPECT_LE(largest_travel(from, to, r, shaft, steps, n), mt * r * (1 + 1e-9)) << "case " << it;
    }
  }
  EXPECT_GT(capped, 10);
}

// With a rotation the shaft's end follows the normalised chord of the two
// axes, which turns fastest half way (2 tan(theta/2) per unit of s, against
// the chord's 2 sin(theta/2)): one check may move the end by up to
// 1 / cos(theta/2) times max_travel x r (1.0000125 for 0.01 rad, 1.41 for
// 90 degrees in one advance) -- slightly more than the header's "at most".
TEST(ContactSubsteps, PureRotationExceedsTheBoundByAtMostOneOverCosHalfTheAngle) {
  const double r = 2e-3, l = 0.05;
  const ToolPose from{{0, 0, 0}, {0, 0, 1}};
  for (const double th : {0.01, 0.3, 1.0, M_PI / 2, 2.5}) {
    const ToolPose to{{0, 0, 0}, {std::sin(th), 0, std::cos(th)}};
    const int n = contact_substeps(from, to, r, l, 1);
    if (n == kMaxSubsteps) continue;
    const double travel = largest_travel(from, to, r, l, 1, n);
    EXPECT_LE(travel, 0.5 * r / std::cos(th / 2) * (1 + 1e-9)) << "theta " << th;
  }
}

// ---------------------------------------------------------------- contact_reaction, contact_tools_as

template <class T>
class Reaction : public ::testing::Test {};
TYPED_TEST_SUITE(Reaction, Scalars);

TYPED_TEST(Reaction, PushedGraspedAndOthers) {
  using T = TypeParam;
  const Vec3<T> n{0, T(0.6), T(0.8)}, f{1, 2, 3};
  // pushed: (f . n)+ n = 3.6 n
  EXPECT_LE(dist(contact_reaction<T>(kPushed, f, n, 0), T(3.6) * n), tol<T>(4));
  // a force pulling the node into the tool (f . n < 0) gives nothing: a contact cannot pull
  const Vec3<T> r = contact_reaction<T>(kPushed, T(-1) * f, n, 0);
  EXPECT_TRUE(r.x == T(0) && r.y == T(0) && r.z == T(0));
  // a held component is the support's: y held leaves f . n = 0.8 * 3
  EXPECT_LE(dist(contact_reaction<T>(kPushed, f, n, 2), T(2.4) * n), tol<T>(4));
  // grasped: the whole force, held components masked
  EXPECT_LE(dist(contact_reaction<T>(kGrasped, f, n, 0), f), 0.0);
  EXPECT_LE(dist(contact_reaction<T>(kGrasped, f, n, 1 | 4), Vec3<T>{0, 2, 0}), 0.0);
  EXPECT_LE(dist(contact_reaction<T>(kGrasped, f, n, kAllAxes), Vec3<T>{0, 0, 0}), 0.0);
  // no contact, and contacts the tool does not hold
  for (const std::uint8_t kind : {kNoContact, kRigidContact, kOutsideRegion}) {
    const Vec3<T> z = contact_reaction<T>(kind, f, n, 0);
    EXPECT_TRUE(z.x == T(0) && z.y == T(0) && z.z == T(0)) << int(kind);
  }
  // random pushed: along n, of length max(0, f_free . n)
  Rng rng(91);
  for (int it = 0; it < 1000; ++it) {
    const Vec3<T> fr = as<T>(rng.vec()), nr = as<T>(rng.unit());
    const std::uint8_t held = std::uint8_t(rng.integer(0, 7));
    const Vec3<T> fm = free_part(held, fr);
    const Vec3<T> got = contact_reaction<T>(kPushed, fr, nr, held);
    const double fn = std::max(0.0, double(dot(L(fm), L(nr))));
    EXPECT_LE(dist(got, T(fn) * nr), tol<T>(2));
  }
}

TYPED_TEST(Reaction, FrictionClampsTheTangentialForceToTheCoulombCone) {
  using T = TypeParam;
  const Vec3<T> n{0, 0, 1};
  // f_n = 2, f_t = (0.6, 0.8): |f_t| = 1 -- inside the cone of mu 0.5 (it sticks: all of f), on it for
  // mu = 0.5 exactly, and beyond it for mu 0.25 (it slides: mu f_n = 0.5 along f_t)
  const Vec3<T> f{T(0.6), T(0.8), 2};
  EXPECT_LE(dist(contact_reaction<T>(kPushed, f, n, 0, T(0.6)), f), tol<T>(4));
  EXPECT_LE(dist(contact_reaction<T>(kPushed, f, n, 0, T(0.5)), f), tol<T>(4));
  EXPECT_LE(dist(contact_reaction<T>(kPushed, f, n, 0, T(0.25)), Vec3<T>{T(0.3), T(0.4), 2}), tol<T>(4));
  // frictionless: the normal part alone, the same bits as without a coefficient
  const Vec3<T> r0 = contact_reaction<T>(kPushed, f, n, 0, T(0)), r = contact_reaction<T>(kPushed, f, n, 0);
  EXPECT_TRUE(r0.x == r.x && r0.y == r.y && r0.z == r.z);
  // a node pulled into the tool feels nothing along it either; a grasp keeps its whole force
  const Vec3<T> pulled = contact_reaction<T>(kPushed, Vec3<T>{1, 0, -1}, n, 0, T(10));
  EXPECT_TRUE(pulled.x == T(0) && pulled.y == T(0) && pulled.z == T(0));
  EXPECT_LE(dist(contact_reaction<T>(kGrasped, f, n, 0, T(0.25)), f), 0.0);
  // random: within the cone, continuous in mu, and its normal part is (f . n)+
  Rng rng(92);
  for (int it = 0; it < 1000; ++it) {
    const Vec3<T> fr = as<T>(rng.vec()), nr = as<T>(rng.unit());
    const T mu = T(rng.uni(0, 2));
    const Vec3<T> got = contact_reaction<T>(kPushed, fr, nr, 0, mu);
    const double fn = std::max(0.0, double(dot(L(fr), L(nr))));
    const double gn = double(dot(L(got), L(nr)));
    const double gt = double(norm(L(got) - dot(L(got), L(nr)) * L(nr)));
    EXPECT_NEAR(gn, fn, tol<T>(4));
    EXPECT_LE(gt, double(mu) * fn + tol<T>(8));
  }
}

TEST(ContactToolsAs, ConvertsEveryField) {
  ContactTools<double> d{};
  d.n_tools = 2;
  d.steps = 5;
  d.face = 0;
  d.tool[0] = one_tool<double>({1, 2, 3}, {0, 0, 1}, {4, 5, 6}, {0, 1, 0}, 2e-3, 0.01, 7).tool[0];
  d.tool[1] = one_tool<double>({-1, -2, -3}, {1, 0, 0}, {0.1, 0.2, 0.3}, {0, 0, -1}, 1e-3, 0, 3).tool[0];
  d.tool[1].grasping = 1;
  d.tool[1].grasp_tip = {9, 8, 7};
  d.tool[1].friction = 0.35;
  const ContactTools<float> f = contact_tools_as<float>(d);
  EXPECT_EQ(f.n_tools, 2);
  EXPECT_EQ(f.steps, 5);
  EXPECT_EQ(f.face, 0);
  for (int t = 0; t < 2; ++t) {
    const auto& a = d.tool[t];
    const auto& b = f.tool[t];
    EXPECT_EQ(b.radius, float(a.radius));
    EXPECT_EQ(b.shaft, float(a.shaft));
    EXPECT_EQ(b.substeps, a.substeps);
    EXPECT_EQ(b.grasping, a.grasping);
    EXPECT_EQ(b.friction, float(a.friction));
    using P = std::pair<Vec3<double>, Vec3<float>>;
    for (const P& p : {P{a.tip0, b.tip0}, P{a.tip1, b.tip1}, P{a.axis0, b.axis0}, P{a.axis1, b.axis1},
                       P{a.grasp_tip, b.grasp_tip}, P{a.grasp_axis, b.grasp_axis}}) {
      EXPECT_EQ(float(p.first.x), p.second.x);
      EXPECT_EQ(float(p.first.y), p.second.y);
      EXPECT_EQ(float(p.first.z), p.second.z);
    }
  }
}

// ---------------------------------------------------------------- node rules (core/node_rules.hpp)

template <class T>
class NodeRules : public ::testing::Test {};
TYPED_TEST_SUITE(NodeRules, Scalars);

TYPED_TEST(NodeRules, CoulombSlipSticksWithinTheConeAndSlidesByMuTimesThePushBeyondIt) {
  using T = TypeParam;
  const Vec3<T> n{0, 0, 1}, u_now{T(1e-3), 0, 0}, w{T(2e-4), 0, 0};  // the tool moved 0.2 mm along x
  // the node ends 0.1 mm along x and 0.05 mm along y from where the tool carries it, pushed 0.1 mm
  const Vec3<T> u1 = u_now + w + Vec3<T>{T(1e-4), T(5e-5), T(1e-4)};
  const Vec3<T> push = T(1e-4) * n;  // the correction dx, 0.1 mm along n
  const T slip = std::sqrt(T(1.25e-8));
  // mu 2: within the cone (|slip| <= 2 push): it sticks, moving with the tool (its normal part stays)
  const Vec3<T> stuck = coulomb_slip<T>(0, u_now, u1, n, w, push, T(2));
  EXPECT_LE(dist(stuck, u_now + w + Vec3<T>{0, 0, T(1e-4)}), tol<T>(8) * T(1e-3));
  // mu 0.5: it slides, the slip shortened by mu push = 0.05 mm along itself
  const Vec3<T> slid = coulomb_slip<T>(0, u_now, u1, n, w, push, T(0.5));
  const T keep = (slip - T(5e-5)) / slip;
  EXPECT_LE(dist(slid, u_now + w + Vec3<T>{keep * T(1e-4), keep * T(5e-5), T(1e-4)}), tol<T>(8) * T(1e-3));
  // frictionless: unchanged, the same bits
  const Vec3<T> same = coulomb_slip<T>(0, u_now, u1, n, w, push, T(0));
  EXPECT_TRUE(same.x == u1.x && same.y == u1.y && same.z == u1.z);
  // a held component (y) does not move
  const Vec3<T> roller = coulomb_slip<T>(2, u_now, u1, n, w, push, T(2));
  EXPECT_EQ(roller.y, u1.y);
  EXPECT_LE(std::fabs(roller.x - (u_now.x + w.x)), tol<T>(8) * T(1e-3));
}

TYPED_TEST(NodeRules, NodeNextHoldsMaskedComponents) {
  using T = TypeParam;
  const CentralDifference<T> cd{T(0.5), T(2), T(-1)};  // next = -0.5 f + 2 u - u_prev
  const Vec3<T> f{1, -2, 4}, u{T(0.1), T(0.2), T(0.3)}, up{T(0.05), T(0.1), T(0.4)}, held{7, 8, 9};
  const Vec3<T> free{T(-0.5 + 0.2 - 0.05), T(1 + 0.4 - 0.1), T(-2 + 0.6 - 0.4)};
  for (std::uint8_t h = 0; h <= kAllAxes; ++h) {
    Vec3<T> carry{T(1e-9), T(1e-9), T(1e-9)};
    const Vec3<T> next = node_next(h, held, cd, f, u, up, carry);
    for (int c = 0; c < 3; ++c) {
      if (h >> c & 1) {
        EXPECT_EQ(next[c], held[c]) << "mask " << int(h) << " component " << c;
        EXPECT_EQ(carry[c], T(0)) << "a held component carries nothing";
      } else {
        EXPECT_NEAR(double(next[c]), double(free[c]), tol<T>(2)) << "mask " << int(h) << " component " << c;
      }
    }
  }
  // the constants of a real node: m = 2e-6 kg, dt = 1e-4 s, alpha = 10 / s
  const CentralDifference<T> real = central_difference_constants(T(2e-6), T(1e-4), T(10));
  const double inertia = 2e-6 / 1e-8, damp = 10 * 2e-6 / 2e-4, A = 1 / (inertia + damp);
  Vec3<T> carry{0, 0, 0};
  const Vec3<T> n = node_next(0, held, real, f, u, up, carry);
  EXPECT_NEAR(double(n.x), A * (-1) + 2 * inertia * A * 0.1 + (damp - inertia) * A * 0.05, 1e3 * tol<T>(1));
}

// Increments below half of u's spacing: float's compensated update keeps
// them (u = 1 moves by 1e-8 a step, a sixth of float's ulp at 1, which
// u + increment alone rounds away every step); double adds them exactly
// enough either way.
TYPED_TEST(NodeRules, NodeNextKeepsIncrementsBelowTheSpacingOfU) {
  using T = TypeParam;
  const CentralDifference<T> cd{T(1), T(1), T(0)};  // next = u - f: no inertia, B + C = 1
  const Vec3<T> f{T(-1e-8), T(-1e-8), T(-1e-8)}, held{0, 0, 0};
  Vec3<T> u{1, 1, 1}, carry{0, 0, 0};
  for (int step = 0; step < 1000; ++step) u = node_next(0, held, cd, f, u, u, carry);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(double(u[c]), 1 + 1e-5, 1.2e-7) << "component " << c;
}

TYPED_TEST(NodeRules, HaloTargetAndFreePart) {
  using T = TypeParam;
  const Vec3<T> u{1, 2, 3}, drive{-1, -2, -3};
  for (std::uint8_t fixed = 0; fixed <= kAllAxes; ++fixed)
    for (std::uint8_t driven = 0; driven <= kAllAxes; ++driven) {
      const Vec3<T> t = halo_target(fixed, driven, u, drive);
      for (int c = 0; c < 3; ++c) {
        const T want = (fixed >> c & 1) ? T(0) : ((driven >> c & 1) ? drive[c] : u[c]);  // fixed wins
        EXPECT_EQ(t[c], want) << "fixed " << int(fixed) << " driven " << int(driven) << " component " << c;
      }
    }
  for (std::uint8_t h = 0; h <= kAllAxes; ++h) {
    const Vec3<T> p = free_part(h, u);
    for (int c = 0; c < 3; ++c) EXPECT_EQ(p[c], (h >> c & 1) ? T(0) : u[c]);
  }
}

TYPED_TEST(NodeRules, NodeTermsHandComputed) {
  using T = TypeParam;
  const Vec3<T> f{1, 2, 3}, u{T(0.1), T(0.2), T(0.2)}, up{T(0), T(0.1), T(0.3)};
  const double mass = 2, dt = 0.5;
  const double e = tol<T>(16);
  // v = (0.2, 0.2, -0.2): kinetic 0.5 * 2 * 0.12; |u| = 0.3
  const NodeTerms outer = node_terms(f, u, up, mass, dt, false, 0, 2, kNoContact, Vec3<T>{0, 0, 1});
  EXPECT_NEAR(outer.kinetic, 0.12, e);
  EXPECT_NEAR(outer.disp, 0.3, e);
  EXPECT_EQ(outer.reaction[0], 0);
  EXPECT_EQ(outer.reaction[1], 2);  // driven y: the drive's reaction
  EXPECT_EQ(outer.reaction[2], 0);
  EXPECT_EQ(outer.internal[0], 0);  // not inner: no internal force, no balance terms
  EXPECT_EQ(outer.free2, 0);
  EXPECT_EQ(outer.held2, 0);
  EXPECT_TRUE(outer.finite);
  // inner, x held
  const NodeTerms plain = node_terms(f, u, up, mass, dt, true, 1, 0, kNoContact, Vec3<T>{0, 0, 1});
  EXPECT_EQ(plain.internal[2], 3);
  EXPECT_NEAR(plain.held2, 1, e);
  EXPECT_NEAR(plain.free2, 13, e);
  // pushed along z: the normal part 3 of the free force is held by the tool
  const NodeTerms pz = node_terms(f, u, up, mass, dt, true, 1, 0, kPushed, Vec3<T>{0, 0, 1});
  EXPECT_NEAR(pz.held2, 1 + 9, e);
  EXPECT_NEAR(pz.free2, 4, e);
  // pushed along (0, 0.6, 0.8): f_n = 3.6
  const NodeTerms py = node_terms(f, u, up, mass, dt, true, 1, 0, kPushed, Vec3<T>{0, T(0.6), T(0.8)});
  EXPECT_NEAR(py.held2, 1 + 3.6 * 3.6, e);
  EXPECT_NEAR(py.free2, 13 - 3.6 * 3.6, e);
  // a normal with a component along the held x: only the free components count (f_n = 3 * 0.8)
  const NodeTerms px = node_terms(f, u, up, mass, dt, true, 1, 0, kPushed, Vec3<T>{T(0.6), 0, T(0.8)});
  EXPECT_NEAR(px.held2, 1 + 2.4 * 2.4, e);
  EXPECT_NEAR(px.free2, 13 - 2.4 * 2.4, e);
  // grasped: everything held by the tool
  const NodeTerms g = node_terms(f, u, up, mass, dt, true, 1, 0, kGrasped, Vec3<T>{0, 0, 1});
  EXPECT_NEAR(g.held2, 14, e);
  EXPECT_EQ(g.free2, 0);
  // blocked contacts count as no contact
  const NodeTerms rigid = node_terms(f, u, up, mass, dt, true, 0, 0, kRigidContact, Vec3<T>{0, 0, 1});
  EXPECT_NEAR(rigid.free2, 14, e);
  EXPECT_EQ(rigid.held2, 0);
  // not finite
  const T nan = std::numeric_limits<T>::quiet_NaN(), inf = std::numeric_limits<T>::infinity();
  EXPECT_FALSE(node_terms(Vec3<T>{nan, 0, 0}, u, up, mass, dt, true, 0, 0, kNoContact, f).finite);
  EXPECT_FALSE(node_terms(f, Vec3<T>{0, inf, 0}, up, mass, dt, true, 0, 0, kNoContact, f).finite);
  EXPECT_FALSE(node_terms(f, u, Vec3<T>{0, 0, nan}, mass, dt, false, 0, 0, kNoContact, f).finite);
}

TYPED_TEST(NodeRules, HeldPlusFreeIsTheWholeForce) {
  using T = TypeParam;
  Rng rng(92);
  for (int it = 0; it < 2000; ++it) {
    const Vec3<T> f = as<T>(rng.vec()), n = as<T>(rng.unit());
    const std::uint8_t held = std::uint8_t(rng.integer(0, 7));
    const std::uint8_t kind = std::uint8_t(rng.integer(0, 4));
    const NodeTerms t = node_terms(f, Vec3<T>{0, 0, 0}, Vec3<T>{0, 0, 0}, 1.0, 1.0, true, held, 0, kind, n);
    EXPECT_NEAR(t.held2 + t.free2, double(dot(L(f), L(f))), tol<T>(4)) << "kind " << int(kind);
    EXPECT_GE(t.free2, 0);
    if (kind == kPushed) {  // the held part is at least the normal part of the free force
      const double fn = double(dot(L(free_part(held, f)), L(n)));
      double h = 0;
      for (int c = 0; c < 3; ++c) h += (held >> c & 1) ? double(f[c]) * double(f[c]) : 0;
      EXPECT_NEAR(t.held2, h + fn * fn, tol<T>(4));
    }
  }
}

}  // namespace
}  // namespace tissue
