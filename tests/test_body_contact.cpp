// Contact between bodies (core/body_contact.hpp; docs/contact.md, "Bodies
// touching each other") on every backend and precision: a soft block
// loaded on a stiffer one carries its load through the interface to the
// supports (balance to 1e-6 of the load in double), nothing sinks in beyond
// the stated tolerance, a block let go onto another does not bounce off
// with energy the contact made, a tool pushing one block into another
// deforms both without inverting anything, friction holds a sheared pair
// together below mu and lets it slide above (passing mu times the press to
// the supports), and the cuda backend runs the same contact as the cpu.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "backends/registry.hpp"
#include "core/body_contact.hpp"
#include "core/box_mesh.hpp"
#include "core/device.hpp"
#include "core/scheduler.hpp"
#include "tests/backend_test_support.hpp"

namespace tissue {
namespace {

using namespace tissue::test;

/// Two blocks, the second on top of the first: the lower kL x kL x kL/2
/// (n x n x n/2 cells, E_lower, its bottom fixed), the upper 0.6 kL square
/// and kL/2 high (m x m x m/2 cells, E_upper, free) centred on it, its
/// bottom face `gap` above the lower's top (0: touching; < 0: sunk in).
struct Stack {
  TissueModel<double> model;
  index_t first_upper = 0;  ///< the upper block's first node
  std::vector<index_t> upper_top;  ///< its top face's nodes
  BodyContactSpec spec(double friction = 0) const {
    BodyContactSpec s;
    s.first_node = {0, first_upper, model.n_nodes};
    s.pairs = {{0, 1, friction}};
    return s;
  }
};

Stack stack(int n, int m, double E_lower, double E_upper, double gap, std::optional<double> damping = {}) {
  ModelInput lower, upper;
  box_mesh(lower, n, n, n / 2, kL, kL, kL / 2);
  box_mesh(upper, m, m, m / 2, 0.6 * kL, 0.6 * kL, kL / 2);
  ModelInput in = lower;
  const index_t first = index_t(lower.nodes.size() / 3);
  for (std::size_t i = 0; i < upper.nodes.size(); i += 3) {
    in.nodes.push_back(upper.nodes[i] + 0.2 * kL);
    in.nodes.push_back(upper.nodes[i + 1] + 0.2 * kL);
    in.nodes.push_back(upper.nodes[i + 2] + kL / 2 + gap);
  }
  for (index_t v : upper.tets) in.tets.push_back(v + first);
  const double nu = 0.45;
  const auto law = [&](double E) { return MaterialParams{E / (2 * (1 + nu)), E / (3 * (1 - 2 * nu)), 1000}; };
  in.materials = {law(E_lower), law(E_upper)};
  in.elem_material.assign(lower.tets.size() / 4, 0);
  in.elem_material.resize(in.tets.size() / 4, 1);
  in.fixed.assign(in.nodes.size() / 3, 0);
  for (index_t a = 0; a < first; ++a) in.fixed[a] = in.nodes[3 * size_t(a) + 2] == 0.0;
  in.damping = damping;
  in.source = "stack";
  Stack s;
  s.model = build_model(in);
  s.first_upper = first;
  const double top = kL + gap;
  for (index_t a = first; a < s.model.n_nodes; ++a)
    if (std::fabs(s.model.X[2 * s.model.n_nodes + a] - top) < 1e-12) s.upper_top.push_back(a);
  return s;
}

/// The load as Backend::set_loads takes it: the loaded nodes and their forces (xyz).
void load(Backend& b, const std::vector<index_t>& nodes, double total) {
  std::vector<double> f;
  for (std::size_t k = 0; k < nodes.size(); ++k) f.insert(f.end(), {0.0, 0.0, -total / double(nodes.size())});
  b.set_loads(nodes, f);
}

/// Sum of the internal forces on the fixed nodes: the supports' reaction.
Vec3<double> support(const TissueModel<double>& m, const Fields& f) {
  Vec3<double> s{0, 0, 0};
  for (index_t a = 0; a < m.n_nodes; ++a)
    if (m.node_flags[a] & kFixed) s = s + node_u(f.f, m.n_nodes, a);
  return s;
}

/// Deformed position of node a.
Vec3<double> at(const TissueModel<double>& m, const Fields& f, index_t a) {
  const index_t n = m.n_nodes;
  return {m.X[a] + f.u[a], m.X[n + a] + f.u[n + a], m.X[2 * n + a] + f.u[2 * n + a]};
}

/// How far a node of one block lies inside the other across the interface
/// (m; <= 0: none), measured apart from the contact's own search: each
/// upper node over a lower top triangle (by its vertical projection, the
/// deformed triangle's normal pointing up) is compared with that
/// triangle's height there, and each lower node under an upper bottom
/// triangle (normal down) with its height.
double sunk(const Stack& s, const Fields& f) {
  const TissueModel<double>& m = s.model;
  const index_t nt = m.n_tris;
  double worst = -1;
  for (index_t t = 0; t < nt; ++t) {
    const Vec3<double> P0 = at(m, f, m.tris[t]), P1 = at(m, f, m.tris[nt + t]), P2 = at(m, f, m.tris[2 * nt + t]);
    const Vec3<double> N = cross(P1 - P0, P2 - P0);
    const bool lower = m.tris[t] < s.first_upper;
    // a lower block's top face (normal up) or an upper block's bottom face (normal down)
    if (!(lower ? N.z > 0.9 * norm(N) : N.z < -0.9 * norm(N))) continue;
    const index_t first = lower ? s.first_upper : 0, last = lower ? m.n_nodes : s.first_upper;
    for (index_t a = first; a < last; ++a) {
      const Vec3<double> p = at(m, f, a);
      // barycentric weights of p's (x, y) in the triangle's projection
      const double d = (P1.y - P2.y) * (P0.x - P2.x) + (P2.x - P1.x) * (P0.y - P2.y);
      const double w0 = ((P1.y - P2.y) * (p.x - P2.x) + (P2.x - P1.x) * (p.y - P2.y)) / d;
      const double w1 = ((P2.y - P0.y) * (p.x - P2.x) + (P0.x - P2.x) * (p.y - P2.y)) / d;
      const double w2 = 1 - w0 - w1;
      if (w0 < 0 || w1 < 0 || w2 < 0) continue;
      const double z = w0 * P0.z + w1 * P1.z + w2 * P2.z;
      if (std::fabs(p.z - z) > 0.25 * kL) continue;  // a node of the far face
      worst = std::max(worst, lower ? z - p.z : p.z - z);
    }
  }
  return worst;
}

class BodyContact : public ::testing::TestWithParam<BackendKind> {
 protected:
  void SetUp() override { SKIP_UNLESS_USABLE(GetParam().backend); }
  bool is_float() const { return GetParam().precision == Precision::Float; }
  std::unique_ptr<Backend> make(const TissueModel<double>& m) const {
    auto b = create_backend(GetParam().backend, GetParam().precision);
    b->upload(m);
    return b;
  }
};

INSTANTIATE_TEST_SUITE_P(Backends, BodyContact, ::testing::ValuesIn(all_backend_kinds()), backend_kind_name);

TEST_P(BodyContact, ALoadedStackCarriesItsLoadThroughTheInterfaceToTheSupports) {
  const Stack s = stack(6, 5, 3e4, 3e3, 0);
  auto b = make(s.model);
  b->set_body_contact(s.spec());
  const double F = 0.02;  // N: ~0.05 strain in the upper block
  load(*b, s.upper_top, F);
  const int steps = int(std::lround(1e-3 / s.model.dt));
  Reductions r;
  for (double t = 0; t < 4.0; t += steps * s.model.dt) {
    b->advance(steps);
    r = b->reduce();
    ASSERT_TRUE(r.finite);
    ASSERT_EQ(r.bad_elem, -1);
  }
  const Fields f = b->download();
  const Vec3<double> react = support(s.model, f);
  // the load pushes down on the upper block; the supports hold the stack up with all of it
  // to 1e-6 of it in double (measured after 4 s on the cpu: 1.5e-8 in double, 2.0e-5 in float)
  const double balance = is_float() ? 5e-4 : 1e-6;
  EXPECT_NEAR(react.z, F, balance * F) << "support reaction " << react.z << " N for a load of " << F;
  // sideways, where nothing holds the upper block but the faceted frictionless interface, it creeps
  // against the damping (measured 5.0e-5 of the load in double)
  EXPECT_LT(std::hypot(react.x, react.y), (is_float() ? 5e-4 : 1e-4) * F);
  // the interface holds: nothing has sunk in beyond the tolerance (measured: 9.4e-4 of an
  // upper edge, at the corner of the upper block's bottom, where the stress is singular)
  const double edge = 0.6 * kL / 5;
  RecordProperty("support_imbalance_of_load", fmt::format("{:.3g}", std::fabs(react.z - F) / F));
  RecordProperty("sunk_of_edge", fmt::format("{:.3g}", sunk(s, f) / edge));
  EXPECT_LT(sunk(s, f), 1e-2 * edge) << "sunk " << sunk(s, f) << " m";
  // and it is loaded: the upper block's bottom moved down with the lower's top, which carries the load
  EXPECT_GT(-f.u[2 * s.model.n_nodes + s.upper_top.front()], 0.0);
  EXPECT_FALSE(b->body_contacts().empty());
}

TEST_P(BodyContact, WithoutContactTheUpperBlockSinksThrough) {  // the check above can fail
  const Stack s = stack(6, 5, 3e4, 3e3, 0);
  auto b = make(s.model);
  load(*b, s.upper_top, 0.02);
  const int steps = int(std::lround(1e-3 / s.model.dt));
  for (int k = 0; k < 100; ++k) b->advance(steps);
  EXPECT_GT(sunk(s, b->download()), 1e-3 * 0.6 * kL / 5);
  EXPECT_TRUE(b->body_contacts().empty());
}

TEST_P(BodyContact, ABlockLoadedOntoAnotherGainsNoEnergy) {
  // undamped, from rest: the upper block is pushed onto the lower by a constant load. Its
  // energy -- kinetic plus strain less the load's work, 0 at the start -- may only fall in
  // contact (an inelastic one) and stays within the central difference's own wobble of 0
  // otherwise; a contact that overshot would push the block off with energy it made. So
  // too pulled sideways by a tenth of the load, sticking (mu 0.5) and sliding (mu 0.05)
  for (const auto& [mu, shear] : {std::pair{0.0, 0.0}, std::pair{0.5, 0.1}, std::pair{0.05, 0.1}}) {
    SCOPED_TRACE(fmt::format("mu {} pulled sideways by {} of the load", mu, shear));
    const Stack s = stack(6, 5, 3e4, 3e3, 0, 0.0);
    auto b = make(s.model);
    b->set_body_contact(s.spec(mu));
    const double F = 0.02;
    const double fx = shear * F / double(s.upper_top.size()), fz = -F / double(s.upper_top.size());
    std::vector<double> f;
    for (std::size_t k = 0; k < s.upper_top.size(); ++k) f.insert(f.end(), {fx, 0.0, fz});
    b->set_loads(s.upper_top, f);
    const int steps = int(std::lround(1e-3 / s.model.dt));
    const index_t n = s.model.n_nodes;
    double most = 0, most_kinetic = 0;
    for (int k = 0; k < 200; ++k) {
      b->advance(steps);
      const Reductions r = b->reduce();
      ASSERT_TRUE(r.finite);
      ASSERT_EQ(r.bad_elem, -1);
      if (r.strain_energy < 0) GTEST_SKIP() << "this backend does not compute the strain energy";
      const Fields u = b->download();
      double work = 0;
      for (index_t a : s.upper_top) work += fx * u.u[a] + fz * u.u[2 * n + a];
      most = std::max(most, r.kinetic + r.strain_energy - work);
      most_kinetic = std::max(most_kinetic, r.kinetic);
      if (k == 199) {
        EXPECT_LT(sunk(s, u), 1e-2 * 0.6 * kL / 5) << "sunk " << sunk(s, u) << " m";
      }
    }
    ASSERT_GT(most_kinetic, 0.0);
    EXPECT_LT(most, 0.02 * most_kinetic) << "energy rose to " << most << " J (most kinetic " << most_kinetic << " J)";
  }
}

/// The upper block of a stack pressed down by F and pulled sideways by
/// `shear` F (its top face loaded), with friction mu: how far its bottom has
/// slid over the lower block's top (mean x displacements over the interface)
/// at each of `at` (s), and the supports' sideways and vertical reactions at
/// the last.
struct Sheared {
  std::vector<double> slip;  ///< m, one per time asked
  Vec3<double> react;        ///< N: the supports' reaction at the last time
};

template <class Make>
Sheared shear_pair(Make make, double mu, double shear, const std::vector<double>& at) {
  const Stack s = stack(6, 5, 3e4, 3e3, 0);
  auto b = make(s.model);
  b->set_body_contact(s.spec(mu));
  const double F = 0.02;
  std::vector<double> f;
  for (std::size_t k = 0; k < s.upper_top.size(); ++k)
    f.insert(f.end(), {shear * F / double(s.upper_top.size()), 0.0, -F / double(s.upper_top.size())});
  b->set_loads(s.upper_top, f);
  const int steps = int(std::lround(1e-3 / s.model.dt));
  Sheared out;
  int ticks = 0;
  for (double t : at) {
    for (; ticks < int(std::lround(t / 1e-3)); ++ticks) b->advance(steps);
    const Fields u = b->download();
    const index_t n = s.model.n_nodes;
    double upper = 0, lower = 0;
    int nu = 0, nl = 0;
    for (index_t a = 0; a < n; ++a) {
      const double x = s.model.X[a], y = s.model.X[n + a], z = s.model.X[2 * n + a];
      if (std::fabs(z - kL / 2) > 1e-12 || x < 0.2 * kL || x > 0.8 * kL || y < 0.2 * kL || y > 0.8 * kL) continue;
      (a >= s.first_upper ? upper : lower) += u.u[a];
      ++(a >= s.first_upper ? nu : nl);
    }
    out.slip.push_back(upper / nu - lower / nl);
    out.react = support(s.model, u);
  }
  return out;
}

TEST_P(BodyContact, FrictionHoldsAShearedPairBelowMuAndLetsItSlideAbove) {
  // pulled sideways by a tenth of the press: with mu 0.5 the pair sticks (its slip stops
  // once the blocks have sheared), with mu 0.05 it slides, the supports feeling mu times the
  // press sideways, and without friction it slides faster still. (Read by 0.3 s: near 0.6 mm
  // of slip the upper block's edge reaches a node of the lower's top outside the dent the
  // load makes, and catches on it, with or without friction.)
  const auto make_backend = [&](const TissueModel<double>& m) { return make(m); };
  const std::vector<double> at = {0.15, 0.3};
  const Sheared held = shear_pair(make_backend, 0.5, 0.1, at), slid = shear_pair(make_backend, 0.05, 0.1, at),
                free = shear_pair(make_backend, 0.0, 0.1, at);
  RecordProperty("slip_mm_held", fmt::format("{:.6g} {:.6g}", 1e3 * held.slip[0], 1e3 * held.slip[1]));
  RecordProperty("slip_mm_mu_0_05", fmt::format("{:.4g} {:.4g}", 1e3 * slid.slip[0], 1e3 * slid.slip[1]));
  RecordProperty("slip_mm_frictionless", fmt::format("{:.4g} {:.4g}", 1e3 * free.slip[0], 1e3 * free.slip[1]));
  const double ratio = -slid.react.x / slid.react.z;
  RecordProperty("sliding_support_ratio", fmt::format("{:.4g}", ratio));
  // stick: measured on the cpu 3.61 um of shear at 0.15 s, 1.1e-8 m more by 0.3 s (double),
  // against 236 um more with mu 0.05
  const double slid_more = slid.slip[1] - slid.slip[0];
  ASSERT_GT(slid_more, 1e-4) << "mu 0.05 under a pull of 0.1: slip " << slid.slip[0] << " then " << slid.slip[1];
  EXPECT_LT(std::fabs(held.slip[1] - held.slip[0]), 1e-3 * slid_more)
      << "mu 0.5 under a pull of 0.1: slip " << held.slip[0] << " then " << held.slip[1] << " m";
  EXPECT_LT(std::fabs(held.slip[1]), 0.02 * slid.slip[1]);
  // slide: the interface passes mu times the press to the supports (measured 0.0496)
  EXPECT_NEAR(ratio, 0.05, 0.05 * 0.05) << "sliding with mu 0.05, the supports' sideways reaction over the vertical";
  // and held, the supports take the whole pull
  EXPECT_NEAR(-held.react.x / held.react.z, 0.1, 1e-2 * 0.1);
  EXPECT_GT(free.slip[0], 1.5 * slid.slip[0]) << "frictionless " << free.slip[0] << " m, mu 0.05 " << slid.slip[0];
}

TEST_P(BodyContact, AToolPushingOneBlockIntoAnotherDeformsBothAndInvertsNothing) {
  const Stack s = stack(6, 5, 3e3, 3e3, 0);
  auto b = make(s.model);
  SchedulerSettings st;
  st.depth = kDepthAll;
  st.body_contact = s.spec();
  st.tools = {ToolSetting{{"probe", 0.003, 0, 0}, {0, 0, 1}}};
  Scheduler sched(*b, s.model, st);
  // a sphere pressed down 3 mm into the middle of the upper block's top, then held
  ScriptedDevice dev(press_path({0.5 * kL, 0.5 * kL, kL + 0.003}, {0, 0, -1}, 0.003, 0.003, 0.05, 0.1, 0.5, 0.05));
  TickReport rep;
  while (sched.time() < 0.6) {
    rep = sched.tick(dev);
    ASSERT_TRUE(std::isfinite(rep.force.z));
  }
  const Fields f = b->download();
  double lower_most = 0;
  for (index_t a = 0; a < s.first_upper; ++a) lower_most = std::max(lower_most, std::fabs(f.u[2 * s.model.n_nodes + a]));
  EXPECT_GT(rep.force.z, 0.0);
  EXPECT_GT(lower_most, 1e-4) << "the lower block did not deform";
  for (double J : f.elem_J) EXPECT_GT(J, 0.0);
  // a 3 mm press through a 10 mm block: the interface under it takes a much higher pressure
  // (measured: 1.7e-2 of an upper edge sunk in at the press's end)
  RecordProperty("sunk_of_edge", fmt::format("{:.3g}", sunk(s, f) / (0.6 * kL / 5)));
  EXPECT_LT(sunk(s, f), 0.1 * 0.6 * kL / 5) << "sunk " << sunk(s, f) << " m";
}

TEST_P(BodyContact, BadSpecsAreNamed) {
  const Stack s = stack(4, 3, 3e4, 3e3, 0);
  auto b = make(s.model);
  BodyContactSpec bad = s.spec();
  bad.pairs = {{0, 0, 0}};
  EXPECT_THROW(b->set_body_contact(bad), std::invalid_argument);
  bad = s.spec(-1);
  EXPECT_THROW(b->set_body_contact(bad), std::invalid_argument);
  bad = s.spec();
  bad.first_node = {0, s.model.n_nodes};
  EXPECT_THROW(b->set_body_contact(bad), std::invalid_argument);
  bad = s.spec();
  bad.pairs.push_back({1, 0, 0});
  try {
    b->set_body_contact(bad);
    ADD_FAILURE() << "a pair given twice was taken";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("the same bodies as pair 0"), std::string::npos) << e.what();
  }
}

TEST(BodyContactRule, CountsWeighCornersByTheirWeightAndAHitScalesByItsMostSharedNode) {
  // three hits: row 0 on candidate 0 (corners rows 3, 4, 5), row 1 on candidate 1 (corners 4, 3, 5),
  // row 2 on candidate 2 (corners 4, 5, 3); rows 3-5 hit nothing themselves
  std::vector<BodyHit<double>> hits(6);
  hits[0] = {0, 0.0, {1, 0, 0}, {0.5, 0.1, 0.4}};
  hits[1] = {1, 0.0, {0, 2, 0}, {0.3, 0.3, 0.4}};
  hits[2] = {2, 0.0, {0, 0, 3}, {0.0, 0.8, 0.2}};
  const std::vector<index_t> cand_rows = {3, 4, 5, 4, 3, 5, 4, 5, 3};
  // each row's corner entries (candidate, its row, the corner), ascending by row as the lists give them
  const std::vector<index_t> start = {0, 0, 0, 0, 3, 6, 9};
  const std::vector<index_t> corner_cand = {0, 1, 2, 0, 1, 2, 0, 1, 2};
  const std::vector<index_t> corner_row = {0, 1, 2, 0, 1, 2, 0, 1, 2};
  const std::vector<std::uint8_t> corner_slot = {0, 1, 2, 1, 0, 0, 2, 2, 1};
  const auto hit = [&](index_t r) -> const BodyHit<double>& { return hits[r]; };
  std::vector<double> counts(6);
  for (index_t r = 0; r < 6; ++r)
    counts[r] = body_row_count<double>(r, start[r], start[r + 1], corner_cand.data(), corner_row.data(),
                                       corner_slot.data(), hit);
  EXPECT_DOUBLE_EQ(counts[0], 1.0);              // its own hit only
  EXPECT_DOUBLE_EQ(counts[3], 0.5 + 0.3 + 0.2);  // a corner of all three, by its weight in each
  EXPECT_DOUBLE_EQ(counts[4], 0.1 + 0.3 + 0.0);  // weight 0 in the third counts for nothing
  EXPECT_DOUBLE_EQ(counts[5], 0.4 + 0.4 + 0.8);
  // a corner of weight >= 1/4 weighs in with its whole count, below it blended towards 1 (1 + 4 w (count - 1))
  BodyHit<double> h = hits[0];
  body_scale_hit(h, 0, cand_rows.data(), counts.data());
  const double most = std::max({1.0, counts[3], 1 + 4 * 0.1 * (counts[4] - 1), counts[5]});
  EXPECT_DOUBLE_EQ(h.c[0], 1.0 / most);
  // a corner shared by many contacts weighs in as far as the hit leans on it: as its weight falls to 0
  // the scale goes continuously to what the other nodes give, and a corner of weight 0 is left out
  counts[3] = 100;
  h = hits[2];
  body_scale_hit(h, 2, cand_rows.data(), counts.data());
  EXPECT_DOUBLE_EQ(h.c[2], 3.0 / (1 + 4 * 0.2 * (counts[3] - 1)));
  hits[2].w[2] = 1e-9;
  h = hits[2];
  body_scale_hit(h, 2, cand_rows.data(), counts.data());
  EXPECT_NEAR(h.c[2], 3.0 / counts[5], 1e-6);
  hits[2].w[2] = 0;
  h = hits[2];
  body_scale_hit(h, 2, cand_rows.data(), counts.data());
  EXPECT_DOUBLE_EQ(h.c[2], 3.0 / counts[5]);
}

TEST(BodyContactLists, AFaceOnASymmetryPlaneIsNoCandidateButASupportIs) {
  // the lower block's top held in z, a roller at each node: a plane of symmetry, which the upper
  // block's bottom lying on it must not touch; held in full, it is a support and stays touchable
  Stack s = stack(4, 3, 3e4, 3e3, 0);
  const index_t n = s.model.n_nodes, nt = s.model.n_tris;
  std::vector<double> x(3 * std::size_t(n));
  for (index_t a = 0; a < n; ++a)
    for (int c = 0; c < 3; ++c) x[3 * size_t(a) + c] = s.model.X[c * n + a];
  const auto on_lower_top = [&](index_t a) { return a < s.first_upper && std::fabs(s.model.X[2 * n + a] - kL / 2) < 1e-12; };
  const auto top_candidates = [&](const BodyLists& L) {
    int count = 0;
    for (index_t t : L.cand_tri)
      count += on_lower_top(s.model.tris[t]) && on_lower_top(s.model.tris[nt + t]) && on_lower_top(s.model.tris[2 * nt + t]);
    return count;
  };
  EXPECT_GT(top_candidates(build_body_lists(s.model, s.spec(), x)), 0);
  for (index_t a = 0; a < n; ++a)
    if (on_lower_top(a)) s.model.node_flags[a] |= kFixedZ;
  EXPECT_EQ(top_candidates(build_body_lists(s.model, s.spec(), x)), 0);
  for (index_t a = 0; a < n; ++a)
    if (on_lower_top(a)) s.model.node_flags[a] |= kFixed;
  EXPECT_GT(top_candidates(build_body_lists(s.model, s.spec(), x)), 0);
  // a model without its node flags is refused, naming them
  s.model.node_flags.clear();
  EXPECT_THROW(build_body_lists(s.model, s.spec(), x), std::invalid_argument);
}

TEST(BodyContactLists, EveryNodeNearTheOtherBodyHasItsTrianglesAndTheCornerListsInvertThem) {
  const Stack s = stack(4, 3, 3e4, 3e3, 0);
  const index_t n = s.model.n_nodes, nt = s.model.n_tris;
  std::vector<double> x(3 * std::size_t(n));
  for (index_t a = 0; a < n; ++a)
    for (int c = 0; c < 3; ++c) x[3 * size_t(a) + c] = s.model.X[c * n + a];
  const BodyLists L = build_body_lists(s.model, s.spec(0.3), x);
  ASSERT_EQ(L.rows(), s.model.n_surf);
  // brute force: every (surface node, other body's triangle) pair whose box comes within the skin
  for (index_t r = 0; r < L.rows(); ++r) {
    const index_t a = L.node[r];
    const bool upper = a >= s.first_upper;
    std::vector<index_t> want;
    for (index_t t = 0; t < nt; ++t) {
      if ((s.model.tris[t] >= s.first_upper) == upper) continue;
      bool in = true;
      for (int c = 0; c < 3 && in; ++c) {
        double lo = 1e9, hi = -1e9;
        for (int k = 0; k < 3; ++k) {
          lo = std::min(lo, x[3 * size_t(s.model.tris[k * nt + t]) + c]);
          hi = std::max(hi, x[3 * size_t(s.model.tris[k * nt + t]) + c]);
        }
        in = x[3 * size_t(a) + c] >= lo - L.skin && x[3 * size_t(a) + c] <= hi + L.skin;
      }
      if (in) want.push_back(t);
    }
    const std::vector<index_t> got(L.cand_tri.begin() + L.cand_start[r], L.cand_tri.begin() + L.cand_start[r + 1]);
    EXPECT_EQ(got, want) << "node " << a;
    for (index_t j = L.cand_start[r]; j < L.cand_start[r + 1]; ++j) EXPECT_EQ(L.cand_mu[j], 0.3);
  }
  // each corner entry names a candidate with the row's node at that corner, and every such pair is listed once
  std::size_t listed = 0;
  for (index_t r = 0; r < L.rows(); ++r)
    for (index_t e = L.corner_start[r]; e < L.corner_start[r + 1]; ++e) {
      const index_t j = L.corner_cand[e];
      EXPECT_EQ(s.model.tris[L.corner_slot[e] * nt + L.cand_tri[j]], L.node[r]);
      EXPECT_TRUE(j >= L.cand_start[L.corner_row[e]] && j < L.cand_start[L.corner_row[e] + 1]);
      ++listed;
    }
  EXPECT_EQ(listed, 3 * L.cand_tri.size());
  EXPECT_FALSE(body_lists_stale(L, [&](index_t a) { return Vec3<double>{x[3 * a], x[3 * a + 1], x[3 * a + 2]}; }));
  EXPECT_TRUE(body_lists_stale(L, [&](index_t a) {
    return Vec3<double>{x[3 * a] + 0.3 * L.skin, x[3 * a + 1], x[3 * a + 2]};
  }));
}

TEST(BodyContactRounding, ANudgeAtTheRoundingStaysAtTheRounding) {
  // the blocks start exactly touching: nodes lie on the other's faces to the rounding, and
  // under edges shared by coplanar faces; nudging every node by 1e-15 m (a rounding of
  // positions ~1e-2 m) must not flip which nodes are inside, nor which triangle they take
  const Stack s = stack(6, 5, 3e4, 3e3, 0);
  std::vector<Fields> out;
  for (int nudged = 0; nudged < 2; ++nudged) {
    auto b = create_backend("cpu", Precision::Double);
    b->upload(s.model);
    if (nudged) {
      std::vector<double> u(3 * std::size_t(s.model.n_nodes));
      for (std::size_t k = 0; k < u.size(); ++k) u[k] = 1e-15 * std::sin(1.0 + 7.3 * double(k));
      for (index_t a = 0; a < s.model.n_nodes; ++a)
        if (s.model.node_flags[a] & kFixed)
          for (int c = 0; c < 3; ++c) u[c * std::size_t(s.model.n_nodes) + a] = 0;
      b->set_displacements(u);
    }
    b->set_body_contact(s.spec(0.2));
    load(*b, s.upper_top, 0.02);
    const int steps = int(std::lround(1e-3 / s.model.dt));
    for (int k = 0; k < 200; ++k) b->advance(steps);
    out.push_back(b->download());
  }
  const double scale = max_abs(out[0].u), diff = max_diff(out[0].u, out[1].u);
  RecordProperty("nudged_diff_of_max_u", fmt::format("{:.3g}", diff / scale));
  // measured: 1.1e-12 of the largest u (7.6e-16 m); with ties decided by the bare comparisons,
  // 3.4e-7 (2.3e-10 m): the nudge had flipped nodes between inside and out and between faces
  ASSERT_GT(scale, 0.0);
  EXPECT_LT(diff, 1e-9 * scale) << "a nudge of 1e-15 m changed u by " << diff << " m";
}

TEST(BodyContactAcrossBackends, CudaRunsTheCpusContact) {
  SKIP_UNLESS_USABLE("cuda");
  const Stack s = stack(6, 5, 3e4, 3e3, 0);
  for (Precision p : {Precision::Double, Precision::Float}) {
    auto cpu = create_backend("cpu", p), cuda = create_backend("cuda", p);
    std::vector<Fields> out;
    std::vector<std::vector<BodyContactNode>> touching;
    for (Backend* b : {cpu.get(), cuda.get()}) {
      b->upload(s.model);
      b->set_body_contact(s.spec(0.2));
      load(*b, s.upper_top, 0.02);
      const int steps = int(std::lround(1e-3 / s.model.dt));
      for (int k = 0; k < 200; ++k) b->advance(steps);
      out.push_back(b->download());
      touching.push_back(b->body_contacts());
    }
    const double scale = max_abs(out[0].u);
    ASSERT_GT(scale, 0.0);
    // the blocks start exactly touching, so nodes lie on the other's surface to the rounding and under
    // shared edges: the device's fused multiply-adds pick the other of two equally near triangles at some,
    // and stick or slip at the cone's edge goes the other way, so the runs part (H200: 9 such nodes; the
    // same nodes touch, u differs by 1.09e-6 m, 1.6e-3 of its largest, in double; under 1e-3 in float)
    EXPECT_LT(max_diff(out[0].u, out[1].u), 5e-3 * scale) << to_string(p);
    if (p == Precision::Double) {
      ASSERT_EQ(touching[0].size(), touching[1].size());
      for (std::size_t i = 0; i < touching[0].size(); ++i) EXPECT_EQ(touching[0][i].node, touching[1][i].node);
    }
  }
}

}  // namespace
}  // namespace tissue
