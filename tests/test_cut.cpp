// Cutting a mesh (core/cut.hpp): a block cut through falls into two pieces,
// each closed and manifold, with its volume kept and no element inverted;
// a cut along the mesh's own faces opens them and makes nothing new; a
// partial incision opens only what it reaches and the block stays one
// piece; an oblique cut through every method leaves a conforming mesh; bad
// blades are clear errors.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <numeric>
#include <string>
#include <vector>

#include "backends/registry.hpp"
#include "core/box_mesh.hpp"
#include "core/cut.hpp"
#include "core/model.hpp"
#include "core/scheduler.hpp"
#include "scene/cut_scene.hpp"
#include "scene/validate.hpp"
#include "tests/cut_scenes.hpp"

namespace tissue {
namespace {

using V = Vec3<double>;

struct Mesh {
  std::vector<double> nodes;
  std::vector<index_t> tets;
};

/// A 20 x 20 x 10 mm block of 4 x 4 x 2 cells (5 mm), six tets each.
Mesh block() {
  ModelInput in;
  box_mesh(in, 4, 4, 2, 0.02, 0.02, 0.01);
  return {in.nodes, in.tets};
}

V node(const std::vector<double>& x, index_t i) { return {x[3 * i], x[3 * i + 1], x[3 * i + 2]}; }

double tet_volume(const std::vector<double>& x, const std::vector<index_t>& t, std::size_t e) {
  const V a = node(x, t[4 * e]), b = node(x, t[4 * e + 1]), c = node(x, t[4 * e + 2]), d = node(x, t[4 * e + 3]);
  return dot(cross(b - a, c - a), d - a) / 6;
}

double total_volume(const std::vector<double>& x, const std::vector<index_t>& t) {
  double v = 0;
  for (std::size_t e = 0; e < t.size() / 4; ++e) v += tet_volume(x, t, e);
  return v;
}

/// Pieces: elements joined through shared nodes.
int pieces(const std::vector<index_t>& t, std::size_t n_nodes) {
  std::vector<index_t> parent(n_nodes);
  std::iota(parent.begin(), parent.end(), 0);
  const auto root = [&](index_t a) {
    while (parent[a] != a) a = parent[a] = parent[parent[a]];
    return a;
  };
  for (std::size_t e = 0; e < t.size() / 4; ++e)
    for (int c = 1; c < 4; ++c) parent[root(t[4 * e + c])] = root(t[4 * e]);
  std::vector<std::uint8_t> used(n_nodes, 0), seen(n_nodes, 0);
  for (index_t v : t) used[v] = 1;
  int n = 0;
  for (std::size_t a = 0; a < n_nodes; ++a)
    if (used[a] && !seen[root(index_t(a))]++) ++n;
  return n;
}

/// What the faces of a mesh say about it: every face is shared by at most
/// two elements (conforming, no face overlaps), and its boundary is closed
/// and oriented (each directed edge of an outward boundary face once, and
/// its reverse once).
struct FaceCheck {
  int overfull = 0, open_edges = 0, boundary_faces = 0;
};
FaceCheck faces_of(const std::vector<index_t>& t) {
  static constexpr int kFace[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};
  std::map<std::array<index_t, 3>, std::vector<std::array<index_t, 3>>> faces;
  for (std::size_t e = 0; e < t.size() / 4; ++e)
    for (const auto& f : kFace) {
      std::array<index_t, 3> v = {t[4 * e + f[0]], t[4 * e + f[1]], t[4 * e + f[2]]}, k = v;
      std::sort(k.begin(), k.end());
      faces[k].push_back(v);
    }
  FaceCheck c;
  std::map<std::pair<index_t, index_t>, int> directed;
  for (const auto& [k, list] : faces) {
    if (list.size() > 2) ++c.overfull;
    if (list.size() != 1) continue;
    ++c.boundary_faces;
    for (int i = 0; i < 3; ++i) ++directed[{list[0][i], list[0][(i + 1) % 3]}];
  }
  for (const auto& [e, n] : directed) {
    const auto back = directed.find({e.second, e.first});
    if (n != 1 || back == directed.end() || back->second != 1) ++c.open_edges;
  }
  return c;
}

/// Every element positive, the volume kept, a conforming closed boundary.
void expect_sound(const Mesh& before, const CutResult& r) {
  ASSERT_EQ(r.from.size(), std::size_t(r.n_nodes()));
  ASSERT_EQ(r.element_from.size(), std::size_t(r.n_elements()));
  double smallest = INFINITY;
  for (std::size_t e = 0; e < r.tets.size() / 4; ++e) smallest = std::min(smallest, tet_volume(r.nodes, r.tets, e));
  EXPECT_GT(smallest, 0) << "an element is inverted or flat";
  const double v0 = total_volume(before.nodes, before.tets);
  EXPECT_NEAR(total_volume(r.nodes, r.tets), v0, 1e-12 * v0) << "the volume (the mass) is kept";
  const FaceCheck f = faces_of(r.tets);
  EXPECT_EQ(f.overfull, 0) << "faces shared by three elements";
  EXPECT_EQ(f.open_edges, 0) << "boundary edges not closed and oriented";
  for (std::size_t i = 0; i < r.from.size(); ++i) {  // each node where its origin says
    const V a = node(before.nodes, r.from[i][0]), b = node(before.nodes, r.from[i][1]);
    const V want = a + r.weight[i] * (b - a), got = node(r.nodes, index_t(i));
    if (r.from[i][0] != r.from[i][1]) {
      ASSERT_LT(norm(got - want), 1e-15) << "node " << i;
    }
  }
}

/// A parallelogram over the whole 20 x 20 mm section at x = x0 (margins beyond the block).
CutSurface through_x(double x0) { return {{x0, -0.01, -0.01}, {0, 0.04, 0}, {0, 0, 0.03}}; }

TEST(Cut, ABlockCutThroughAlongItsOwnFacesFallsIntoTwoPieces) {
  const Mesh m = block();
  for (CutMethod method : {CutMethod::Snap, CutMethod::Split, CutMethod::SnapSplit}) {
    const CutResult r = cut_along(m.nodes, m.tets, through_x(0.01), {.method = method});
    expect_sound(m, r);
    EXPECT_EQ(pieces(r.tets, r.from.size()), 2);
    EXPECT_EQ(r.n_elements(), index_t(m.tets.size() / 4)) << "nothing to split: the plane holds faces already";
    EXPECT_EQ(r.copies, 5 * 3) << "every node of the plane x = 10 mm once";
    EXPECT_EQ(r.cut_faces, 4 * 2 * 2);
    EXPECT_EQ(r.snapped + r.split + r.unresolved, 0);
  }
}

TEST(Cut, ACutBetweenTheNodesSplitsOrSnapsAndTheBlockFallsApart) {
  const Mesh m = block();
  const CutSurface cut = through_x(0.012);  // 2 mm past the nodes at x = 10 mm (0.4 of their 5 mm edges)
  const CutResult split = cut_along(m.nodes, m.tets, cut, {.method = CutMethod::Split});
  expect_sound(m, split);
  EXPECT_EQ(pieces(split.tets, split.from.size()), 2);
  EXPECT_EQ(split.snapped, 0);
  EXPECT_GT(split.split, 0);
  EXPECT_GT(split.edge_nodes, 0);
  const CutResult hybrid = cut_along(m.nodes, m.tets, cut, {.method = CutMethod::SnapSplit});
  expect_sound(m, hybrid);
  EXPECT_EQ(pieces(hybrid.tets, hybrid.from.size()), 2);
  // of the 15 nodes at x = 10 mm: the 3 inside and the 8 on the faces (sliding along them); the 4 on the block's
  // edges stay
  EXPECT_EQ(hybrid.snapped, 3 + 8);
  EXPECT_LT(hybrid.split, split.split) << "snapping leaves fewer elements to split";
  // snapping alone cannot move the nodes on the block's edges: the elements there stay whole and join the halves
  const CutResult snap = cut_along(m.nodes, m.tets, cut, {.method = CutMethod::Snap});
  expect_sound(m, snap);
  EXPECT_GT(snap.unresolved, 0);
  EXPECT_EQ(snap.split, 0);
  EXPECT_EQ(pieces(snap.tets, snap.from.size()), 1);
}

TEST(Cut, APartialIncisionOpensWhatItReachesAndTheBlockStaysWhole) {
  const Mesh m = block();
  // the plane x = 10 mm from y = -10 mm to y = 5 mm: the faces of the first row of cells, up to the nodes at 5 mm
  const CutSurface cut{{0.01, -0.01, -0.01}, {0, 0.015, 0}, {0, 0, 0.03}};
  const CutResult r = cut_along(m.nodes, m.tets, cut, {.method = CutMethod::SnapSplit});
  expect_sound(m, r);
  EXPECT_EQ(pieces(r.tets, r.from.size()), 1);
  EXPECT_EQ(r.cut_faces, 2 * 2) << "the first row's two cells, two triangles each";
  EXPECT_EQ(r.copies, 3) << "the nodes at y = 0, three heights; the front's at y = 5 mm stay joined";
  EXPECT_GT(faces_of(r.tets).boundary_faces, faces_of(m.tets).boundary_faces) << "the incision's faces are surface";
}

TEST(Cut, AnObliqueCutByEveryMethodLeavesAConformingMesh) {
  const Mesh m = block();
  const CutSurface cut{{0.011, -0.01, -0.01}, {0.003, 0.04, 0}, {0.002, 0, 0.03}};
  for (CutMethod method : {CutMethod::Split, CutMethod::SnapSplit}) {
    const CutResult r = cut_along(m.nodes, m.tets, cut, {.method = method});
    expect_sound(m, r);
    EXPECT_EQ(pieces(r.tets, r.from.size()), 2) << "method " << int(method);
    EXPECT_EQ(r.unresolved, 0);
  }
}

/// The cutting tests' block as a scene (tests/cut_scenes.hpp: E 3 kPa, nu 0.4, its base held, a probe
/// parked far above), its corner node 0 held by id too, with the default mass scaling.
scene::Scene block_scene() {
  scene::Scene s = test::block_scene();
  scene::Constraint corner;
  corner.nodes = {0};
  s.constraints.push_back(corner);
  s.solver.mass_scaling = scene::Solver{}.mass_scaling;
  return s;
}

/// u after `ticks` ticks of a sideways pull (+x) on the top nodes beyond x = 12 mm.
std::vector<double> pulled(const scene::Scene& s, int ticks) {
  const TissueModel<double> m = scene::load_model(s);
  auto backend = create_backend("cpu", Precision::Double);
  backend->upload(m);
  Scheduler sched(*backend, m, scene::scheduler_settings(s));
  std::vector<index_t> top;
  std::vector<double> force;
  for (index_t i = 0; i < m.n_nodes; ++i)
    if (m.X[2 * size_t(m.n_nodes) + i] > 0.01 - 1e-9 && m.X[i] > 0.012 + 1e-9) {
      top.push_back(i);
      force.insert(force.end(), {2e-4, 0, 0});
    }
  sched.set_loads(top, force);
  ScriptedDevice device(s.tools[0].path);
  for (int k = 0; k < ticks; ++k) sched.tick(device);
  return backend->download().u;  // component-major
}

// Cut through, the halves move apart under a load on one of them: the
// other rests exactly, where the whole block carried the pull across; the
// cut scene keeps its supports (the corner node listed by id and its copies).
TEST(Cut, TheHalvesOfACutBlockMoveIndependently) {
  const scene::Scene whole = block_scene();
  CutResult r;
  const scene::Scene cut = scene::cut_scene(whole, through_x(0.012), {}, &r);
  EXPECT_EQ(cut.constraints[1].nodes, std::vector<index_t>{0});
  EXPECT_NO_THROW(scene::validate(cut));
  const std::vector<double> u0 = pulled(whole, 400), u1 = pulled(cut, 400);
  const index_t n0 = index_t(whole.nodes.size() / 3), n1 = r.n_nodes();
  double left_whole = 0, left_cut = 0, right_cut = 0;
  for (index_t i = 0; i < n0; ++i)
    if (whole.nodes[3 * i] < 0.01 - 1e-9) left_whole = std::max(left_whole, std::fabs(u0[i]));
  for (index_t i = 0; i < n1; ++i) {
    const double x = cut.nodes[3 * i];
    if (x < 0.012 - 1e-9) left_cut = std::max(left_cut, std::fabs(u1[i]));
    if (x > 0.012 + 1e-9) right_cut = std::max(right_cut, std::fabs(u1[i]));
  }
  EXPECT_GT(left_whole, 1e-5) << "the whole block carries the pull across";
  EXPECT_GT(right_cut, 1e-4) << "the pulled half moves";
  EXPECT_EQ(left_cut, 0.0) << "the other half rests: nothing joins it to the pulled one";
}

// A fixed node on the cut is copied, and both copies stay fixed.
TEST(Cut, AFixedNodeOnTheCutStaysFixedOnBothSides) {
  scene::Scene s = block_scene();
  s.constraints[1].nodes = {box_node(4, 4, 2, 0, 0)};  // on the plane x = 10 mm, at the base
  const scene::Scene cut = scene::cut_scene(s, through_x(0.01), {});
  ASSERT_EQ(cut.constraints[1].nodes.size(), 2u);
  for (index_t i : cut.constraints[1].nodes) {
    EXPECT_DOUBLE_EQ(cut.nodes[3 * i], 0.01);
    EXPECT_DOUBLE_EQ(cut.nodes[3 * i + 1], 0.0);
  }
  const ModelInput in = scene::to_model_input(cut);
  EXPECT_EQ(in.fixed[cut.constraints[1].nodes[0]], 1);
  EXPECT_EQ(in.fixed[cut.constraints[1].nodes[1]], 1);
}

TEST(Cut, BadBladesAreClearErrors) {
  const Mesh m = block();
  const auto message = [&](const CutSurface& c, CutOptions o = {}) {
    try {
      (void)cut_along(m.nodes, m.tets, c, o);
    } catch (const CutError& e) {
      return std::string(e.what());
    }
    return std::string("(no error)");
  };
  EXPECT_NE(message({{0.01, 0, 0}, {0, 0, 0}, {0, 0, 0.01}}).find("edge has zero length"), std::string::npos);
  EXPECT_NE(message({{0.01, 0, 0}, {0, 0.01, 0}, {0, 0, 0}}).find("sweep has zero length"), std::string::npos);
  EXPECT_NE(message({{0.01, 0, 0}, {0, 0.01, 0}, {0, 0.02, 0}}).find("moves along its own edge"), std::string::npos);
  EXPECT_NE(message({{0.05, 0, 0}, {0, 0.01, 0}, {0, 0, 0.01}}).find("crosses no element"), std::string::npos);
  EXPECT_NE(message({{0.01, 0, 0}, {0, 0.01, 0}, {0, 0, 0.01}}, {.snap = 0.7}).find("snap = 0.7"), std::string::npos);
  EXPECT_NE(message({{0.01, 0, 0}, {NAN, 0.01, 0}, {0, 0, 0.01}}).find("finite"), std::string::npos);
}

}  // namespace
}  // namespace tissue
