// Surface repair and remeshing (io/surface_repair) on surfaces the test
// generates: each kind of damage a segmented organ carries is repaired,
// reported, and leaves a closed surface that TetGen accepts and that encloses
// the volume it should; damage that cannot be repaired safely is an error
// that says why.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "io/surface_repair.hpp"
#include "io/tetgen_mesher.hpp"
#include "tests/surfaces.hpp"

using namespace tissue::io;
using tissue::index_t;
namespace tt = tissue::test;

namespace {

constexpr double kPi = 3.14159265358979323846;

/// A 6 x 4 x 3 cm ellipsoid, 1,280 triangles.
SurfaceMesh organ() { return tt::ellipsoid({0, 0, 0}, {0.03, 0.02, 0.015}, 3); }

double organ_volume() { return 4.0 / 3.0 * kPi * 0.03 * 0.02 * 0.015; }

std::string repair_error(SurfaceMesh s, const RepairOptions& o = {}) {
  try {
    repair_surface(s, o, "organ.stl");
  } catch (const MeshError& e) {
    return e.what();
  }
  return "";
}

/// The repaired surface is closed, free of self-intersections and meshable.
void expect_meshable(const SurfaceMesh& s) {
  ASSERT_NO_THROW(check_closed(s, "repaired"));
  EXPECT_EQ(count_self_intersections(s, "repaired"), 0);
  EXPECT_GT(enclosed_volume(s), 0) << "outward";
  MeshingOptions o;
  o.max_volume = organ_volume() / 2000;
  EXPECT_GT(tetrahedralize_surface(s, o, "repaired").n_tets(), 1000);
}

}  // namespace

TEST(RepairSurface, CleanSurfaceIsLeftAlone) {
  SurfaceMesh s = organ();
  const SurfaceMesh before = s;
  const RepairReport r = repair_surface(s, {}, "organ");
  EXPECT_FALSE(r.changed()) << r.summary();
  EXPECT_EQ(s.vertices, before.vertices);
  EXPECT_EQ(s.triangles, before.triangles);
}

TEST(RepairSurface, DuplicatedVerticesAreMerged) {
  const SurfaceMesh clean = organ();
  SurfaceMesh s = tt::unshare_vertices(clean);
  ASSERT_EQ(s.n_vertices(), 3 * clean.n_triangles());
  const RepairReport r = repair_surface(s, {}, "soup.stl");
  EXPECT_EQ(r.soup_points_merged, 3 * clean.n_triangles() - clean.n_vertices());
  EXPECT_EQ(s.n_vertices(), clean.n_vertices());
  EXPECT_EQ(s.n_triangles(), clean.n_triangles());
  EXPECT_NEAR(enclosed_volume(s), enclosed_volume(clean), 1e-12);
  expect_meshable(s);
}

TEST(RepairSurface, ZeroAreaTriangleIsRemoved) {
  SurfaceMesh s = organ();
  tt::add_zero_area_triangle(s);
  EXPECT_THROW(check_closed(s, "damaged"), MeshError) << "today's check refuses it";
  const RepairReport r = repair_surface(s, {}, "organ.stl");
  EXPECT_GE(r.degenerate_removed, 1) << r.summary();
  expect_meshable(s);
}

TEST(RepairSurface, SmallHolesAreFilled) {
  SurfaceMesh s = organ();
  tt::cut_fan(s, 0);   // a hole at the tip of the long axis
  tt::cut_fan(s, 20);  // and another one elsewhere
  EXPECT_THROW(check_closed(s, "holes"), MeshError) << "today's check refuses it";
  SurfaceMesh r_s = s;
  const RepairReport r = repair_surface(r_s, {}, "holes.obj");
  EXPECT_EQ(r.holes_filled, 2) << r.summary();
  EXPECT_GT(r.hole_triangles_added, 0);
  EXPECT_GT(r.largest_hole, 0);
  EXPECT_NEAR(enclosed_volume(r_s), organ_volume(), 0.02 * organ_volume()) << "the patches follow the surface";
  expect_meshable(r_s);
}

TEST(RepairSurface, LargeHoleIsAnErrorThatSaysWhy) {
  SurfaceMesh s = organ();
  // cut away every triangle with a vertex above z = 0.01: a cap 2/3 of the way up
  std::vector<index_t> kept;
  for (index_t t = 0; t < s.n_triangles(); ++t) {
    bool above = false;
    for (int k = 0; k < 3; ++k) above |= s.vertices[3 * s.triangles[3 * t + k] + 2] > 0.005;
    if (!above) kept.insert(kept.end(), s.triangles.begin() + 3 * t, s.triangles.begin() + 3 * t + 3);
  }
  s.triangles = kept;
  const std::string msg = repair_error(s);
  EXPECT_NE(msg.find("organ.stl"), std::string::npos) << msg;
  EXPECT_NE(msg.find("hole of"), std::string::npos) << msg;
  EXPECT_NE(msg.find("across"), std::string::npos) << msg;
}

