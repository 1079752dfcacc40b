// The built-in kidney: a closed bean-shaped surface, the default scene's tet
// count, orientation, hilum constraint and the scripted tool path.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "core/tet.hpp"
#include "io/kidney.hpp"
#include "scene/validate.hpp"

using tissue::index_t;
using tissue::Vec3;
using namespace tissue::io;

namespace {

Vec3<double> vtx(const SurfaceMesh& s, index_t i) {
  return {s.vertices[3 * i], s.vertices[3 * i + 1], s.vertices[3 * i + 2]};
}

Vec3<double> node(const tissue::scene::Scene& s, index_t i) {
  return {s.nodes[3 * i], s.nodes[3 * i + 1], s.nodes[3 * i + 2]};
}

/// The default scene is built once for the whole suite (about 2 s).
const tissue::scene::Scene& scene() {
  static const tissue::scene::Scene s = default_kidney_scene();
  return s;
}

const tissue::TissueModel<double>& model() {
  static const tissue::TissueModel<double> m = tissue::scene::load_model(scene());
  return m;
}

/// First crossing of segment A -> B with the model's deformed-free surface
/// (core segment_triangle over every surface triangle): fraction t, or -1.
double first_crossing(const tissue::TissueModel<double>& m, Vec3<double> A, Vec3<double> B, index_t* tri) {
  double best = -1;
  const index_t nt = m.n_tris, n = m.n_nodes;
  for (index_t t = 0; t < nt; ++t) {
    Vec3<double> P[3];
    for (int k = 0; k < 3; ++k) {
      const index_t v = m.tris[k * nt + t];
      P[k] = {m.X[v], m.X[n + v], m.X[2 * n + v]};
    }
    double bary[2];
    const double h = tissue::segment_triangle(A, B, P[0], P[1], P[2], bary);
    if (h >= 0 && (best < 0 || h < best)) {
      best = h;
      *tri = t;
    }
  }
  return best;
}

}  // namespace

TEST(KidneySurface, ClosedOutwardAndKidneySized) {
  const SurfaceMesh s = kidney_surface(KidneyScene::frequency);
  EXPECT_EQ(s.n_vertices(), 10 * 36 + 2);
  EXPECT_EQ(s.n_triangles(), 20 * 36);
  EXPECT_NO_THROW(check_closed(s, "kidney"));
  double lo[3] = {1, 1, 1}, hi[3] = {-1, -1, -1};
  for (size_t k = 0; k < s.vertices.size(); ++k) {
    lo[k % 3] = std::min(lo[k % 3], s.vertices[k]);
    hi[k % 3] = std::max(hi[k % 3], s.vertices[k]);
  }
  EXPECT_NEAR(hi[0] - lo[0], 0.11, 0.005);   // about 11 cm long
  EXPECT_NEAR(hi[2] - lo[2], 0.044, 0.004);  // about 4.4 cm thick
  EXPECT_GT(hi[1] - lo[1], 0.04);            // lateral 3 cm + medial side pulled in by the dent
  EXPECT_LT(hi[1] - lo[1], 0.06);
  const KidneyShape k;
  const double ellipsoid = 4.0 / 3.0 * M_PI * k.a * k.b * k.c;
  EXPECT_GT(enclosed_volume(s), 0.8 * ellipsoid) << "outward oriented, a little smaller than the ellipsoid";
  EXPECT_LT(enclosed_volume(s), ellipsoid);
}

TEST(KidneySurface, EveryFrequencyIsClosedAndStarShaped) {
  for (int f = 1; f <= 9; ++f) {
    const SurfaceMesh s = kidney_surface(f);
    EXPECT_EQ(s.n_vertices(), 10 * f * f + 2) << f;
    EXPECT_NO_THROW(check_closed(s, "kidney")) << f;
    for (index_t t = 0; t < s.n_triangles(); ++t) {
      const Vec3<double> a = vtx(s, s.triangles[3 * t]), b = vtx(s, s.triangles[3 * t + 1]),
                         c = vtx(s, s.triangles[3 * t + 2]);
      ASSERT_GT(dot(a, cross(b, c)), 0) << "frequency " << f << " triangle " << t << " faces the centre";
    }
  }
  EXPECT_THROW(kidney_surface(0), std::invalid_argument);
}

