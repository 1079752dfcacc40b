// Volume meshing through the TetGen library: a cube's tets fill exactly the
// cube, respect the maximum volume, come out positive, and the target-count
// helper lands within its stated tolerance; open and self-intersecting
// surfaces give clear errors instead of crashes.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <random>
#include <utility>
#include <vector>
#include <string>

#include "core/model.hpp"
#include "core/tet.hpp"
#include "io/tetgen_mesher.hpp"

using tissue::index_t;
using tissue::Vec3;
using namespace tissue::io;

namespace {

constexpr int kQuads[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};

/// Appends the closed, outward box [lo, lo + side]^3 (12 triangles).
void add_box(SurfaceMesh& s, double lo, double side) {
  const index_t base = s.n_vertices();
  for (int v = 0; v < 8; ++v)
    for (int a = 0; a < 3; ++a) s.vertices.push_back(lo + side * ((v >> a) & 1));
  for (const auto& q : kQuads)
    s.triangles.insert(s.triangles.end(),
                       {base + q[0], base + q[1], base + q[2], base + q[0], base + q[2], base + q[3]});
}

SurfaceMesh cube(double side) {
  SurfaceMesh s;
  add_box(s, 0.0, side);
  return s;
}

double tet_volume(const VolumeMesh& m, index_t e) {
  Vec3<double> X[4];
  for (int a = 0; a < 4; ++a) X[a] = m.node(m.tets[4 * e + a]);
  double dN[12];
  return tissue::tet_shape_gradients(X, dN);
}

std::string mesh_error(const SurfaceMesh& s, const MeshingOptions& o) {
  try {
    tetrahedralize_surface(s, o, "test.stl");
  } catch (const MeshError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

TEST(TetgenMesher, CubeVolumesSumToCube) {
  const double side = 0.1;
  MeshingOptions o;
  o.max_volume = side * side * side / 500;
  const VolumeMesh m = tetrahedralize_surface(cube(side), o, "cube");
  ASSERT_GT(m.n_tets(), 500);
  double sum = 0;
  for (index_t e = 0; e < m.n_tets(); ++e) {
    const double v = tet_volume(m, e);
    EXPECT_GT(v, 0) << "tet " << e << " is not positively oriented";
    sum += v;
  }
  EXPECT_NEAR(sum, side * side * side, 1e-10 * side * side * side);
  EXPECT_NEAR(total_volume(m), sum, 1e-15);
  // every node inside the cube (up to rounding)
  for (double x : m.nodes) {
    EXPECT_GE(x, -1e-12);
    EXPECT_LE(x, side + 1e-12);
  }
}

TEST(TetgenMesher, BuildModelAcceptsTheMeshWithoutReorienting) {
  MeshingOptions o;
  o.max_volume = 1e-3 / 200;
  const VolumeMesh m = tetrahedralize_surface(cube(0.1), o, "cube");
  tissue::ModelInput in;
  in.nodes = m.nodes;
  in.tets = m.tets;
  in.materials = {{1000.0, 10000.0, 1000.0}};
  const auto model = tissue::build_model(in);  // throws on unused nodes or zero volumes
  EXPECT_EQ(model.reoriented, 0);
  EXPECT_EQ(model.n_elems, m.n_tets());
  double V = 0;
  for (double v : model.volume) V += v;
  EXPECT_NEAR(V, 1e-3, 1e-12);
}

TEST(TetgenMesher, MaxVolumeRespected) {
  for (double a : {2e-5, 5e-6}) {
    MeshingOptions o;
    o.max_volume = a;
    const VolumeMesh m = tetrahedralize_surface(cube(0.1), o, "cube");
    double vmax = 0;
    for (index_t e = 0; e < m.n_tets(); ++e) vmax = std::max(vmax, tet_volume(m, e));
    EXPECT_LE(vmax, a * (1 + 1e-9)) << "max_volume " << a;
    EXPECT_GE(m.n_tets(), 1e-3 / a) << "at least volume / max_volume tets";
    EXPECT_EQ(m.max_volume, a);
  }
}

TEST(TetgenMesher, FinerMaxVolumeGivesMoreTets) {
  MeshingOptions coarse, fine;
  coarse.max_volume = 1e-5;
  fine.max_volume = 1e-6;
  EXPECT_GT(tetrahedralize_surface(cube(0.1), fine, "cube").n_tets(),
            3 * tetrahedralize_surface(cube(0.1), coarse, "cube").n_tets());
}

TEST(TetgenMesher, TargetTetsWithinStatedTolerance) {
  for (int target : {1500, 6000}) {
    MeshingOptions o;
    o.target_tets = target;
    const VolumeMesh m = tetrahedralize_surface(cube(0.05), o, "cube");
    EXPECT_LE(std::abs(m.n_tets() - target), kTargetTolerance * target)
        << "target " << target << " got " << m.n_tets() << " after " << m.runs << " runs";
    EXPECT_LE(m.runs, kTargetRounds);
    EXPECT_GT(m.max_volume, 0);
  }
}

TEST(TetgenMesher, SwitchesFromOptions) {
  MeshingOptions o;
  EXPECT_EQ(tetgen_switches(o, "s"), "pzQq1.414");
  o.max_volume = 2.5e-8;
  o.quality = 2;
  EXPECT_EQ(tetgen_switches(o, "s"), "pzQq2a2.5e-08");
  o.quality = 0;
  EXPECT_EQ(tetgen_switches(o, "s"), "pzQa2.5e-08");
}

TEST(TetgenMesher, BadOptionsNamed) {
  MeshingOptions o;
  o.quality = 0.8;
  EXPECT_NE(mesh_error(cube(1), o).find("quality"), std::string::npos);
  o = {};
  o.max_volume = -1;
  EXPECT_NE(mesh_error(cube(1), o).find("maximum tet volume"), std::string::npos);
  o = {};
  o.target_tets = -5;
  EXPECT_NE(mesh_error(cube(1), o).find("target"), std::string::npos);
}

TEST(TetgenMesher, OpenSurfaceIsAClearError) {
  SurfaceMesh s = cube(1.0);
  s.triangles.resize(s.triangles.size() - 3);  // drop the last triangle
  const std::string msg = mesh_error(s, {});
  EXPECT_NE(msg.find("test.stl"), std::string::npos) << msg;
  EXPECT_NE(msg.find("is used by 1 triangle: the surface is open"), std::string::npos) << msg;
}

TEST(TetgenMesher, SelfIntersectingSurfaceIsAClearError) {
  SurfaceMesh s;
  add_box(s, 0.0, 1.0);
  add_box(s, 0.5, 1.0);  // interpenetrates the first box; each box alone is closed
  ASSERT_NO_THROW(check_closed(s, "two boxes"));
  const std::string msg = mesh_error(s, {});
  EXPECT_NE(msg.find("test.stl"), std::string::npos) << msg;
  EXPECT_NE(msg.find("the surface intersects itself"), std::string::npos) << msg;
  // still alive, and TetGen still usable afterwards
  EXPECT_GT(tetrahedralize_surface(cube(1.0), {}, "cube").n_tets(), 0);
}

TEST(TetgenMesher, DisjointBoxesMeshAsTwoBodies) {
  SurfaceMesh s;
  add_box(s, 0.0, 1.0);
  add_box(s, 3.0, 1.0);
  MeshingOptions o;
  o.max_volume = 0.01;
  const VolumeMesh m = tetrahedralize_surface(s, o, "two boxes");
  EXPECT_NEAR(total_volume(m), 2.0, 1e-9);
}

namespace {

/// The median of v, printed as `what`.
double median(std::vector<double> v, const char* what) {
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  std::printf("[measured] median %s %.4f of the nodes\n", what, v[v.size() / 2]);
  return v[v.size() / 2];
}

/// The median over tets of (largest - smallest corner id) / node count:
/// about 0.6 for a random numbering, small for one along a space-filling
/// curve (whose few jumps, where a tet straddles two of its big cells,
/// the median ignores).
double median_tet_span(const VolumeMesh& m) {
  std::vector<double> span;
  for (index_t e = 0; e < m.n_tets(); ++e) {
    const auto c = m.tets.begin() + 4 * e;
    span.push_back(double(*std::max_element(c, c + 4) - *std::min_element(c, c + 4)) / m.n_nodes());
  }
  return median(span, "tet span");
}

/// The median over consecutive tets of |lowest corner id of one - of the
/// next| / node count: how far the tet order jumps (about 0.14 at random).
double median_tet_step(const VolumeMesh& m) {
  std::vector<double> step;
  for (index_t e = 0; e + 1 < m.n_tets(); ++e) {
    const auto c = m.tets.begin() + 4 * e;
    step.push_back(std::fabs(double(*std::min_element(c + 4, c + 8)) - double(*std::min_element(c, c + 4))) /
                   m.n_nodes());
  }
  return median(step, "step between consecutive tets");
}

/// Each tet as its four corner positions in corner order (the renumbering
/// keeps positions, corner order and so orientation), with its region.
std::vector<std::pair<std::array<double, 12>, int>> tets_by_position(const VolumeMesh& m) {
  std::vector<std::pair<std::array<double, 12>, int>> out;
  for (index_t e = 0; e < m.n_tets(); ++e) {
    std::array<double, 12> x;
    for (int a = 0; a < 4; ++a)
      for (int c = 0; c < 3; ++c) x[3 * a + c] = m.nodes[3 * m.tets[4 * e + a] + c];
    out.push_back({x, m.tet_region.empty() ? -1 : m.tet_region[e]});
  }
  std::sort(out.begin(), out.end());
  return out;
}

}  // namespace

/// sort_for_locality renumbers a shuffled mesh along the Morton curve: the
/// same tets (corner positions in corner order, so orientation and volume)
/// with their regions, every node used, tets whose corners have nearby ids
/// and consecutive tets near each other; sorting again changes nothing, and
/// the mesher's own output is already sorted.
TEST(TetgenMesher, SortForLocalityRenumbersWithoutChangingTheMesh) {
  MeshingOptions o;
  o.quality = 1.5;
  o.max_volume = 1e-6;
  VolumeMesh m = tetrahedralize_surface(cube(0.1), o, "cube");
  ASSERT_GT(m.n_tets(), 2000);
  {
    VolumeMesh again = m;
    sort_for_locality(again);
    EXPECT_EQ(again.nodes, m.nodes);
    EXPECT_EQ(again.tets, m.tets);
  }
  m.tet_region.resize(m.n_tets());
  for (index_t e = 0; e < m.n_tets(); ++e) m.tet_region[e] = int(e % 7);
  EXPECT_LT(median_tet_span(m), 0.1);  // the mesher's output comes sorted (measured 0.047)
  // shuffle nodes and tets
  std::mt19937 rng(5);
  std::vector<index_t> perm(m.n_nodes());
  std::iota(perm.begin(), perm.end(), 0);
  std::shuffle(perm.begin(), perm.end(), rng);
  VolumeMesh shuffled = m;
  for (index_t i = 0; i < m.n_nodes(); ++i)
    for (int c = 0; c < 3; ++c) shuffled.nodes[3 * perm[i] + c] = m.nodes[3 * i + c];
  for (index_t& c : shuffled.tets) c = perm[c];
  std::vector<index_t> tet_perm(m.n_tets());
  std::iota(tet_perm.begin(), tet_perm.end(), 0);
  std::shuffle(tet_perm.begin(), tet_perm.end(), rng);
  VolumeMesh random = shuffled;
  for (index_t e = 0; e < m.n_tets(); ++e) {
    for (int a = 0; a < 4; ++a) random.tets[4 * tet_perm[e] + a] = shuffled.tets[4 * e + a];
    random.tet_region[tet_perm[e]] = shuffled.tet_region[e];
  }
  EXPECT_GT(median_tet_span(random), 0.25);  // measured 0.63
  EXPECT_GT(median_tet_step(random), 0.07);  // measured 0.14
  VolumeMesh sorted = random;
  sort_for_locality(sorted);
  EXPECT_LT(median_tet_span(sorted), 0.1);
  EXPECT_LT(median_tet_step(sorted), 0.02);  // measured 0.0026
  EXPECT_EQ(tets_by_position(sorted), tets_by_position(m));
  std::vector<int> used(sorted.n_nodes(), 0);
  for (index_t c : sorted.tets) used[c] = 1;
  EXPECT_EQ(std::count(used.begin(), used.end(), 0), 0);
  for (index_t e = 0; e < sorted.n_tets(); ++e) ASSERT_GT(tet_volume(sorted, e), 0) << "tet " << e;
  VolumeMesh again = sorted;
  sort_for_locality(again);
  EXPECT_EQ(again.nodes, sorted.nodes);
  EXPECT_EQ(again.tets, sorted.tets);
  EXPECT_EQ(again.tet_region, sorted.tet_region);
}

/// The Morton order itself: the eight corners of a box, given in reverse,
/// come out z-major, then y, then x (x the key's lowest bit); a region list
/// of the wrong length is refused, and a non-finite position leaves the
/// mesh as it is.
TEST(TetgenMesher, SortForLocalityFollowsTheMortonCurve) {
  VolumeMesh m;
  for (int v = 7; v >= 0; --v)
    for (int a = 0; a < 3; ++a) m.nodes.push_back(0.02 * ((v >> a) & 1));
  m.tets = {7, 6, 5, 3};  // corners (0,0,0), (1,0,0), (0,1,0), (0,0,1)
  sort_for_locality(m);
  for (int v = 0; v < 8; ++v)
    for (int a = 0; a < 3; ++a) EXPECT_EQ(m.nodes[3 * v + a], 0.02 * ((v >> a) & 1)) << "node " << v;
  EXPECT_EQ(m.tets, (std::vector<index_t>{0, 1, 2, 4}));
  m.tet_region = {1, 2};
  EXPECT_THROW(sort_for_locality(m), MeshError);
  m.tet_region.clear();
  m.nodes[5] = std::nan("");
  const VolumeMesh before = m;
  sort_for_locality(m);
  EXPECT_EQ(m.tets, before.tets);
}
