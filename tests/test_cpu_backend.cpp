// The cpu backend's own tests (the interface contract, shared with the cuda
// backend, is tests/test_backend_contract.cpp): its name and thread count,
// determinism across thread counts, float against double, the halo rule on
// its state, the reductions against their definitions on its state, host
// positions, the surface BVH that is rebuilt only when the surface has
// left its margin, and the contact query's skin.
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <numeric>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "core/box_mesh.hpp"
#include "core/contact.hpp"
#include "core/device.hpp"
#include "core/scheduler.hpp"
#include "core/tet.hpp"
#include "cpu/cpu_backend.hpp"
#include "cpu/element_lanes.hpp"
#include "cpu/host_backend.hpp"
#include "cpu/surface_bvh.hpp"
#include "tests/backend_test_support.hpp"
#include "tests/pressed_box.hpp"

namespace tissue {
namespace {

using namespace tissue::test;

class CpuBackendTest : public ::testing::TestWithParam<Precision> {
 protected:
  bool is_float() const { return GetParam() == Precision::Float; }
  std::unique_ptr<Backend> make(const TissueModel<double>& m) {
    auto b = make_cpu_backend(GetParam());
    b->upload(m);
    return b;
  }
};

INSTANTIATE_TEST_SUITE_P(Precisions, CpuBackendTest, ::testing::Values(Precision::Float, Precision::Double),
                         [](const auto& info) { return std::string(to_string(info.param)); });

TEST_P(CpuBackendTest, NamesTheProcessorAndItsThreads) {
  auto b = make_cpu_backend(GetParam());
  EXPECT_NE(b->device_name().find("TBB threads"), std::string::npos) << b->device_name();
  EXPECT_EQ(b->device_name(), cpu_device_name());
}

/// A scripted run: stretch, drive two nodes, step, release, step. Returns the
/// fields and the reductions bit-for-bit.
struct RunResult {
  Fields fields;
  std::vector<Reductions> red;
};

RunResult scripted_run(Precision p, const TissueModel<double>& m, int team_size = 0) {
  auto b = make_cpu_backend(p);
  if (team_size > 0) {
    if (p == Precision::Float)
      static_cast<cpu::CpuBackend<float>&>(*b).set_team_size(team_size);
    else
      static_cast<cpu::CpuBackend<double>&>(*b).set_team_size(team_size);
  }
  b->upload(m);
  RunResult out;
  b->set_displacements(field(m, [](Vec3<double> X) { return Vec3<double>{0.03 * X.x, 0.01 * X.z, -0.02 * X.z}; }));
  const index_t nodes[] = {box_node(12, 12, 6, 6, 12), box_node(12, 12, 7, 6, 12)};
  const double target[] = {0, 0, -0.001, 0, 0, -0.0012};
  b->set_driven(nodes, target);
  for (int s = 0; s < 4; ++s) {
    b->advance(10);
    out.red.push_back(b->reduce());
  }
  b->clear_driven();
  b->advance(10);
  out.red.push_back(b->reduce());
  out.fields = b->download();
  return out;
}

bool same_bits(const std::vector<double>& a, const std::vector<double>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0;
}

TEST_P(CpuBackendTest, RunsAreBitIdenticalAcrossThreadCounts) {
  const auto m = box_model(12, true);  // 10368 tets, about the kidney's size
  const RunResult a = scripted_run(GetParam(), m);
  RunResult b;
  tbb::task_arena one_thread(1);
  one_thread.execute([&] { b = scripted_run(GetParam(), m); });
  const RunResult c = scripted_run(GetParam(), m);
  for (const RunResult* r : {static_cast<const RunResult*>(&b), &c}) {
    EXPECT_TRUE(same_bits(a.fields.u, r->fields.u));
    EXPECT_TRUE(same_bits(a.fields.f, r->fields.f));
    EXPECT_TRUE(same_bits(a.fields.node_p, r->fields.node_p));
    EXPECT_TRUE(same_bits(a.fields.elem_J, r->fields.elem_J));
    ASSERT_EQ(a.red.size(), r->red.size());
    for (size_t k = 0; k < a.red.size(); ++k)
      EXPECT_EQ(std::memcmp(&a.red[k], &r->red[k], offsetof(Reductions, bad_elem)), 0) << "reduction " << k;
  }
  EXPECT_GT(max_abs(a.fields.f), 0.0);
}

// The advance's thread team (cpu/thread_team.hpp) slices the region by its
// size; sizes beyond this machine's cores run oversubscribed. Every size must
// give the same bits, on the whole mesh and (set_driven seeds nothing, so
// via build_region) a limited region.
TEST_P(CpuBackendTest, RunsAreBitIdenticalAcrossTeamSizes) {
  const auto m = box_model(12, true);
  const RunResult a = scripted_run(GetParam(), m, 1);
  for (int size : {2, 3, 5, 16}) {
    const RunResult r = scripted_run(GetParam(), m, size);
    EXPECT_TRUE(same_bits(a.fields.u, r.fields.u)) << size << " members";
    EXPECT_TRUE(same_bits(a.fields.f, r.fields.f)) << size << " members";
    EXPECT_TRUE(same_bits(a.fields.node_p, r.fields.node_p)) << size << " members";
    EXPECT_TRUE(same_bits(a.fields.elem_J, r.fields.elem_J)) << size << " members";
    ASSERT_EQ(a.red.size(), r.red.size());
    for (size_t k = 0; k < a.red.size(); ++k)
    {
      EXPECT_EQ(std::memcmp(&a.red[k], &r.red[k], offsetof(Reductions, bad_elem)), 0) << size << " members, reduction " << k;
      EXPECT_EQ(a.red[k].bad_elem, r.red[k].bad_elem);
      EXPECT_EQ(a.red[k].finite, r.red[k].finite);
    }
  }
  // a small region keeps fewer members busy, with the same bits
  const auto region_run = [&](int size, int* busy) {
    auto b = std::make_unique<cpu::CpuBackend<double>>();
    b->set_team_size(size);
    b->upload(m);
    b->set_displacements(field(m, [](Vec3<double> X) { return Vec3<double>{0.02 * X.x, 0.0, -0.01 * X.z}; }));
    const index_t seed = box_node(12, 12, 6, 6, 12);
    b->build_region(std::span<const index_t>(&seed, 1), 4);
    b->advance(20);
    *busy = b->busy_team_members();
    return b->download();
  };
  int busy1 = 0, busy16 = 0;
  const Fields f1 = region_run(1, &busy1), f16 = region_run(16, &busy16);
  EXPECT_GT(busy16, 1);
  EXPECT_LT(busy16, 16);
  EXPECT_TRUE(same_bits(f1.u, f16.u));
  EXPECT_TRUE(same_bits(f1.f, f16.f));
  EXPECT_GT(max_abs(f1.f), 0.0);
}

// Cores lent to other work (a cut in preparation, Session) leave the team's
// members idle for a while, never fewer than one busy, and change no bit.
TEST(CpuBackendTeam, LentCoresIdleMembersAndKeepTheBits) {
  const auto m = box_model(12, true);
  const auto run = [&](bool lend, std::vector<int>* busy) {
    auto b = std::make_unique<cpu::CpuBackend<double>>();
    b->set_team_size(3);
    b->upload(m);
    b->set_displacements(field(m, [](Vec3<double> X) { return Vec3<double>{0.02 * X.x, 0.0, -0.01 * X.z}; }));
    for (int lent : {0, 1, 5, 0}) {
      if (lend) b->lend_cores(lent);
      b->advance(10);
      busy->push_back(b->busy_team_members());
    }
    return b->download();
  };
  std::vector<int> kept, lent;
  const Fields a = run(false, &kept), b = run(true, &lent);
  EXPECT_EQ(kept, (std::vector<int>{3, 3, 3, 3}));
  EXPECT_EQ(lent, (std::vector<int>{3, 2, 1, 3}));
  EXPECT_TRUE(same_bits(a.u, b.u));
  EXPECT_TRUE(same_bits(a.f, b.f));
  EXPECT_GT(max_abs(a.f), 0.0);
}

TEST(CpuBackendPrecision, FloatAgreesWithDouble) {
  const auto m = box_model(12, true);
  const RunResult f = scripted_run(Precision::Float, m);
  const RunResult d = scripted_run(Precision::Double, m);
  // Tolerance, relative to the largest value of each field: 2e-4 for
  // displacements and 1e-4 for forces and reductions. The cancellation in
  // F - I and in the Neo-Hookean stress at 5% strain costs float about
  // 1e-6 per step, and 50 explicit steps accumulate it (measured here:
  // u 4.7e-5, f 2.4e-5, reaction 2.2e-5, max |u| 3.2e-5).
  EXPECT_LT(max_diff(f.fields.u, d.fields.u), 2e-4 * max_abs(d.fields.u));
  EXPECT_LT(max_diff(f.fields.f, d.fields.f), 1e-4 * max_abs(d.fields.f));
  for (size_t k = 0; k < d.red.size(); ++k) {
    EXPECT_NEAR(f.red[k].reaction.z, d.red[k].reaction.z, 1e-4 * std::fabs(d.red[k].reaction.z)) << k;
    EXPECT_NEAR(f.red[k].max_disp, d.red[k].max_disp, 1e-4 * d.red[k].max_disp) << k;
  }
  // the driven nodes were pushed down: their internal force f = dW/du points down too
  EXPECT_LT(d.red[3].reaction.z, 0.0);
}

/// build_region on a moving mesh, with a driven node that becomes halo (body
/// of BuildRegionHaloSemantics, per scalar type).
template <class T>
void check_halo_semantics() {
  const auto m = box_model(6, true);
  cpu::CpuBackend<T> b;
  b.upload(m);
  const T target_z = T(0.0007);
  const index_t n = m.n_nodes;
  // whole mesh in motion: released from a stretch, 20 steps
  b.set_displacements(field(m, [](Vec3<double> X) { return Vec3<double>{0.0, 0.0, 0.05 * X.z}; }));
  b.advance(20);
  const auto seeds = top_triangle(m);
  // a driven node that will end up in the halo of the depth-1 region
  const Region deep = flood_fill(m, std::span<const index_t>(seeds), 2);
  const Region shallow = flood_fill(m, std::span<const index_t>(seeds), 1);
  index_t h = -1;
  for (index_t a = 0; a < n && h < 0; ++a)
    if (shallow.role[a] == kHalo && !(m.node_flags[a] & kFixed)) h = a;
  ASSERT_GE(h, 0);
  ASSERT_EQ(deep.role[h], kInner);
  const double target[] = {0.0, 0.0, 0.0007};
  b.set_driven(std::span<const index_t>(&h, 1), target);

  const std::vector<double> u0(b.state().u.begin(), b.state().u.end());
  ASSERT_GT(max_diff(u0, std::vector<double>(b.state().u_prev.begin(), b.state().u_prev.end())), 0.0);  // moving

  b.build_region(seeds, 1);
  // pass 1 was recomputed over every element, from the current u
  for (index_t e = 0; e < m.n_elems; ++e) {
    Vec3<double> ue[4];
    double dN[12];
    for (int a = 0; a < 4; ++a) ue[a] = node_u(u0, n, m.elem_nodes[a * m.n_elems + e]);
    for (int k = 0; k < 12; ++k) dN[k] = m.dndx[k * m.n_elems + e];
    const double tol = std::is_same_v<T, float> ? 1e-6 : 1e-15;
    ASSERT_NEAR(b.state().elem_J[e], det(deformation_gradient(ue, dN)), tol) << "element " << e;
  }
  b.advance(15);
  const Fields f = b.download();
  int inner_moved = 0;
  for (index_t a = 0; a < n; ++a) {
    const Vec3<double> u = node_u(f.u, n, a), was = node_u(u0, n, a);
    if (m.node_flags[a] & kFixed) {
      EXPECT_EQ(norm(u), 0.0) << "fixed node " << a;
    } else if (a == h) {
      EXPECT_EQ(u.z, double(target_z)) << "driven halo node keeps its target";
    } else if (shallow.role[a] == kInner) {
      inner_moved += norm(u - was) > 0;
    } else {  // halo held at, and outside frozen at, the displacement they had
      EXPECT_EQ(norm(u - was), 0.0) << "node " << a << " role " << int(shallow.role[a]);
      if (shallow.role[a] == kOutside) {
        EXPECT_EQ(norm(node_u(f.f, n, a)), 0.0);
      }
    }
  }
  EXPECT_GT(inner_moved, 0);

  // released, the halo node stays held where it is; a released inner node moves
  b.clear_driven();
  const index_t s0 = seeds[0];
  const double down[] = {0.0, 0.0, -0.0005};
  b.set_driven(std::span<const index_t>(&s0, 1), down);
  b.advance(5);
  b.clear_driven();
  const T s0_z = b.state().u[2 * n + s0];
  b.advance(5);
  EXPECT_EQ(b.state().u[2 * n + h], target_z);
  EXPECT_NE(b.state().u[2 * n + s0], s0_z);
  EXPECT_FALSE(b.state().held[s0]);
  EXPECT_TRUE(b.state().held[h]);
}

TEST_P(CpuBackendTest, BuildRegionHaloSemantics) {
  if (is_float())
    check_halo_semantics<float>();
  else
    check_halo_semantics<double>();
}

TEST_P(CpuBackendTest, ReductionsMatchTheirDefinitions) {
  const auto m = box_model(4, true);
  cpu::CpuBackend<double> b;
  b.upload(m);
  const index_t n = m.n_nodes;
  const auto seeds = top_triangle(m);
  b.build_region(seeds, 2);
  const double push[] = {0.0002, 0, -0.001, 0, 0, -0.001, 0, 0.0001, -0.001};
  b.set_driven(seeds, push);
  b.advance(7);
  const Reductions r = b.reduce();
  const auto& s = b.state();
  Vec3<double> reaction{0, 0, 0}, internal{0, 0, 0};
  double free2 = 0, held2 = 0, kinetic = 0, max_disp = 0;
  for (index_t a : s.region.nodes) {
    const Vec3<double> f{s.f[a], s.f[n + a], s.f[2 * n + a]};
    const Vec3<double> v = (1.0 / m.dt) * (Vec3<double>{s.u[a], s.u[n + a], s.u[2 * n + a]} -
                                           Vec3<double>{s.u_prev[a], s.u_prev[n + a], s.u_prev[2 * n + a]});
    kinetic += 0.5 * m.mass[a] * dot(v, v);
    max_disp = std::max(max_disp, norm(Vec3<double>{s.u[a], s.u[n + a], s.u[2 * n + a]}));
    if (s.driven[a]) reaction = reaction + f;
    if (s.region.role[a] != kInner) continue;
    internal = internal + f;
    (s.held[a] ? held2 : free2) += dot(f, f);
  }
  const double tol = 1e-12;
  EXPECT_NEAR(r.reaction.z, reaction.z, tol * std::fabs(reaction.z));
  EXPECT_NEAR(r.reaction.x, reaction.x, tol * norm(reaction));
  EXPECT_NEAR(r.internal.z, internal.z, tol * norm(reaction));
  EXPECT_NEAR(r.free_force2, free2, tol * free2);
  EXPECT_NEAR(r.held_force2, held2, tol * held2);
  EXPECT_NEAR(r.kinetic, kinetic, tol * kinetic);
  EXPECT_EQ(r.max_disp, max_disp);
  EXPECT_GT(free2, 0);
  EXPECT_GT(kinetic, 0);
  EXPECT_TRUE(r.finite);
  EXPECT_EQ(r.bad_elem, -1);
}

TEST_P(CpuBackendTest, WritePositionsGivesDeformedXyzTriples) {
  const auto m = box_model(2);
  auto b = make(m);
  const auto u = field(m, [](Vec3<double> X) { return Vec3<double>{0.01 * X.y, 0.002, -0.03 * X.x}; });
  b->set_displacements(u);
  const index_t n = m.n_nodes;
  std::vector<float> pos(3 * n);
  b->write_positions(pos.data());
  for (index_t i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(pos[3 * i + c], m.X[c * n + i] + u[c * n + i], 1e-8) << i;
}

constexpr double kProbeRadius = 0.003;  ///< m: smaller than the 6-cell box's 3.3 mm surface edges

/// Moves the probe from `from` to `to` over the next advance (axis +z).
void move_probe(Backend& b, Vec3<double> from, Vec3<double> to) {
  const ToolMotion mv{{from, {0, 0, 1}}, {to, {0, 0, 1}}};
  b.move_tools(std::span<const ToolMotion>(&mv, 1));
}

/// A cpu backend (double) over m with one probe of kProbeRadius held at `at`.
std::unique_ptr<cpu::CpuBackend<double>> probed(const TissueModel<double>& m, Vec3<double> at) {
  auto b = std::make_unique<cpu::CpuBackend<double>>();
  b->upload(m);
  const ToolShape tool{"probe", kProbeRadius, 0};
  b->set_tools(std::span<const ToolShape>(&tool, 1));
  move_probe(*b, at, at);
  return b;
}

/// The full-run gathers of the lane kernels (lanes_corner_u, lanes_pbar:
/// vector gathers in the AVX-512 and AVX2 clones) read what the element's
/// own corner list names, bit for bit, at runs starting anywhere in the
/// element list (not only at multiples of the lane count).
template <class T>
void expect_lane_gathers_read_each_elements_corners() {
  const TissueModel<double> m = box_model(4);
  const index_t n = m.n_nodes, ne = m.n_elems;
  ASSERT_GE(ne, 3 * cpu::kLanes);
  std::vector<T> u(3 * size_t(n)), p(n);
  for (size_t i = 0; i < u.size(); ++i) u[i] = T(std::sin(0.37 * double(i) + 0.1));  // distinct values
  for (index_t a = 0; a < n; ++a) p[a] = T(1000 * std::cos(0.91 * double(a)));
  for (const index_t e0 : {index_t(0), index_t(5), index_t(cpu::kLanes), ne - cpu::kLanes}) {
    alignas(64) T out[12][cpu::kLanes], pbar[cpu::kLanes];
    cpu::lanes_corner_u(u.data(), n, m.elem_nodes.data() + e0, ne, out);
    cpu::lanes_pbar(p.data(), m.elem_nodes.data() + e0, ne, pbar);
    for (int l = 0; l < cpu::kLanes; ++l) {
      const index_t e = e0 + l;
      T sum = T(0);
      for (int a = 0; a < 4; ++a) {
        const index_t node = m.elem_nodes[a * size_t(ne) + e];
        for (int c = 0; c < 3; ++c)
          EXPECT_EQ(out[3 * a + c][l], u[c * size_t(n) + node]) << "element " << e << " corner " << a << " axis " << c;
        sum = a == 0 ? p[node] : sum + p[node];
      }
      EXPECT_EQ(pbar[l], T(0.25) * sum) << "element " << e;
    }
  }
}

TEST(CpuLanes, FullRunGathersReadEachElementsCorners) {
  expect_lane_gathers_read_each_elements_corners<float>();
  expect_lane_gathers_read_each_elements_corners<double>();
}

/// The lane kernels' two compilations (cpu::LanesTuning: tuned for a Xeon,
/// and generic) give the same bits: the whole mesh of a box whose halves
/// are Neo-Hookean and fibre-viscoelastic (every kernel: passes 1 and 3 in
/// full runs and gathered batches, the law terms, the energies), stepped
/// from a random field with the top driven, a reduction after every chunk.
TEST(CpuLanes, BothTuningsGiveTheSameBits) {
  const cpu::LanesTuning initial = cpu::lanes_tuning();
  struct Restore {
    cpu::LanesTuning t;
    ~Restore() { cpu::set_lanes_tuning(t); }
  } restore{initial};
#if defined(__GNUC__) && defined(__x86_64__)
  if (std::getenv("TISSUE_CPU_TUNING") == nullptr) {  // the default follows the vendor
    EXPECT_EQ(initial, __builtin_cpu_is("intel") ? cpu::LanesTuning::Xeon : cpu::LanesTuning::Generic);
  }
#endif
  ModelInput in = mixed_law_box(5, kL);
  const test::PressedTop press = fix_bottom_press_top(in, -0.05 * kL);
  const std::vector<index_t>& top = press.nodes;
  const std::vector<double>& target = press.target;
  const auto m = build_model(in);
  ASSERT_TRUE(m.has_fibre() && m.has_visco());
  for (Precision p : {Precision::Float, Precision::Double}) {
    SCOPED_TRACE(p == Precision::Float ? "float" : "double");
    struct Out {
      Fields f;
      std::vector<double> energy;
    };
    auto run = [&](cpu::LanesTuning t, int depth) {
      cpu::set_lanes_tuning(t);
      auto b = make_cpu_backend(p);
      b->upload(m);
      b->set_displacements(field(m, [](Vec3<double> x) { return Vec3<double>{0.01 * x.y, -0.02 * x.z, 0.015 * x.x}; }));
      const index_t seed[] = {top.front()};
      b->build_region(seed, depth);  // depth 1: gathered batches
      if (depth == kDepthAll) {
        b->set_driven(top, target);
      } else {  // the region's seed only
        b->set_driven(seed, std::span<const double>(target.data(), 3));
      }
      Out o;
      for (int k = 0; k < 4; ++k) {
        b->advance(25);
        o.energy.push_back(b->reduce().strain_energy);
      }
      o.f = b->download();
      return o;
    };
    for (int depth : {kDepthAll, 1}) {
      SCOPED_TRACE(::testing::Message() << "depth " << depth);
      const Out x = run(cpu::LanesTuning::Xeon, depth), g = run(cpu::LanesTuning::Generic, depth);
      EXPECT_EQ(x.f.u, g.f.u);
      EXPECT_EQ(x.f.f, g.f.f);
      EXPECT_EQ(x.f.node_p, g.f.node_p);
      EXPECT_EQ(x.f.elem_J, g.f.elem_J);
      EXPECT_EQ(x.energy, g.energy);
      EXPECT_GT(x.energy.back(), 0.0);
    }
  }
  EXPECT_STREQ(cpu::to_string(cpu::LanesTuning::Xeon), "xeon");
  EXPECT_STREQ(cpu::to_string(cpu::LanesTuning::Generic), "generic");
}

/// A slab whose top the tool presses: the BVH is built once, then rebuilt
/// only when a surface node has moved more than the margin since.
TEST(SurfaceBvh, RebuiltOnlyWhenTheSurfaceLeavesItsMargin) {
  const auto m = box_model(6, true);
  const Vec3<double> top{0.5 * kL + 1e-4, 0.5 * kL + 2e-4, kL + kProbeRadius};
  auto b = probed(m, top);
  b->advance(5);
  EXPECT_EQ(b->surface_builds(), 1);  // the first query builds it; nothing moved since
  // press 4 mm (more than the margin, the median surface edge of 3.3 mm), then hold
  for (int k = 0; k < 40; ++k) {
    move_probe(*b, top - Vec3<double>{0, 0, 1e-4 * k}, top - Vec3<double>{0, 0, 1e-4 * (k + 1)});
    b->advance(2);
  }
  const long after_press = b->surface_builds();
  EXPECT_GE(after_press, 2);
  EXPECT_LE(after_press, 6);  // a few rebuilds for 4 mm of travel, not one per step (80 steps)
  EXPECT_GT(b->reduce().tools[0].contact, 0);
}

/// The members of a team check shares of the region's nodes against the
/// margin (left_margin) and one of them updates with the result
/// (update_checked): the same rebuilds as one check of every node, and a
/// full check after invalidate() whatever the shares found.
TEST(SurfaceBvh, SharedMarginChecksRebuildAsOneCheckDoes) {
  const auto m = box_model(6);
  const double margin = median_surface_edge(m);
  cpu::SurfaceBvh<double> one(m, margin), shared(m, margin);
  std::vector<double> u(3 * size_t(m.n_nodes), 0.0);
  one.update(u.data());
  shared.update(u.data());
  std::vector<index_t> all(m.n_nodes);
  std::iota(all.begin(), all.end(), index_t(0));
  const std::span<const index_t> nodes(all);
  const std::size_t third = all.size() / 3;
  const std::span<const index_t> slices[3] = {nodes.first(third), nodes.subspan(third, third), nodes.subspan(2 * third)};
  const auto shared_update = [&] {
    int found = 0;
    for (const auto& slice : slices) found += shared.left_margin(u.data(), slice) ? 1 : 0;
    shared.update_checked(u.data(), found > 0);
    return found;
  };
  const index_t a = m.surf_nodes[m.n_surf / 2];
  const size_t z = 2 * size_t(m.n_nodes) + a;
  u[z] = 0.6 * margin;  // within the margin
  one.update(u.data(), nodes);
  EXPECT_EQ(shared_update(), 0);
  EXPECT_EQ(one.builds(), 1);
  EXPECT_EQ(shared.builds(), 1);
  u[z] = 1.5 * margin;  // beyond it: exactly one share finds it
  one.update(u.data(), nodes);
  EXPECT_EQ(shared_update(), 1);
  EXPECT_EQ(one.builds(), 2);
  EXPECT_EQ(shared.builds(), 2);
  u[z] = 1.6 * margin;  // within the new build's margin
  EXPECT_EQ(shared_update(), 0);
  EXPECT_EQ(shared.builds(), 2);
  // a node no share holds moves beyond the margin: only a full check sees it
  const index_t b = m.surf_nodes[0];
  u[b] = 2 * margin;
  shared.update_checked(u.data(), false);
  EXPECT_EQ(shared.builds(), 2);
  shared.invalidate();
  shared.update_checked(u.data(), false);
  EXPECT_EQ(shared.builds(), 3);
}

/// The margin check looks only at the region's nodes (nodes outside it are
/// held), so a change of u beyond the region -- new displacements here --
/// must make the next query check the whole surface: the upper half moved
/// 5 mm (more than the 3.3 mm margin) outside a small region is still found
/// under the tool (its nodes reported as outside the region), after one rebuild.
TEST(SurfaceBvh, DisplacementsBeyondTheRegionAreSeenByTheNextQuery) {
  const auto m = box_model(6, true);
  auto b = probed(m, {0.5 * kL, 0.5 * kL, 3 * kL});  // far above the box
  b->advance(1);
  ASSERT_EQ(b->surface_builds(), 1);
  b->build_region(std::vector<index_t>{0}, 1);  // a corner of the bottom: the top's middle is outside
  b->advance(1);
  EXPECT_EQ(b->surface_builds(), 1);  // nothing moved
  std::vector<double> u(3 * size_t(m.n_nodes), 0.0);
  for (index_t a = 0; a < m.n_nodes; ++a)  // the upper half, far from the region
    if (m.X[2 * size_t(m.n_nodes) + a] > 0.5 * kL) u[2 * size_t(m.n_nodes) + a] = 5e-3;
  b->set_displacements(u);
  const Vec3<double> top{0.5 * kL + 1e-4, 0.5 * kL + 2e-4, kL + 5e-3 + kProbeRadius - 1e-3};  // 1 mm into the moved top
  move_probe(*b, top, top);
  b->advance(1);
  EXPECT_EQ(b->surface_builds(), 2);
  const Reductions r = b->reduce();
  EXPECT_GT(r.tools[0].outside, 0);
  EXPECT_EQ(r.tools[0].contact, 0);
}

/// The skin query returns every triangle the plain query returns (and those
/// within the skin), walks the BVH again only when the box leaves the padded
/// box or the BVH was rebuilt, and skin 0 walks it every time.
TEST(SurfaceBvh, SkinQueriesHoldThePlainQueryAndAreReusedWithinTheSkin) {
  const auto m = box_model(8, true);
  cpu::SurfaceBvh<double> bvh(m, median_surface_edge(m)), bvh0(m, median_surface_edge(m));
  const std::vector<double> u(3 * size_t(m.n_nodes), 0.0);
  bvh.update(u.data());
  bvh0.update(u.data());
  const double skin = 0.5 * bvh.margin(), r = 0.003;
  bvh.set_skin(skin);  // bvh0 keeps the default, 0
  const auto box_at = [&](double x) {
    cpu::Box b;
    const double p[3] = {x, 0.5 * kL, kL};
    b.add(p, r);
    return b;
  };
  std::vector<index_t> plain, wide;
  long reused = 0;
  for (int k = 0; k <= 40; ++k) {
    const double x = 0.3 * kL + 1e-4 * k;  // 4 mm in 0.1 mm steps
    const cpu::Box b = box_at(x);
    const long before = bvh.skin_queries();
    const std::vector<index_t> got = bvh.query_within_skin(b);
    reused += bvh.skin_queries() == before;
    bvh.query(b, plain);
    ASSERT_FALSE(plain.empty());
    EXPECT_TRUE(std::includes(got.begin(), got.end(), plain.begin(), plain.end())) << "step " << k;
    cpu::Box padded = b;
    const double lo[3] = {b.lo[0], b.lo[1], b.lo[2]}, hi[3] = {b.hi[0], b.hi[1], b.hi[2]};
    padded.add(lo, 2 * skin);  // no triangle beyond the skin of the box it was queried for
    padded.add(hi, 2 * skin);
    bvh.query(padded, wide);
    EXPECT_TRUE(std::includes(wide.begin(), wide.end(), got.begin(), got.end())) << "step " << k;
    EXPECT_EQ(bvh0.query_within_skin(b), plain) << "step " << k;
  }
  EXPECT_EQ(bvh0.skin_queries(), 41);
  EXPECT_GE(reused, 30);  // 1.25 mm of skin: a query per 12 steps or so of 0.1 mm
  EXPECT_LE(bvh.skin_queries(), 11);
  // a box far smaller than the kept one queries again (a fast step's large box is not kept sweeping)
  cpu::Box large = box_at(0.5 * kL);
  const double lo[3] = {large.lo[0], large.lo[1], large.lo[2]}, hi[3] = {large.hi[0], large.hi[1], large.hi[2]};
  large.add(lo, 3 * skin);
  large.add(hi, 3 * skin);
  bvh.query_within_skin(large);
  long before = bvh.skin_queries();
  bvh.query_within_skin(box_at(0.5 * kL));
  EXPECT_EQ(bvh.skin_queries(), before + 1);
  // a rebuild invalidates the kept triangles: the top raised by two margins is found where it is now
  std::vector<double> moved = u;
  for (index_t a = 0; a < m.n_nodes; ++a) moved[2 * size_t(m.n_nodes) + a] = 2 * bvh.margin();
  bvh.update(moved.data());
  ASSERT_EQ(bvh.builds(), 2);
  before = bvh.skin_queries();
  bvh.query_within_skin(box_at(0.5 * kL));  // the box kept before the rebuild: walked again
  EXPECT_EQ(bvh.skin_queries(), before + 1);
  before = bvh.skin_queries();
  cpu::Box raised = box_at(0.5 * kL);
  raised.lo[2] += 2 * bvh.margin();
  raised.hi[2] += 2 * bvh.margin();
  const std::vector<index_t> got = bvh.query_within_skin(raised);
  EXPECT_EQ(bvh.skin_queries(), before + 1);
  bvh.query(raised, plain);
  ASSERT_FALSE(plain.empty());
  EXPECT_TRUE(std::includes(got.begin(), got.end(), plain.begin(), plain.end()));
  EXPECT_THROW(bvh.set_skin(-1.0), std::invalid_argument);
}

/// The contact stage's results depend neither on its query skin nor on how
/// many team members share the sweep: a probe that presses into the top and
/// slides across it, one step per advance, gives the same bits with a query
/// per step (skin 0) on one member as with the default skin (far fewer
/// queries) and with a 1 m skin (every step sweeps the whole surface), on
/// 1, 2, 3 and 16 members.
TEST_P(CpuBackendTest, ContactQuerySkinAndSweepSharesChangeNoBit) {
  const auto m = box_model(8, true);
  struct Run {
    Fields fields;
    std::vector<Reductions> red;
    std::vector<std::vector<ContactNode>> contacts;
    long queries = 0;
  };
  const auto run = [&](std::optional<double> skin, int members) {
    Run out;
    long queries = 0;
    const auto go = [&](auto* cpu) {
      cpu->set_team_size(members);
      cpu->upload(m);
      if (skin) cpu->contact_stage()->set_query_skin(*skin);
      const ToolShape tool{"probe", kProbeRadius, 0.01};
      cpu->set_tools(std::span<const ToolShape>(&tool, 1));
      Vec3<double> at{0.3 * kL, 0.45 * kL, kL + kProbeRadius};
      for (int k = 0; k < 120; ++k) {
        // press 3 mm over the first 30 steps, then slide 6 mm along x with a slight turn of the axis
        const Vec3<double> next = at + (k < 30 ? Vec3<double>{0, 0, -1e-4} : Vec3<double>{5e-5, 1e-5, 0});
        const ToolMotion mv{{at, {0, 0, 1}}, {next, unit_or(Vec3<double>{0.002 * (k - 30 > 0 ? k - 30 : 0) / 90.0, 0, 1}, Vec3<double>{0, 0, 1})}};
        cpu->move_tools(std::span<const ToolMotion>(&mv, 1));
        at = next;
        cpu->advance(1);
        out.red.push_back(cpu->reduce());
        out.contacts.push_back(cpu->contacts());
      }
      out.fields = cpu->download();
      queries = cpu->contact_stage()->bvh().skin_queries();  // the steps' walks (candidates() uses query())
    };
    if (GetParam() == Precision::Float) {
      auto c = std::make_unique<cpu::CpuBackend<float>>();
      go(c.get());
    } else {
      auto c = std::make_unique<cpu::CpuBackend<double>>();
      go(c.get());
    }
    out.queries = queries;
    return out;
  };
  const Run a = run(0.0, 1);
  EXPECT_EQ(a.queries, 120);
  int touching = 0;
  for (const Reductions& r : a.red) touching += r.tools[0].contact > 0;
  EXPECT_GT(touching, 80);  // in contact for most of the path
  for (const auto& [skin, members] : std::vector<std::pair<std::optional<double>, int>>{
           {std::nullopt, 1}, {std::nullopt, 2}, {std::nullopt, 3}, {std::nullopt, 16}, {1.0, 1}, {1.0, 16}}) {
    const std::string what = fmt::format("skin {}, {} members", skin ? fmt::format("{} m", *skin) : "default", members);
    const Run d = run(skin, members);
    if (!skin) {
      EXPECT_LT(d.queries, 40) << what;
      EXPECT_GT(d.queries, 0) << what;
    }
    EXPECT_TRUE(same_bits(a.fields.u, d.fields.u)) << what;
    EXPECT_TRUE(same_bits(a.fields.f, d.fields.f)) << what;
    ASSERT_EQ(a.red.size(), d.red.size());
    for (size_t k = 0; k < a.red.size(); ++k) {
      EXPECT_EQ(std::memcmp(&a.red[k], &d.red[k], offsetof(Reductions, bad_elem)), 0) << what << ", step " << k;
      expect_same_contacts(a.contacts[k], d.contacts[k], fmt::format("{}, step {}", what, k));
    }
  }
}

}  // namespace
}  // namespace tissue