TEST(KidneySurface, BeanWithConcaveHilum) {
  const SurfaceMesh s = kidney_surface(KidneyScene::frequency);
  const Vec3<double> hilum = surface_point_along(s, {0, -1, 0});
  const Vec3<double> lateral = surface_point_along(s, {0, 1, 0});
  EXPECT_LT(hilum.y, 0);
  EXPECT_NEAR(lateral.y, KidneyShape{}.b, 1e-3);
  // medial concavity: 2 cm above and below the hilum the medial surface
  // reaches further out (more negative y) than at the hilum itself
  for (double x : {-0.02, 0.02}) {
    const Vec3<double> p = surface_point_along(s, {x, hilum.y, 0});
    EXPECT_LT(p.y, hilum.y - 0.003) << "x = " << x;
  }
  // while the lateral side is convex: the surface falls away from its crest
  for (double x : {-0.02, 0.02}) EXPECT_LT(surface_point_along(s, {x, lateral.y, 0}).y, lateral.y);
}

TEST(KidneyScene, AboutTheReferenceTetCount) {
  const double n = scene().tets.size() / 4.0;
  EXPECT_GE(n, 8400 * 0.9);
  EXPECT_LE(n, 8400 * 1.1);
  EXPECT_EQ(model().n_elems, static_cast<index_t>(n));
}

TEST(KidneyScene, PositiveVolumesNoReorientation) {
  const auto& s = scene();
  double total = 0;
  for (size_t e = 0; e < s.tets.size() / 4; ++e) {
    Vec3<double> X[4];
    for (int a = 0; a < 4; ++a) X[a] = node(s, s.tets[4 * e + a]);
    double dN[12];
    const double V = tissue::tet_shape_gradients(X, dN);
    ASSERT_GT(V, 0) << "tet " << e;
    total += V;
  }
  EXPECT_EQ(model().reoriented, 0);
  EXPECT_NEAR(total, enclosed_volume(kidney_surface(KidneyScene::frequency)), 1e-9 * total);
}

TEST(KidneyScene, MaterialAndSolverDefaults) {
  const auto& s = scene();
  ASSERT_EQ(s.materials.size(), 1u);
  EXPECT_EQ(s.materials[0].name, "kidney");  // messages name the organ, not the tissue its numbers come from
  EXPECT_EQ(s.materials[0].form, tissue::scene::Material::Form::YoungPoisson);
  EXPECT_DOUBLE_EQ(s.materials[0].a, 3000);
  EXPECT_DOUBLE_EQ(s.materials[0].b, 0.45);
  EXPECT_DOUBLE_EQ(s.materials[0].rho, 1000);
  ASSERT_EQ(s.sets.size(), 1u);
  EXPECT_TRUE(s.sets[0].all);
  EXPECT_EQ(s.sets[0].material, "kidney");
  EXPECT_EQ(s.solver.backend, "cpu");
  EXPECT_EQ(s.solver.precision, tissue::Precision::Float);
  EXPECT_FALSE(s.solver.dt);
  EXPECT_DOUBLE_EQ(s.solver.dt_safety, 0.8);  // docs/reliability.md, "Soak": the margin large indentations need
  EXPECT_DOUBLE_EQ(s.solver.mass_scaling, 0.025);
  EXPECT_FALSE(s.solver.damping);
  EXPECT_EQ(s.solver.depth, tissue::kDepthAuto);
  EXPECT_DOUBLE_EQ(s.solver.tick, 1e-3);
  EXPECT_NO_THROW(tissue::scene::validate(s));
}

