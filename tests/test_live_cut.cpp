// Cutting while the simulation runs (Session::cut, core cut_moving,
// docs/cutting.md): a cut made where the tissue is now carries the motion
// over as the mesh's own field at the new nodes, keeps the mass, creates no
// energy, and the pieces move on independently; a cut while a tool presses
// runs on; bad cuts are refused and leave the run as it was; reset goes
// back to the mesh before the cut.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <string>
#include <map>
#include <memory>
#include <numeric>
#include <vector>

#include "core/box_mesh.hpp"
#include "backend_test_support.hpp"
#include "cut_scenes.hpp"
#include "core/cut.hpp"
#include "io/kidney.hpp"
#include "scene/validate.hpp"
#include "session/scene_batch.hpp"
#include "session/session.hpp"

namespace tissue {
namespace {

using V = Vec3<double>;
using test::blade_scene;
using test::block_scene;

/// The top nodes beyond x = 12 mm, pulled sideways (+x) with 0.2 mN each.
void pull_right_top(Session& s) {
  const TissueModel<double>& m = s.model();
  std::vector<index_t> top;
  std::vector<double> force;
  for (index_t i = 0; i < m.n_nodes; ++i)
    if (m.X[2 * size_t(m.n_nodes) + i] > 0.01 - 1e-9 && m.X[i] > 0.012 + 1e-9) {
      top.push_back(i);
      force.insert(force.end(), {2e-4, 0, 0});
    }
  s.set_loads(top, force);
}

std::string g(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%.4g", v);
  return b;
}

V at(const std::vector<double>& f, std::size_t n, std::size_t a) { return {f[a], f[n + a], f[2 * n + a]}; }
V ref(const TissueModel<double>& m, index_t a) { return reference_position(m, a); }

double total_mass(const TissueModel<double>& m) { return std::accumulate(m.mass.begin(), m.mass.end(), 0.0); }

/// A vertical cut at x = x0 over the whole 20 x 20 mm section (margins beyond the block).
CutSurface through_x(double x0) { return {{x0, -0.01, -0.01}, {0, 0.04, 0}, {0, 0, 0.03}}; }

/// Each node's piece (elements joined through shared nodes): a root node id.
std::vector<index_t> piece_of(const TissueModel<double>& m) {
  std::vector<index_t> parent(std::size_t(m.n_nodes));
  std::iota(parent.begin(), parent.end(), 0);
  const auto root = [&](index_t a) {
    while (parent[a] != a) a = parent[a] = parent[parent[a]];
    return a;
  };
  const std::size_t ne = std::size_t(m.n_elems);
  for (std::size_t e = 0; e < ne; ++e)
    for (int c = 1; c < 4; ++c) parent[root(m.elem_nodes[c * ne + e])] = root(m.elem_nodes[e]);
  for (index_t a = 0; a < m.n_nodes; ++a) parent[a] = root(a);
  return parent;
}

int pieces(const TissueModel<double>& m) {
  const std::vector<index_t> p = piece_of(m);
  int n = 0;
  for (index_t a = 0; a < m.n_nodes; ++a) n += p[a] == a;
  return n;
}

// A block pulled sideways, cut mid-motion between the nodes (2 mm past
// those at x = 10 mm: snapped, split, opened): every node that keeps its id
// keeps its place, reference position and velocity; every node made on an
// edge lies where the deformed edge is and moves as the edge's ends in
// proportion; the mass is the volume's, exactly; the kinetic energy does
// not rise.
TEST(LiveCut, ACutCarriesTheMotionOverAsTheFieldAtTheNewNodes) {
  Session s(block_scene());
  pull_right_top(s);
  for (int k = 0; k < 30; ++k) s.tick();
  const TissueModel<double> before = s.model();  // a copy: the session's model is replaced
  const index_t n0 = before.n_nodes;
  const std::vector<double> u0 = s.backend().download().u, p0 = s.backend().previous_displacements();
  const Reductions e0 = s.backend().reduce();
  double largest_v = 0;
  for (std::size_t k = 0; k < u0.size(); ++k) largest_v = std::max(largest_v, std::fabs(u0[k] - p0[k]));
  ASSERT_GT(largest_v, 1e-9) << "the block is moving when it is cut";

  const SessionCut c = s.cut(through_x(0.012));
  const TissueModel<double>& after = s.model();
  EXPECT_GT(c.cut.split, 0);
  EXPECT_GT(c.cut.copies, 0);
  EXPECT_EQ(pieces(after), 2) << "cut through";
  EXPECT_EQ(after.n_nodes, c.cut.n_nodes());
  const index_t n1 = after.n_nodes;
  const std::vector<double> u1 = s.backend().download().u, p1 = s.backend().previous_displacements();
  ASSERT_EQ(u1.size(), 3 * std::size_t(n1));

  const auto x0 = [&](index_t a) { return ref(before, a) + at(u0, n0, a); };
  const auto x1 = [&](index_t a) { return ref(after, a) + at(u1, n1, a); };
  index_t unmoved = 0, edge = 0;
  for (index_t i = 0; i < n1; ++i) {
    const auto [a, b] = c.cut.from[i];
    if (a == b) {
      if (norm(x1(i) - x0(a)) > 1e-15) continue;  // a snapped node (or its copy): below
      ++unmoved;
      EXPECT_LT(norm(ref(after, i) - ref(before, a)), 1e-15) << "node " << i;
      const V v0 = (1 / c.dt_before) * (at(u0, n0, a) - at(p0, n0, a));
      const V v1 = (1 / c.dt_after) * (at(u1, n1, i) - at(p1, n1, i));
      EXPECT_LT(norm(v1 - v0), 1e-9 * largest_v / c.dt_before) << "node " << i << ": the same velocity";
      continue;
    }
    ++edge;
    // on the deformed edge between its ends as they are after the cut, moving with them
    const index_t ea = a, eb = b;  // the ends keep their ids (old nodes come first)
    const double w = c.cut.weight[i];
    EXPECT_LT(norm(x1(i) - ((1 - w) * x1(ea) + w * x1(eb))), 1e-12) << "edge node " << i;
    const V v_i = at(u1, n1, i) - at(p1, n1, i);
    const V v_ab = (1 - w) * (at(u1, n1, ea) - at(p1, n1, ea)) + w * (at(u1, n1, eb) - at(p1, n1, eb));
    EXPECT_LT(norm(v_i - v_ab), 1e-12 * std::max(1.0, largest_v)) << "edge node " << i;
  }
  EXPECT_GT(unmoved, n0 / 2);
  EXPECT_GT(edge, 0);

  const double rho_v = 1000 * 0.02 * 0.02 * 0.01;
  EXPECT_NEAR(total_mass(before), rho_v, 1e-12 * rho_v);
  EXPECT_NEAR(total_mass(after), rho_v, 1e-12 * rho_v) << "no element is deleted: the mass is kept";

  const Reductions e1 = s.backend().reduce();
  EXPECT_LE(e1.kinetic, e0.kinetic * (1 + 1e-9)) << "the velocities carried over move no more mass faster";
}

/// The strain energy's change across a cut of the pulled block, relative.
double energy_jump(bool ianp, CutMethod method) {
  scene::Scene sc = block_scene();
  sc.solver.ianp = ianp;
  Session s(sc);
  pull_right_top(s);
  for (int k = 0; k < 30; ++k) s.tick();
  const double before = s.backend().reduce().strain_energy;
  s.cut(through_x(0.012), {.method = method});
  return s.backend().reduce().strain_energy / before - 1;
}

// What the cut does to the strain energy at its instant. Splitting alone
// keeps it exactly without IANP: each piece of a split element is that
// element's own affine map. Snapping moves nodes within their elements, so
// the field is interpolated again there: within 1 %. IANP's nodal pressure
// averages over each node's elements; a node copied across the cut then
// averages over its own side's only, and by Jensen's inequality (the
// volumetric energy is convex in J) that can only raise the energy: +1.2 %
// on this coarse block (0.25-0.5 % on 8 cells across, docs/cutting.md).
TEST(LiveCut, TheCutChangesTheStrainEnergyOnlyWhereItInterpolatesOrSplitsANodalAverage) {
  const double split_plain = energy_jump(false, CutMethod::Split), snap_plain = energy_jump(false, CutMethod::SnapSplit);
  const double split_ianp = energy_jump(true, CutMethod::Split), snap_ianp = energy_jump(true, CutMethod::SnapSplit);
  RecordProperty("split_plain", g(split_plain));
  RecordProperty("snap_split_plain", g(snap_plain));
  RecordProperty("split_ianp", g(split_ianp));
  RecordProperty("snap_split_ianp", g(snap_ianp));
  EXPECT_LT(std::fabs(split_plain), 1e-12);
  EXPECT_LT(std::fabs(snap_plain), 0.01);
  EXPECT_GT(split_ianp, 0) << "Jensen: a split average only raises a convex energy";
  EXPECT_LT(split_ianp, 0.015);
  EXPECT_LT(std::fabs(snap_ianp), 0.015);
}

// Undamped, the block swings after its pull is let go; cut mid-swing, its
// energy (strain + kinetic) stays within the band it swung in before: the
// cut and the run after it create no energy.
void undamped_cut_mid_swing(bool lip_contact) {
  scene::Scene sc = block_scene();
  sc.solver.damping = 0.0;
  sc.solver.dt_safety = 0.2;
  sc.solver.lip_contact = lip_contact;
  Session s(sc);
  pull_right_top(s);
  for (int k = 0; k < 30; ++k) s.tick();
  s.set_loads({}, {});
  const auto energy = [&] {
    const Reductions r = s.backend().reduce();
    return r.strain_energy + r.kinetic;
  };
  double before = 0;
  for (int k = 0; k < 200; ++k) {
    s.tick();
    before = std::max(before, energy());
  }
  s.cut(through_x(0.012));
  double after = energy();
  for (int k = 0; k < 800; ++k) {
    s.tick();
    after = std::max(after, energy());
  }
  ::testing::Test::RecordProperty(lip_contact ? "most_before_lips_touching_J" : "most_before_J", g(before));
  ::testing::Test::RecordProperty(lip_contact ? "most_after_lips_touching_J" : "most_after_J", g(after));
  EXPECT_LE(after, before) << (lip_contact ? "the lips touching" : "");
}

TEST(LiveCut, AnUndampedBlockCutMidSwingGainsNoEnergy) {
  undamped_cut_mid_swing(false);
  undamped_cut_mid_swing(true);
}

// Cut through and run on: the half that is pulled moves off; the other, no
// longer joined to it, springs back towards rest; the session runs on
// without a stop and counts its ticks on.
TEST(LiveCut, ThePiecesMoveOnIndependently) {
  Session s(block_scene());
  pull_right_top(s);
  for (int k = 0; k < 200; ++k) s.tick();
  // the largest |u| of the nodes of node 0's piece (the unloaded side: x = 0), or before the cut of those at
  // x <= 10 mm; and the largest u_x of the others
  const auto largest = [&](bool loaded_side) {
    const TissueModel<double>& m = s.model();
    const std::vector<double> u = s.backend().download().u;
    const std::vector<index_t> piece = piece_of(m);
    const bool whole = pieces(m) == 1;
    double most = 0;
    for (index_t i = 0; i < m.n_nodes; ++i) {
      const bool left = whole ? ref(m, i).x < 0.01 + 1e-9 : piece[i] == piece[0];
      if (left != loaded_side)
        most = std::max(most, loaded_side ? u[std::size_t(i)] : norm(at(u, std::size_t(m.n_nodes), std::size_t(i))));
    }
    return most;
  };
  const double left_joined = largest(false), right_joined = largest(true);
  ASSERT_GT(left_joined, 1e-5) << "the whole block carries the pull across";
  s.cut(through_x(0.011));
  EXPECT_EQ(pieces(s.model()), 2);
  for (int k = 0; k < 600; ++k) s.tick();
  EXPECT_EQ(s.scheduler().ticks(), 800);
  EXPECT_FALSE(s.failed());
  const double left_freed = largest(false), right_freed = largest(true);
  RecordProperty("unloaded_before_m", g(left_joined));
  RecordProperty("unloaded_after_m", g(left_freed));
  RecordProperty("pulled_before_m", g(right_joined));
  RecordProperty("pulled_after_m", g(right_freed));
  EXPECT_LT(left_freed, 1e-3 * left_joined) << "the unloaded piece springs back to rest once nothing pulls it";
  EXPECT_GT(right_freed, 1.2 * right_joined) << "the pulled piece, no longer held by the other, moves farther";
}

// A cut partway into a block under tension opens: the two lips, joined
// before, move apart; the block stays one piece.
TEST(LiveCut, APartialIncisionOpensUnderTension) {
  scene::Scene sc = block_scene();
  Session s(sc);
  // pull the right face (+x) and hold the left face: tension across x
  const TissueModel<double>& m = s.model();
  std::vector<index_t> right;
  std::vector<double> force;
  for (index_t i = 0; i < m.n_nodes; ++i)
    if (ref(m, i).x > 0.02 - 1e-9) {
      right.push_back(i);
      force.insert(force.end(), {5e-4, 0, 0});
    }
  s.set_loads(right, force);
  for (int k = 0; k < 200; ++k) s.tick();
  // an incision from the top (z = 10 mm) down to z = 4 mm, at x = 12 mm, across the whole width
  const SessionCut c = s.cut({{0.012, -0.01, 0.004}, {0, 0.04, 0}, {0, 0, 0.01}});
  EXPECT_EQ(pieces(s.model()), 1) << "a partial incision leaves one piece";
  EXPECT_GT(c.cut.cut_faces, 0);
  for (int k = 0; k < 400; ++k) s.tick();
  // the gap between a top node's copies across the cut
  const TissueModel<double>& cm = s.model();
  const std::vector<double> u = s.backend().download().u;
  const std::size_t n = std::size_t(cm.n_nodes);
  double widest = 0;
  for (index_t i = 0; i < cm.n_nodes; ++i) {
    const auto [a, b] = c.cut.from[std::size_t(i)];
    if (a != b || a == i || ref(cm, i).z < 0.01 - 1e-9) continue;  // a copy, on the top
    widest = std::max(widest, norm((ref(cm, i) + at(u, n, i)) - (ref(cm, a) + at(u, n, a))));
  }
  RecordProperty("lip_gap_m", g(widest));
  EXPECT_GT(widest, 1e-4) << "the incision opens under tension";
}

// A cut across the kidney while its probe presses it: no element inverts,
// the step stays at least half of what it was, and the press runs on.
void kidney_cut_while_pressed(bool lip_contact) {
  scene::Scene sc = io::default_kidney_scene();
  sc.solver.lip_contact = lip_contact;
  Session s(sc);
  for (int k = 0; k < 150; ++k) s.tick();
  ASSERT_GT(s.last().tools[0].contact_nodes, 0) << "the probe presses when the cut is made";
  const double force = norm(s.last().tools[0].force);
  // a transverse cut 25 mm from the probe's side of the kidney's middle (x), through its whole section
  const SessionCut c = s.cut({{-0.025, -0.06, -0.04}, {0, 0.12, 0}, {0, 0, 0.08}});
  EXPECT_GT(c.cut.split + c.cut.snapped, 0);
  if (!lip_contact) {
    ::testing::Test::RecordProperty("dt_after_over_before", g(c.dt_after / c.dt_before));
    ::testing::Test::RecordProperty("dt_crit_after_over_before", g(c.dt_crit_after / c.dt_crit_before));
    ::testing::Test::RecordProperty("added_mass_before_kg", g(c.added_mass_before));
    ::testing::Test::RecordProperty("added_mass_after_kg", g(c.added_mass_after));
    ::testing::Test::RecordProperty("elements_made", g(double(c.cut.n_elements() - c.elements_before)));
  }
  EXPECT_GE(c.dt_crit_after, 0.5 * c.dt_crit_before) << "no sliver sets the step";
  EXPECT_GE(c.dt_after, c.dt_before) << "mass scaling keeps the scene's step";
  for (int k = 0; k < 200; ++k) s.tick();  // throws SimulationError on an inverted element
  EXPECT_FALSE(s.failed());
  EXPECT_GT(norm(s.last().tools[0].force), 0.5 * force) << "the probe still presses";
  if (lip_contact) {
    EXPECT_TRUE(s.backend().body_contact().lips) << "the lips touch";
    EXPECT_TRUE(s.scheduler().region_depth() == kDepthAll) << "a cut mesh whose lips touch steps whole";
  }
}

TEST(LiveCut, ACutAcrossTheKidneyWhileItsProbePresses) {
  kidney_cut_while_pressed(false);
  kidney_cut_while_pressed(true);  // its lips touching
}

// The kidney cut across four times, 20 ticks apart, while its probe presses,
// stepped whole with its lips touching (cpu, double): the pieces a cut leaves
// between the planes' splits took the assembled mesh's stable step below the
// scene's dt while every element's own L_e / c_e still allowed it (0.87 of
// dt after the third cut, on the cuts made at rest), and an element in the
// cut inverted 20 ticks after it.
// The model's assembled check gives the nodes of that mode mass instead.
TEST(LiveCut, TheKidneyCutFourTimesStepsWholeWithItsLipsTouching) {
  scene::Scene scene = io::default_kidney_scene();
  scene.solver.precision = Precision::Double;
  scene.solver.lip_contact = true;
  Session s(scene);
  while (!s.scheduler().in_contact() && s.scheduler().ticks() < 2000) s.tick();
  for (int k = 0; k < 50; ++k) s.tick();
  index_t given = 0;
  for (double x : {-0.03, -0.02, 0.02, 0.03}) {
    s.cut({{x, -0.06, -0.04}, {0, 0.12, 0}, {0, 0, 0.08}});
    const TissueModel<double>& m = s.model();
    EXPECT_LE(m.dt, 0.95 * m.assembled_step * (1 + 1e-12)) << "cut at x = " << x;
    given = std::max(given, m.assembled_nodes);
    for (int k = 0; k < 20; ++k) s.tick();  // throws SimulationError on an inverted element
  }
  ::testing::Test::RecordProperty("assembled_nodes_most", g(double(given)));
  EXPECT_GT(given, 0) << "a cut left a mode the elements' own steps miss";
  EXPECT_EQ(s.scheduler().steps_per_tick(), 4) << "mass, not more steps";
  for (int k = 0; k < 100; ++k) s.tick();
  EXPECT_FALSE(s.failed());
  EXPECT_TRUE(s.scheduler().region_depth() == kDepthAll);
}

// The same cuts made at rest: the assembled check gives the cut's mode mass
// within the mass-scaling budget. With a budget that the elements' own
// scaling fits in but the check's mass does not, the check takes its mass
// back and lowers dt to 0.95 of the assembled limit, in whole steps per
// tick; a dt the scene asks for is refused, naming the assembled limit.
TEST(LiveCut, TheAssembledCheckKeepsToTheMassScalingBudget) {
  scene::Scene kidney = io::default_kidney_scene();
  kidney.solver.precision = Precision::Double;
  Session s(kidney);
  for (double x : {-0.03, -0.02, 0.02}) s.cut({{x, -0.06, -0.04}, {0, 0.12, 0}, {0, 0, 0.08}}, {}, CutSpace::Reference);
  const TissueModel<double>& m = s.model();
  ASSERT_GT(m.assembled_mass, 0) << "the third cut's mode is given mass";
  EXPECT_LE(m.added_mass, kidney.solver.mass_scaling * m.total_mass * (1 + 1e-12));
  const double elements = m.added_mass - m.assembled_mass;
  scene::Scene tight = s.scene();
  tight.solver.mass_scaling = (elements + 0.5 * m.assembled_mass) / m.total_mass;
  const TissueModel<double> lowered = scene::load_model(tight);
  EXPECT_EQ(lowered.assembled_nodes, 0);
  EXPECT_EQ(lowered.assembled_mass, 0);
  EXPECT_NEAR(lowered.added_mass, elements, 1e-12 * m.total_mass) << "the elements' own scaling only";
  EXPECT_GT(lowered.assembled_step, 0);
  EXPECT_LE(lowered.dt, 0.95 * lowered.assembled_step * (1 + 1e-12));
  EXPECT_LT(lowered.dt, m.dt);
  const double steps = tight.solver.tick / lowered.dt;
  EXPECT_NEAR(steps, std::round(steps), 1e-9);
  ::testing::Test::RecordProperty("steps_per_tick_lowered", g(std::round(steps)));
  tight.solver.dt = m.dt;
  try {
    scene::load_model(tight);
    ADD_FAILURE() << "a requested dt above the assembled limit was accepted";
  } catch (const std::exception& e) {
    EXPECT_NE(std::string(e.what()).find("assembled mesh's stable limit"), std::string::npos) << e.what();
  }
}

// Refused cuts name the rule and leave the run as it was; reset goes back
// to the mesh before the first cut.
TEST(LiveCut, BadCutsAreRefusedAndResetRestoresTheWholeMesh) {
  Session s(block_scene());
  pull_right_top(s);
  for (int k = 0; k < 20; ++k) s.tick();
  const index_t n0 = s.model().n_nodes;
  const std::vector<double> u0 = s.backend().download().u;
  const auto message = [&](const CutSurface& c) {
    try {
      s.cut(c);
    } catch (const CutError& e) {
      return std::string(e.what());
    }
    return std::string("(no error)");
  };
  EXPECT_NE(message({{0.01, 0, 0}, {0, 0, 0}, {0, 0, 0.01}}).find("edge has zero length"), std::string::npos);
  EXPECT_NE(message({{0.05, 0, 0}, {0, 0.01, 0}, {0, 0, 0.01}}).find("crosses no element"), std::string::npos);
  EXPECT_EQ(s.model().n_nodes, n0);
  EXPECT_EQ(s.backend().download().u, u0) << "a refused cut changes nothing";
  s.tick();  // and the run goes on

  s.cut(through_x(0.012));
  EXPECT_GT(s.model().n_nodes, n0);
  for (int k = 0; k < 5; ++k) s.tick();
  s.restart();
  EXPECT_EQ(s.model().n_nodes, n0) << "reset: the mesh before the cut";
  EXPECT_EQ(pieces(s.model()), 1);
  s.tick();
}

struct Stroke {
  long first_cut_tick = 0;     ///< the tick whose report first said the tissue gave
  double first_cut_force = 0;  ///< the blade's force when the tissue first gave (N)
  double most = 0;             ///< the largest force over the stroke (N)
  long cuts = 0;
  int pieces = 0;
};

Stroke stroke(const scene::Scene& sc, int ticks) {
  Session s(sc);
  Stroke out;
  for (int k = 0; k < ticks; ++k) {
    s.tick();
    const ToolReport& r = s.last().tools[0];
    out.most = std::max(out.most, r.force.z);
    if (r.cut && out.first_cut_force == 0) out.first_cut_force = r.force.z, out.first_cut_tick = s.last().tick;
  }
  out.cuts = s.cuts();
  out.pieces = pieces(s.model());
  return out;
}

// A blade pushed down through the block with its button held: it presses
// until the force per metre of edge in contact (the block's 20 mm width)
// reaches its cutting resistance, then the tissue gives, and by the stroke's
// end the block lies in two pieces. Twice the resistance takes twice the
// force to start the cut. With the button up the same blade presses like a
// tool, beyond that force, and cuts nothing.
TEST(Blade, ItCutsWhereTheForcePerMetreReachesItsResistanceAndPressesBelowIt) {
  const Stroke at5 = stroke(blade_scene(true, 5), 1000), at2 = stroke(blade_scene(true, 2.5), 1000);
  RecordProperty("first_cut_force_5", g(at5.first_cut_force));
  RecordProperty("first_cut_force_2_5", g(at2.first_cut_force));
  RecordProperty("most_force_5", g(at5.most));
  RecordProperty("cuts_5", g(double(at5.cuts)));
  EXPECT_NEAR(at5.first_cut_force, 5 * 0.02, 0.15 * 5 * 0.02) << "J_c times the edge in contact (the block's width)";
  EXPECT_NEAR(at5.first_cut_force / at2.first_cut_force, 2, 0.2);
  EXPECT_GE(at5.cuts, 2);
  EXPECT_EQ(at5.pieces, 2) << "cut through";
  EXPECT_EQ(at2.pieces, 2);
  EXPECT_LT(at5.most, 2 * 5 * 0.02) << "the tissue gives at about its resistance, not far beyond";

  const Stroke pressed = stroke(blade_scene(false, 5, 0.007), 480);  // 3 mm into the block
  EXPECT_EQ(pressed.cuts, 0);
  EXPECT_EQ(pressed.pieces, 1);
  EXPECT_GT(pressed.most, 1.1 * 5 * 0.02) << "without its button the blade presses past the resistance";
}

// A cut prepared while the ticks run on (begin_cut) and taking effect ten
// ticks later is, in the reference configuration, the very cut cut() makes
// then: the same mesh and, bit for bit, the same motion, then and 50 ticks
// on (cpu, double). One at a time; restart drops one in preparation.
/// The block pulled and cut through at x = 12 mm at the end of tick 40 twice: prepared from tick 30 on
/// (`later`, begin_cut) and made then (`now`, cut()); both run on 50 ticks. The two must agree bit for bit.
void expect_a_later_cut_to_be_the_cut_made_then(Session& later, Session& now) {
  const CutSurface plane = through_x(0.012);
  for (Session* s : {&later, &now}) {
    pull_right_top(*s);
    for (int k = 0; k < 30; ++k) s->tick();
  }
  later.begin_cut(plane, {}, CutSpace::Reference, 40);
  EXPECT_TRUE(later.cut_pending());
  EXPECT_THROW(later.begin_cut(plane, {}, CutSpace::Reference, 45), std::logic_error);
  for (int k = 30; k < 40; ++k) {
    EXPECT_EQ(later.model().n_nodes, now.model().n_nodes) << "the cut takes effect at the end of tick 40, not before";
    later.tick(), now.tick();
  }
  EXPECT_FALSE(later.cut_pending());
  EXPECT_EQ(later.cuts(), 1);
  EXPECT_GT(later.last_cut_prepare_seconds(), 0);
  now.cut(plane, {}, CutSpace::Reference);
  ASSERT_EQ(later.model().n_nodes, now.model().n_nodes);
  ASSERT_EQ(later.model().n_elems, now.model().n_elems);
  EXPECT_EQ(pieces(later.model()), 2);
  EXPECT_EQ(later.backend().download().u, now.backend().download().u);
  EXPECT_EQ(later.backend().previous_displacements(), now.backend().previous_displacements());
  for (int k = 0; k < 50; ++k) later.tick(), now.tick();
  EXPECT_EQ(later.backend().download().u, now.backend().download().u) << "and runs on as it";
}

TEST(DeferredCut, ACutTakingEffectLaterIsTheCutMadeThen) {
  Session later(block_scene()), now(block_scene());
  expect_a_later_cut_to_be_the_cut_made_then(later, now);

  later.begin_cut(through_x(0.004), {}, CutSpace::Reference, later.scheduler().ticks() + 5);
  later.restart();
  EXPECT_FALSE(later.cut_pending());
  EXPECT_FALSE(later.was_cut());
  for (int k = 0; k < 10; ++k) later.tick();
  EXPECT_FALSE(later.was_cut()) << "restart dropped the cut in preparation";

  // a cut outside the body: the tick that makes it refuses it, and the run goes on uncut
  later.begin_cut({{0.1, -0.01, -0.01}, {0, 0.04, 0}, {0, 0, 0.03}}, {}, CutSpace::Reference, later.scheduler().ticks() + 2);
  later.tick();
  EXPECT_THROW(later.tick(), CutError);
  EXPECT_FALSE(later.cut_pending());
  later.tick();
  EXPECT_FALSE(later.was_cut());
  EXPECT_FALSE(later.failed());
}

// A blade with a cut delay (the default's way): the tissue gives at the
// same tick as without one (the runs are the same until then), and its cut
// takes effect the delay later, prepared while the ticks ran on; the
// stroke still ends in two pieces.
TEST(DeferredCut, ABladesCutTakesEffectItsDelayAfterTheTissueGives) {
  const Stroke at_once = stroke(blade_scene(true, 5), 1000);
  const Stroke delayed = stroke(blade_scene(true, 5, 0.002, 0.02), 1000);
  RecordProperty("first_cut_tick", g(double(at_once.first_cut_tick)));
  RecordProperty("first_cut_tick_delayed", g(double(delayed.first_cut_tick)));
  RecordProperty("first_cut_force_delayed", g(delayed.first_cut_force));
  EXPECT_EQ(delayed.first_cut_tick, at_once.first_cut_tick + 20) << "0.02 s at 1 ms ticks";
  EXPECT_GT(delayed.first_cut_force, at_once.first_cut_force) << "it pressed on meanwhile";
  EXPECT_GE(delayed.cuts, 2);
  EXPECT_EQ(delayed.pieces, 2);
}

scene::Scene on(scene::Scene s, const char* backend, Precision p) {
  s.solver.backend = backend;
  s.solver.precision = p;
  return s;
}

/// Largest |a - b| over the largest |a|.
double relative_gap(const std::vector<double>& a, const std::vector<double>& b) {
  double most = 0, scale = 0;
  for (std::size_t k = 0; k < a.size(); ++k) {
    most = std::max(most, std::fabs(a[k] - b[k]));
    scale = std::max(scale, std::fabs(a[k]));
  }
  return most / scale;
}

// The same live cut on the cuda backend: the block pulled, cut mid-motion
// and run on gives the cpu's pieces (the same node and element counts) and
// the cpu's displacements within the cross-backend tolerances (docs/cuda.md,
// "Cross-backend consistency": double 1e-9, float 1e-3 on a box), through
// cuda's set_motion and previous_displacements.
TEST(LiveCutCuda, ACutMidMotionGivesTheCpusPiecesAndMotion) {
  SKIP_UNLESS_USABLE("cuda");
  for (Precision p : {Precision::Double, Precision::Float}) {
    const bool dbl = p == Precision::Double;
    Session cpu(on(block_scene(), "cpu", p)), gpu(on(block_scene(), "cuda", p));
    ASSERT_EQ(gpu.backend().name(), "cuda");
    std::vector<SessionCut> cuts;
    for (Session* s : {&cpu, &gpu}) {
      pull_right_top(*s);
      for (int k = 0; k < 30; ++k) s->tick();
      cuts.push_back(s->cut(through_x(0.012)));
    }
    EXPECT_EQ(cuts[1].cut.n_nodes(), cuts[0].cut.n_nodes()) << (dbl ? "double" : "float");
    EXPECT_EQ(cuts[1].cut.n_elements(), cuts[0].cut.n_elements());
    EXPECT_EQ(pieces(gpu.model()), 2);
    const double right_after = relative_gap(cpu.backend().download().u, gpu.backend().download().u);
    EXPECT_LT(right_after, dbl ? 1e-9 : 1e-3) << "the motion set on each backend";
    const std::vector<double> v_cpu = cpu.backend().previous_displacements(),
                              v_gpu = gpu.backend().previous_displacements();
    EXPECT_LT(relative_gap(v_cpu, v_gpu), dbl ? 1e-9 : 1e-3) << "u_prev set on each backend";
    for (int k = 0; k < 100; ++k) cpu.tick(), gpu.tick();
    const double after = relative_gap(cpu.backend().download().u, gpu.backend().download().u);
    RecordProperty(dbl ? "double_u_gap_100_ticks_after" : "float_u_gap_100_ticks_after", g(after));
    EXPECT_LT(after, dbl ? 1e-9 : 1e-3) << (dbl ? "double" : "float");
  }
}

// A prepared cut on cuda (double): its backend, made and uploaded on
// another thread, ticks on bit for bit as the cut made then.
TEST(LiveCutCuda, ACutTakingEffectLaterIsTheCutMadeThen) {
  SKIP_UNLESS_USABLE("cuda");
  Session later(on(block_scene(), "cuda", Precision::Double)), now(on(block_scene(), "cuda", Precision::Double));
  ASSERT_EQ(later.backend().name(), "cuda");
  expect_a_later_cut_to_be_the_cut_made_then(later, now);
}

// A prepared cut of the pressed kidney on cuda (double, depth 5, as the
// consistency suite compares the kidney: under depth auto a ring can be
// added a tick apart on the two backends): the new backend's tick graphs are
// the old backend's, updated in place (cudaGraphExecUpdate) rather than
// instantiated, and they step as the cpu does, 60 ticks on, within the
// kidney's cross-backend tolerance (1e-5 m, tests/api/test_api.cpp
// Facade.CudaRunsTheKidneyAsTheCpuDoes).
TEST(LiveCutCuda, APreparedCutOfTheKidneyUpdatesItsTickGraphsAndStepsAsTheCpu) {
  SKIP_UNLESS_USABLE("cuda");
  scene::Scene kidney = io::default_kidney_scene();
  kidney.solver.depth = 5;
  Session cpu(on(kidney, "cpu", Precision::Double)), gpu(on(kidney, "cuda", Precision::Double));
  ASSERT_EQ(gpu.backend().name(), "cuda");
  const CutSurface across{{-0.025, -0.06, -0.04}, {0, 0.12, 0}, {0, 0, 0.08}};
  long updates_after_commit = -1;
  for (Session* s : {&cpu, &gpu}) {
    for (int k = 0; k < 150; ++k) s->tick();
    s->begin_cut(across, {}, CutSpace::Reference, 160);
    while (s->cuts() == 0 && s->scheduler().ticks() < 170) s->tick();
    ASSERT_EQ(s->cuts(), 1);
    // the new backend's first ticks, before it has dropped a graph of its own (no region built again): what it
    // updates it took over from the old one
    const long rebuilds = s->scheduler().region_rebuilds(), updates = s->backend().graph_updates();
    for (int k = 0; k < 8; ++k) s->tick();
    if (s == &gpu) {
      EXPECT_EQ(s->scheduler().region_rebuilds(), rebuilds);
      updates_after_commit = s->backend().graph_updates() - updates;
    }
    while (s->scheduler().ticks() < 220) s->tick();
    EXPECT_FALSE(s->failed());
  }
  RecordProperty("graph_updates_8_ticks_after_commit", g(double(updates_after_commit)));
  EXPECT_GT(updates_after_commit, 0) << "the old backend's graphs, taken over and updated";
  const std::vector<double> uc = cpu.backend().download().u, ug = gpu.backend().download().u;
  ASSERT_EQ(uc.size(), ug.size());
  double most = 0;
  for (std::size_t k = 0; k < uc.size(); ++k) most = std::max(most, std::fabs(uc[k] - ug[k]));
  RecordProperty("u_gap_m_60_ticks_after", g(most));
  EXPECT_LT(most, 1e-5);
}

// The blade on cuda: the same stroke through the block (double) makes the
// cpu's cuts, at the cpu's force, into the cpu's two pieces.
TEST(LiveCutCuda, TheBladeCutsAsOnTheCpu) {
  SKIP_UNLESS_USABLE("cuda");
  const Stroke cpu = stroke(blade_scene(true, 5), 1000);
  const Stroke gpu = stroke(on(blade_scene(true, 5), "cuda", Precision::Double), 1000);
  RecordProperty("first_cut_force_cuda", g(gpu.first_cut_force));
  EXPECT_EQ(gpu.cuts, cpu.cuts);
  EXPECT_EQ(gpu.pieces, 2);
  EXPECT_NEAR(gpu.first_cut_force, cpu.first_cut_force, 1e-6 * cpu.first_cut_force);
  EXPECT_NEAR(gpu.most, cpu.most, 1e-6 * cpu.most);
}

// The kidney cut across while its probe presses, on cuda in the scene's
// float: no element inverts over 200 ticks after, the step holds, the probe
// still presses.
TEST(LiveCutCuda, ACutAcrossTheKidneyWhileItsProbePresses) {
  SKIP_UNLESS_USABLE("cuda");
  Session s(on(io::default_kidney_scene(), "cuda", Precision::Float));
  for (int k = 0; k < 150; ++k) s.tick();
  ASSERT_GT(s.last().tools[0].contact_nodes, 0);
  const double force = norm(s.last().tools[0].force);
  const SessionCut c = s.cut({{-0.025, -0.06, -0.04}, {0, 0.12, 0}, {0, 0, 0.08}});
  RecordProperty("elements_made", g(double(c.cut.n_elements() - c.elements_before)));
  EXPECT_GE(c.dt_crit_after, 0.5 * c.dt_crit_before);
  for (int k = 0; k < 200; ++k) s.tick();
  EXPECT_FALSE(s.failed());
  EXPECT_GT(norm(s.last().tools[0].force), 0.5 * force);
}

// A blade is refused in a batch (its cuts would change a mesh the batch's
// scenes share), naming the scene and the tool.
// ---- the lips of a cut touch each other ------------------------------------

/// An incision at x = 11 mm from the top of the block down to z = 4 mm, across its width.
CutSurface incision() { return {{0.011, -0.01, 0.004}, {0, 0.04, 0}, {0, 0, 0.01}}; }

/// The pairs of nodes at one reference position (a cut's two lips), each (left, right) of the plane x = x0.
std::vector<std::array<index_t, 2>> twins(const TissueModel<double>& m, double x0);

/// Whether node a lies on the left of x0: the mean of its elements' centroids (reference) does.
bool left_of(const TissueModel<double>& m, index_t a, double x0) {
  const std::size_t ne = std::size_t(m.n_elems);
  double sum = 0;
  int count = 0;
  for (index_t k = m.node_elem_start[a]; k < m.node_elem_start[a + 1]; ++k) {
    const std::size_t e = std::size_t(m.node_elem[k] / 4);
    for (int c = 0; c < 4; ++c) sum += 0.25 * m.X[std::size_t(m.elem_nodes[std::size_t(c) * ne + e])];
    ++count;
  }
  return sum / count < x0;
}

std::vector<std::array<index_t, 2>> twins(const TissueModel<double>& m, double x0) {
  std::map<std::array<double, 3>, std::vector<index_t>> at_place;
  for (index_t a = 0; a < m.n_nodes; ++a) {
    const V X = ref(m, a);
    at_place[{X.x, X.y, X.z}].push_back(a);
  }
  std::vector<std::array<index_t, 2>> out;
  for (const auto& [place, nodes] : at_place) {
    if (nodes.size() != 2) continue;
    const bool first_left = left_of(m, nodes[0], x0);
    out.push_back(first_left ? std::array<index_t, 2>{nodes[0], nodes[1]} : std::array<index_t, 2>{nodes[1], nodes[0]});
  }
  return out;
}

// The lists of the lips' contact (core/body_contact.hpp): none before a cut;
// after it, every lip node a row whose candidates are the other lip's faces
// and the surface faces at its rim (never its own side's, nor one it is a
// corner of); a node of both lips (the incision's front) and the other
// corners of the rim's faces rows without candidates.
TEST(LipContact, EachLipsNodesHaveTheOtherLipsFacesAsCandidates) {
  Session s(block_scene());
  BodyContactSpec spec;
  spec.lips = true;
  const auto lists = [&] {
    const TissueModel<double>& m = s.model();
    std::vector<double> x(3 * std::size_t(m.n_nodes));
    for (index_t a = 0; a < m.n_nodes; ++a)
      for (int c = 0; c < 3; ++c) x[3 * size_t(a) + c] = m.X[std::size_t(c) * m.n_nodes + a];
    return build_body_lists(m, spec, x);
  };
  EXPECT_EQ(lists().rows(), 0) << "an uncut block has no lips";
  s.cut(incision());
  const TissueModel<double>& m = s.model();
  const BodyLists L = lists();
  const index_t nt = m.n_tris;
  std::vector<std::uint8_t> twinned(std::size_t(m.n_nodes), 0);
  for (const auto& [l, r] : twins(m, 0.011)) twinned[std::size_t(l)] = twinned[std::size_t(r)] = 1;
  int copies = 0, others = 0;
  for (index_t r = 0; r < L.rows(); ++r) {
    const index_t a = L.node[r];
    const index_t count = L.cand_start[r + 1] - L.cand_start[r];
    if (!twinned[std::size_t(a)]) {
      EXPECT_EQ(count, 0) << "node " << a << " lies on both lips (the front) or off them";
      ++others;
      continue;
    }
    EXPECT_NEAR(m.X[a], 0.011, 0.0025) << "a lip node lies within half an edge of the cut's plane: node " << a;
    ++copies;
    EXPECT_GT(count, 0) << "lip node " << a;
    const bool left = left_of(m, a, 0.011);
    for (index_t j = L.cand_start[r]; j < L.cand_start[r + 1]; ++j) {
      const index_t t = L.cand_tri[j];
      const V x0 = ref(m, m.tris[t]);
      const V N = cross(ref(m, m.tris[nt + t]) - x0, ref(m, m.tris[2 * nt + t]) - x0);
      EXPECT_LT(left ? N.x : -N.x, 0.1 * norm(N)) << "node " << a << ": triangle " << t << " is not of its lip";
      bool other = false;
      for (int k = 0; k < 3; ++k) {
        const index_t b = m.tris[k * nt + t];
        EXPECT_NE(b, a);
        EXPECT_TRUE(!twinned[std::size_t(b)] || left_of(m, b, 0.011) != left)
            << "node " << a << ": triangle " << t << " has a corner on its own lip";
        other = other || (twinned[std::size_t(b)] && left_of(m, b, 0.011) != left);
      }
      EXPECT_TRUE(other) << "node " << a << ": triangle " << t << " touches the other lip";
      EXPECT_EQ(L.cand_mu[j], 0.0);
    }
  }
  EXPECT_GT(copies, 0);
  EXPECT_GT(others, 0);
  RecordProperty("lip_rows", L.rows());
  RecordProperty("rows_without_candidates", others);
}

/// How far the incision's lips cross after a push of both ends towards them: the most a left lip node lies
/// right of its twin on the right lip (m; <= 0: none crossed), over the lips' inside and over their rim (the
/// nodes on the block's surface too).
struct Crossing {
  double inside = -1, rim = -1;
};

Crossing lip_crossing(bool lip_contact) {
  scene::Scene sc = block_scene(8);  // 2.5 mm cells: lip nodes inside the lips, not only on their rim
  sc.solver.lip_contact = lip_contact;
  Session s(sc);
  s.cut(incision());
  const TissueModel<double>& m = s.model();
  // both end faces pushed inwards, 0.5 mN a node: the block compressed across the incision
  std::vector<index_t> ends;
  std::vector<double> force;
  for (index_t i = 0; i < m.n_nodes; ++i) {
    const double x = ref(m, i).x;
    if (x < 1e-9 || x > 0.02 - 1e-9) {
      ends.push_back(i);
      force.insert(force.end(), {x < 0.01 ? 5e-4 : -5e-4, 0.0, 0.0});
    }
  }
  s.set_loads(ends, force);
  for (int k = 0; k < 400; ++k) s.tick();
  EXPECT_FALSE(s.failed()) << s.failure();
  const std::vector<double> u = s.backend().download().u;
  Crossing out;
  int inside = 0;
  for (const auto& [l, r] : twins(m, 0.011)) {
    const V X = ref(m, l);
    const double by = u[std::size_t(l)] - u[std::size_t(r)];
    out.rim = std::max(out.rim, by);
    if (X.z < 0.01 - 1e-9 && X.y > 1e-9 && X.y < 0.02 - 1e-9) {
      out.inside = std::max(out.inside, by);
      ++inside;
    }
  }
  EXPECT_GT(inside, 4);
  return out;
}

// An incision pressed shut: without the lips' contact the two lips pass
// through each other; with it (the default) they meet and stay apart,
// but for their rim, where a node of one lip may ride over the other's
// edge onto the block's surface (docs/cutting.md).
TEST(LipContact, TheLipsOfAnIncisionPressedShutDoNotCross) {
  const Crossing free_lips = lip_crossing(false), touching = lip_crossing(true);
  RecordProperty("inside_crossing_without_m", g(free_lips.inside));
  RecordProperty("inside_crossing_with_m", g(touching.inside));
  RecordProperty("rim_crossing_without_m", g(free_lips.rim));
  RecordProperty("rim_crossing_with_m", g(touching.rim));
  EXPECT_GT(free_lips.inside, 1e-4) << "the check can fail: free lips cross";
  EXPECT_LT(touching.inside, 1e-3 * free_lips.inside);
  EXPECT_LT(touching.rim, 0.6 * free_lips.rim);
}

// The blade pressed 3 mm into the kidney with its button up, then drawn
// across with it down: where the tissue gives (5 N/m), the stroke's crack,
// mapped back to the body at rest, lies in the surface material the blade
// carried down, and crosses no element. The blade does not cut there, and
// the notes say so, once for the stroke (docs/cutting.md, "What it does
// not do").
TEST(Blade, ACutUnderADimpleThatMeetsNoElementIsNoted) {
  scene::Scene sc = io::default_kidney_scene();
  scene::Tool blade;
  blade.kind = scene::Tool::Kind::Blade;
  blade.name = "scalpel";
  blade.radius = 5e-4;
  blade.shaft = 0.02;
  blade.cut_resistance = 5;
  blade.direction = {-0.0553, 0.9953, 0.0796};
  blade.path = {{0, {0, 0.035, 0}, false}, {0.2, {0, 0.0276, 0}, true}, {0.9, {0.021, 0.0276, 0}, true}};
  sc.tools = {blade};
  Session s(sc);
  std::vector<std::string> said;
  for (int k = 0; k < 320; ++k) {
    s.tick();
    for (std::string& n : s.scheduler().take_notes())
      if (n.find("blade 'scalpel'") != std::string::npos) said.push_back(std::move(n));
  }
  EXPECT_EQ(s.cuts(), 0);
  ASSERT_EQ(said.size(), 1u) << "once for the stroke";
  EXPECT_NE(said[0].find("the tissue gave, but the cut it makes meets no element"), std::string::npos) << said[0];
  EXPECT_NE(said[0].find("crosses no element of the mesh"), std::string::npos) << "the cut's own refusal, with its surface";
}

TEST(Blade, ABatchRefusesABlade) {
  const auto shared = std::make_shared<const scene::Scene>(blade_scene(true, 5));
  try {
    SceneBatch batch({shared}, "cpu", Precision::Double);
    ADD_FAILURE() << "a blade ran in a batch";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("tool 'scalpel' is a blade"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace tissue