TEST(RepairSurface, FoldedSurfaceIsRepaired) {
  // A vertex of the flat side pushed in until its fan pokes through the
  // opposite side by half an edge: the kind of local crossing a smoothing
  // step leaves in a thin part of a segmented organ.
  SurfaceMesh s = tt::ellipsoid({0, 0, 0}, {0.03, 0.02, 0.004}, 3);
  const double h = mean_edge_length(s);
  index_t v = 0;  // the highest vertex
  for (index_t i = 0; i < s.n_vertices(); ++i)
    if (s.vertices[3 * i + 2] > s.vertices[3 * v + 2]) v = i;
  tt::move_vertex(s, v, {0, 0, -2 * s.vertices[3 * v + 2] - 0.5 * h});
  const long pairs = count_self_intersections(s, "folded");
  ASSERT_GT(pairs, 0) << "the test surface must intersect itself";
  {
    try {
      tetrahedralize_surface(s, {}, "folded.stl");
      FAIL() << "TetGen must refuse the unrepaired surface";
    } catch (const MeshError& e) {
      EXPECT_NE(std::string(e.what()).find("intersects itself"), std::string::npos) << e.what();
    }
  }
  const RepairReport r = repair_surface(s, {}, "folded.stl");
  EXPECT_EQ(r.intersecting_pairs, pairs);
  EXPECT_TRUE(r.autorefined || r.smoothed);
  EXPECT_LT(r.max_moved, 5 * h) << "the repair stays local";
  const double thin = 4.0 / 3.0 * kPi * 0.03 * 0.02 * 0.004;
  EXPECT_NEAR(enclosed_volume(s), thin, 0.05 * thin);
  expect_meshable(s);
}

TEST(RepairSurface, InterpenetratingBodiesBecomeTheirUnion) {
  SurfaceMesh s;
  tt::add_box(s, 0.0, 1.0);
  tt::add_box(s, 0.5, 1.0);
  const RepairReport r = repair_surface(s, {}, "two boxes");
  EXPECT_GT(r.intersecting_pairs, 0);
  EXPECT_TRUE(r.autorefined) << r.summary();
  EXPECT_NEAR(r.max_moved, 0, 1e-12) << "autorefinement moves nothing";
  EXPECT_NEAR(enclosed_volume(s), 2.0 - 0.125, 1e-9) << "the union of the two unit boxes";
  ASSERT_NO_THROW(check_closed(s, "union"));
  EXPECT_EQ(count_self_intersections(s, "union"), 0);
}

TEST(RepairSurface, TooManyIntersectionsAreRefused) {
  SurfaceMesh s = organ();
  tt::append(s, tt::ellipsoid({0.01, 0, 0}, {0.03, 0.02, 0.015}, 3));
  RepairOptions o;
  o.max_intersecting_pairs = 10;
  const std::string msg = repair_error(s, o);
  EXPECT_NE(msg.find("intersects itself in"), std::string::npos) << msg;
  EXPECT_NE(msg.find("organ.stl"), std::string::npos) << msg;
}

TEST(RepairSurface, InwardSurfaceIsTurnedOutward) {
  SurfaceMesh s = organ();
  for (index_t t = 0; t < s.n_triangles(); ++t) std::swap(s.triangles[3 * t + 1], s.triangles[3 * t + 2]);
  ASSERT_LT(enclosed_volume(s), 0);
  const RepairReport r = repair_surface(s, {}, "inward.obj");
  EXPECT_TRUE(r.reoriented);
  EXPECT_NEAR(enclosed_volume(s), enclosed_volume(organ()), 1e-12);
}

TEST(RemeshSurface, DenseSurfaceComesToTheAskedEdgeLength) {
  // 20 * 4^7 = 327,680 triangles, as a smoothed segmentation exports them
  SurfaceMesh s = tt::ellipsoid({0, 0, 0}, {0.03, 0.02, 0.015}, 7);
  ASSERT_GT(s.n_triangles(), 200000);
  const double target = 2.5e-3;
  int lines = 0;
  const index_t n = remesh_surface(s, target, 3, "dense.stl", [&](const std::string&) { ++lines; });
  EXPECT_EQ(lines, 3) << "one progress line per pass";
  EXPECT_EQ(n, s.n_triangles());
  EXPECT_LT(n, 20000);
  const double h = mean_edge_length(s);
  EXPECT_GT(h, 0.7 * target);
  EXPECT_LT(h, 1.3 * target);
  EXPECT_NEAR(enclosed_volume(s), organ_volume(), 0.01 * organ_volume());
  ASSERT_NO_THROW(check_closed(s, "remeshed"));
}

TEST(RemeshSurface, BadEdgeLengthNamed) {
  SurfaceMesh s = organ();
  try {
    remesh_surface(s, -1, 1, "organ.stl");
    FAIL();
  } catch (const MeshError& e) {
    EXPECT_NE(std::string(e.what()).find("edge length"), std::string::npos) << e.what();
  }
}