TEST(KidneyScene, FixedPatchIsExactlyTheHilumBall) {
  const auto& s = scene();
  ASSERT_EQ(s.constraints.size(), 1u);
  const auto& c = s.constraints[0];
  ASSERT_EQ(c.kind, tissue::scene::Constraint::Kind::Nodes);
  ASSERT_FALSE(c.nodes.empty());
  const Vec3<double> hilum = kidney_hilum_centre();
  EXPECT_LT(hilum.y, -0.01) << "the hilum is on the medial (-y) side";
  std::vector<char> fixed(s.nodes.size() / 3, 0);
  for (index_t i : c.nodes) {
    EXPECT_LE(norm(node(s, i) - hilum), KidneyScene::fix_radius + 1e-12) << "node " << i;
    fixed[i] = 1;
  }
  for (index_t i = 0; i < static_cast<index_t>(fixed.size()); ++i)
    if (!fixed[i]) {
      EXPECT_GT(norm(node(s, i) - hilum), KidneyScene::fix_radius) << "node " << i << " left free";
    }
  // the model carries them as fixed nodes
  index_t n_fixed = 0;
  for (auto f : model().node_flags) n_fixed += (f & tissue::kFixed) ? 1 : 0;
  EXPECT_EQ(n_fixed, static_cast<index_t>(c.nodes.size()));
}

TEST(KidneyScene, ProbeIsARodPressedAlongTheLateralNormal) {
  const auto& s = scene();
  ASSERT_EQ(s.tools.size(), 1u);
  const auto& tool = s.tools[0];
  EXPECT_DOUBLE_EQ(tool.radius, KidneyScene::tool_radius);
  EXPECT_DOUBLE_EQ(tool.shaft, KidneyScene::tool_shaft);
  EXPECT_EQ(tool.device, "scripted");
  ASSERT_EQ(tool.path.size(), 5u);  // start, touch, deepest, hold end, back at start
  EXPECT_NEAR(tool.path.back().t, 1.0, 1e-12);
  const Vec3<double> start = tool.path[0].p, touch = tool.path[1].p, deep = tool.path[2].p;
  EXPECT_GT(start.y, 0.03) << "starts outside the convex lateral side";
  // the shaft points back along the press, out of the organ
  const Vec3<double> dir = (1.0 / norm(touch - start)) * (touch - start);
  EXPECT_NEAR(dot(tool.direction, dir), -1.0, 1e-12);
  EXPECT_NEAR(norm(tool.direction), 1.0, 1e-12);
  // the generated surface: the tip sphere touches it at the touch pose (its
  // lowest point on the surface point along +y) and its lowest point goes
  // press_depth below it
  const SurfaceMesh surf = kidney_surface(KidneyScene::frequency);
  const Vec3<double> p = surface_point_along(surf, {0, 1, 0});
  EXPECT_NEAR(norm(touch + KidneyScene::tool_radius * dir - p), 0.0, 1e-12);
  EXPECT_NEAR(dot(deep + KidneyScene::tool_radius * dir - p, dir), KidneyScene::press_depth, 1e-12);
  EXPECT_NEAR(norm(touch - start), KidneyScene::approach, 1e-12);
  // the mesh's boundary passes through that point: TetGen keeps the input surface
  index_t tri = -1;
  const double t = first_crossing(model(), p - 0.001 * dir, p + 0.001 * dir, &tri);
  ASSERT_GE(t, 0);
  EXPECT_NEAR(t, 0.5, 1e-6);
}

TEST(KidneyScene, Deterministic) {
  const tissue::scene::Scene again = default_kidney_scene();
  EXPECT_EQ(again.nodes, scene().nodes);
  EXPECT_EQ(again.tets, scene().tets);
  EXPECT_EQ(again.constraints[0].nodes, scene().constraints[0].nodes);
}
