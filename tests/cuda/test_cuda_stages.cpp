// Unit tests of each cuda backend stage against the cpu backend and the core
// host references, on random non-zero displacement fields: the four passes,
// the device flood fill, the contact stage and grasping, the reductions, the
// bad-element flag, write_positions, the step modes (identical bits, with a
// tool in contact), the per-tick transfer counts and the bad-input errors
// (the interface contract shared with the cpu is test_backend_contract). Every test skips when
// no usable GPU is present, except the one that checks how the backend
// refuses to run without one.
#include <cuda_runtime.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numeric>
#include <span>
#include <stdexcept>
#include <string>

#include "backends/registry.hpp"
#include "core/device.hpp"
#include "core/region.hpp"
#include "core/scheduler.hpp"
#include "core/tet.hpp"
#include "io/kidney.hpp"
#include "scene/validate.hpp"
#include "tests/cuda/cuda_test_support.hpp"
#include "tests/pressed_box.hpp"
#include "tests/sliver.hpp"

namespace tissue::cuda_test {
namespace {

/// Stage-by-stage tolerances, relative to the field's magnitude. Both
/// backends evaluate the same core functions over the same element orders;
/// what differs is the compiler's FMA contraction, the device's pow/cbrt (an
/// ulp or two) and the cuda backend's pairwise node sums. Measured on an
/// NVIDIA H200 (docs/cuda.md): double <= 6.2e-15, float <= 5.7e-6 per pass;
/// the bounds below leave a 3x (float) and 1000x (double) margin.
double pass_tol(Precision p) { return p == Precision::Double ? 1e-11 : 2e-5; }

void report(const char* what, Precision p, double value) {
  std::printf("[measured] %s (%s): %.3g\n", what, to_string(p), value);
}

std::vector<double> minus_one(std::vector<double> v) {
  for (auto& x : v) x -= 1;
  return v;
}

class Stages : public ::testing::TestWithParam<Precision> {};

INSTANTIATE_TEST_SUITE_P(Precisions, Stages, ::testing::Values(Precision::Float, Precision::Double),
                         [](const auto& info) { return name_of(info.param); });

TEST_P(Stages, EachPassMatchesCpuOnRandomField) {
  SKIP_WITHOUT_GPU();
  const Precision p = GetParam();
  const auto m = box_model(5, 4, 3, 0.05, 0.04, 0.03);
  auto cpu = make_cpu_backend(p), gpu = make_cuda_backend(p);
  cpu->upload(m);
  gpu->upload(m);
  const index_t seeds[3] = {m.tris[7], m.tris[m.n_tris + 7], m.tris[2 * m.n_tris + 7]};
  unsigned seed = 1;
  for (int depth : {kDepthAll, 1, 0}) {
    SCOPED_TRACE(depth);
    if (depth != kDepthAll) {
      EXPECT_EQ(gpu->build_region(seeds, depth).nodes(), cpu->build_region(seeds, depth).nodes());
    }
    const auto u = random_field(m.n_nodes, 2e-4, seed++);  // strains of a few percent
    cpu->set_displacements(u);
    gpu->set_displacements(u);
    cpu->element_pressure();
    gpu->element_pressure();
    const Fields c1 = cpu->download(), g1 = gpu->download();
    ASSERT_GT(*std::max_element(c1.elem_J.begin(), c1.elem_J.end()), 1.0);  // really deformed
    const double dJ = rel_diff(minus_one(g1.elem_J), minus_one(c1.elem_J));
    report("pass 1 J - 1", p, dJ);
    EXPECT_LT(dJ, pass_tol(p));

    cpu->nodal_pressure();
    gpu->nodal_pressure();
    const double dp = rel_diff(gpu->download().node_p, cpu->download().node_p);
    report("pass 2 p", p, dp);
    EXPECT_LT(dp, pass_tol(p));

    cpu->element_forces();
    gpu->element_forces();
    cpu->node_update();
    gpu->node_update();
    const Fields c4 = cpu->download(), g4 = gpu->download();
    const double df = rel_diff(g4.f, c4.f), du = rel_diff(g4.u, c4.u);
    report("passes 3+4 f", p, df);
    report("pass 4 u", p, du);
    EXPECT_LT(df, 10 * pass_tol(p));
    EXPECT_LT(du, pass_tol(p));
    EXPECT_GT(*std::max_element(c4.f.begin(), c4.f.end()), 0.0);
  }
}

TEST_P(Stages, PlainTetForcesMatchCpu) {
  SKIP_WITHOUT_GPU();
  const Precision p = GetParam();
  const auto m = box_model(3, 3, 3, 0.03, 0.03, 0.03, /*ianp=*/false);
  auto cpu = make_cpu_backend(p), gpu = make_cuda_backend(p);
  cpu->upload(m);
  gpu->upload(m);
  const auto u = random_field(m.n_nodes, 2e-4, 11);
  cpu->set_displacements(u);
  gpu->set_displacements(u);
  cpu->advance(3);
  gpu->advance(3);
  const double df = rel_diff(gpu->download().f, cpu->download().f);
  report("plain tet f after 3 steps", p, df);
  EXPECT_LT(df, 10 * pass_tol(p));
}

TEST_P(Stages, FloodFillMatchesCoreForEveryDepth) {
  SKIP_WITHOUT_GPU();
  const auto m = box_model(6, 5, 4, 0.06, 0.05, 0.04);
  auto gpu = make_cuda_backend(GetParam());
  gpu->upload(m);
  for (index_t t : {index_t(0), m.n_tris / 3, m.n_tris - 1}) {
    const std::vector<index_t> seeds = {m.tris[t], m.tris[m.n_tris + t], m.tris[2 * m.n_tris + t]};
    for (int depth : {0, 1, 2, 3, kDepthAll}) {
      SCOPED_TRACE(::testing::Message() << "triangle " << t << " depth " << depth);
      const Region ref = flood_fill(m, seeds, depth);
      const RegionSizes s = gpu->build_region(seeds, depth);
      EXPECT_EQ(s.n_inner, ref.n_inner);
      EXPECT_EQ(s.n_halo, ref.n_halo);
      EXPECT_EQ(s.n_elems, index_t(ref.elems.size()));
      EXPECT_EQ(s.depth, depth);
      const Region r = gpu->region();
      EXPECT_EQ(r.role, ref.role);
      EXPECT_EQ(r.nodes, ref.nodes);
      EXPECT_EQ(r.elems, ref.elems);
      EXPECT_EQ(r.seeds, ref.seeds);
      EXPECT_EQ(r.front, ref.front);
      EXPECT_EQ(r.n_inner, ref.n_inner);
      EXPECT_EQ(r.n_halo, ref.n_halo);
      if (depth == 1) {
        EXPECT_GT(ref.n_halo, 0);  // the test exercises all three roles
        EXPECT_LT(ref.nodes.size(), size_t(m.n_nodes));
      }
    }
  }
  // empty seeds at a finite depth: an empty region
  const RegionSizes e = gpu->build_region({}, 3);
  EXPECT_EQ(e.nodes(), 0);
  EXPECT_EQ(e.n_elems, 0);
}

/// m on b (from displacements u, where given) with tools of `shapes` moving
/// by `motion` over three steps: the contacts and the reductions after them.
std::pair<std::vector<ContactNode>, Reductions> press(Backend& b, const TissueModel<double>& m,
                                                      std::span<const ToolShape> shapes,
                                                      std::span<const ToolMotion> motion,
                                                      const std::vector<double>* u = nullptr) {
  b.upload(m);
  if (u) b.set_displacements(*u);
  b.set_tools(shapes);
  b.move_tools(motion);
  b.advance(3);
  return {b.contacts(), b.reduce()};
}

/// The contact stage on a randomly displaced surface: two tools (a sphere
/// and a capsule lying across the top) swept over three steps against the cpu
/// backend: the same nodes in contact, of the same kind and tool, the same
/// corrected displacements and normals, the same per-tool reductions (to
/// the pass tolerance), in every step mode.
TEST_P(Stages, ContactStageMatchesCpu) {
  SKIP_WITHOUT_GPU();
  const Precision p = GetParam();
  const auto m = box_model(8, 8, 4, 0.04, 0.04, 0.02);
  const auto u = random_field(m.n_nodes, 2e-4, 41);
  const ToolShape shapes[] = {{"sphere", 0.004, 0}, {"capsule", 0.002, 0.02}};
  const ToolMotion motion[] = {{{{0.0131, 0.0162, 0.0235}, {0, 0, 1}}, {{0.0131, 0.0162, 0.0215}, {0, 0, 1}}},
                               {{{0.025, 0.01, 0.0215}, {0, 1, 0}}, {{0.025, 0.011, 0.0205}, {0.1, 1, 0}}}};
  auto run = [&](Backend& b) { return press(b, m, shapes, motion, &u); };
  auto cpu = make_cpu_backend(p);
  const auto [cc, rc] = run(*cpu);
  const Fields fc = cpu->download();
  ASSERT_GT(rc.tools[0].contact, 3);
  ASSERT_GT(rc.tools[1].contact, 3);
  for (CudaStepMode mode : {CudaStepMode::Launch, CudaStepMode::Graph, CudaStepMode::Grid, CudaStepMode::Cluster}) {
    SCOPED_TRACE(to_string(mode));
    auto gpu = make_cuda_backend(p);
    set_cuda_step_mode(*gpu, mode);
    const auto [cg, rg] = run(*gpu);
    ASSERT_EQ(cg.size(), cc.size());
    for (size_t k = 0; k < cc.size(); ++k) {
      EXPECT_EQ(cg[k].node, cc[k].node);
      EXPECT_EQ(cg[k].tool, cc[k].tool);
      EXPECT_EQ(cg[k].kind, cc[k].kind);
      // (the normal is the unit direction of the node's correction: corrections of 1e-7 m carry the
      // rounding of 4 cm positions, 1e-16 x 0.04 m, as 1e-8 of their direction; measured 3e-8 on an H100)
      EXPECT_LT(norm(cg[k].normal - cc[k].normal), p == Precision::Double ? 2e-7 : 2e-4);
    }
    const double d = rel_diff(gpu->download().u, fc.u);
    report("contact step displacements", p, d);
    EXPECT_LT(d, pass_tol(p));
    for (int t = 0; t < 2; ++t) {
      EXPECT_EQ(rg.tools[t].contact, rc.tools[t].contact);
      EXPECT_LT(norm(rg.tools[t].reaction - rc.tools[t].reaction), 1e3 * pass_tol(p) * norm(rc.tools[t].reaction));
    }
  }
}

/// A tool much larger than the triangles (a 15 mm sphere on a surface of
/// 1.25 mm cells, a few hundred triangles that may touch): the sweep's lane
/// groups take several triangles each, a block's 32 groups more than one
/// round of its compacted list (Launch, Graph) and a warp's 4 groups more
/// than one round of its ballot (Grid, Cluster; the test checks both on the
/// host first). Every mode against the cpu, and bit for bit against the
/// Grid mode.
TEST_P(Stages, DenseContactMatchesCpuInEveryStepMode) {
  const Precision p = GetParam();
  const auto m = box_model(32, 32, 2, 0.04, 0.04, 0.0025);
  const double r = 0.015, top = 0.0025;
  const ToolShape shape[] = {{"sphere", r, 0}};
  const ToolMotion motion[] = {{{{0.0203, 0.0198, top + r - 0.0008}, {0, 0, 1}}, {{0.0205, 0.0199, top + r - 0.001}, {0, 0, 1}}}};
  // the triangles that may touch at the first step's check, per block of 256 and per warp of 32, for the
  // tools as press() gives them to a backend
  auto host = make_cpu_backend(p);
  host->upload(m);
  host->set_tools(shape);
  host->move_tools(motion);
  const ContactTools<double> tools = host->contact_tools(3);
  std::vector<int> per_block(m.n_tris / 256 + 1, 0), per_warp(m.n_tris / 32 + 1, 0);
  for (index_t t = 0; t < m.n_tris; ++t) {
    Vec3<double> x[3];
    for (int v = 0; v < 3; ++v) {
      const index_t i = m.tris[v * m.n_tris + t];
      x[v] = {m.X[i], m.X[m.n_nodes + i], m.X[2 * m.n_nodes + i]};
    }
    if (!triangle_may_touch(tools, StepCapsules<double>{tools, 0}, x)) continue;
    ++per_block[t / 256];
    ++per_warp[t / 32];
  }
  ASSERT_GT(*std::max_element(per_block.begin(), per_block.end()), 32) << "more than a block's 32 groups";
  ASSERT_GT(*std::max_element(per_warp.begin(), per_warp.end()), 4) << "more than a warp's 4 groups";
  std::printf("  [%s] most triangles that may touch in a block of 256: %d, in a warp: %d\n",
              p == Precision::Double ? "double" : "float", *std::max_element(per_block.begin(), per_block.end()),
              *std::max_element(per_warp.begin(), per_warp.end()));
  SKIP_WITHOUT_GPU();  // (the counts above are the host's)
  auto run = [&](Backend& b) { return press(b, m, shape, motion); };
  auto cpu = make_cpu_backend(p);
  const auto [cc, rc] = run(*cpu);
  const Fields fc = cpu->download();
  ASSERT_GT(rc.tools[0].contact, 30);
  std::vector<double> grid_u;
  for (CudaStepMode mode : {CudaStepMode::Grid, CudaStepMode::Launch, CudaStepMode::Graph, CudaStepMode::Cluster}) {
    SCOPED_TRACE(to_string(mode));
    auto gpu = make_cuda_backend(p);
    set_cuda_step_mode(*gpu, mode);
    const auto [cg, rg] = run(*gpu);
    const Fields fg = gpu->download();
    if (p == Precision::Double)
      EXPECT_EQ(rg.tools[0].contact, rc.tools[0].contact);
    else  // float's rounding may put a node on the contact's rim either way
      EXPECT_NEAR(rg.tools[0].contact, rc.tools[0].contact, 1 + rc.tools[0].contact / 10);
    const double d = rel_diff(fg.u, fc.u);
    report("dense contact displacements", p, d);
    EXPECT_LT(d, p == Precision::Double ? 1e-9 : 1e-3);
    if (grid_u.empty())
      grid_u = fg.u;
    else
      EXPECT_EQ(fg.u, grid_u) << "the same bits as the Grid mode";
  }
}

/// The reductions on a mesh with more items than the reduction kernel has
/// threads (134k tets, 25k nodes and 5.4k surface nodes: its grid-stride
/// loop, its last block combining 1024 blocks' partials), with four tools
/// pressing into the top at once, near its four corners (their nodes fall in
/// a few neighbouring blocks, some meeting two tools): the same per-tool
/// counts as the cpu, the same reactions, energies and norms to the pass
/// tolerance, and the same bits from a second run (the sums' order is
/// fixed).
TEST_P(Stages, ReductionsOfManyBlocksAndFourToolsMatchCpu) {
  SKIP_WITHOUT_GPU();
  const Precision p = GetParam();
  const double top = 0.02, r = 0.003;
  const auto m = box_model(40, 40, 14, 0.06, 0.06, top);
  ASSERT_GT(m.n_nodes + m.n_elems, 1024 * 128);
  const auto u = random_field(m.n_nodes, 1e-5, 43);
  const ToolShape shapes[] = {{"a", r, 0}, {"b", r, 0}, {"c", r, 0.01}, {"d", r, 0}};
  auto press = [&](double x, double y) {
    return ToolMotion{{{x, y, top + r - 0.0004}, {0, 0, 1}}, {{x, y, top + r - 0.0008}, {0, 0, 1}}};
  };
  const ToolMotion motion[] = {press(0.011, 0.012), press(0.049, 0.013), press(0.012, 0.047), press(0.046, 0.05)};
  auto run = [&](Backend& b) {
    b.upload(m);
    b.set_displacements(u);
    b.set_tools(shapes);
    b.move_tools(motion);
    return b.advance_reduce(2);
  };
  auto cpu = make_cpu_backend(p);
  const Reductions rc = run(*cpu);
  auto gpu = make_cuda_backend(p);
  const Reductions rg = run(*gpu);
  const Reductions again = run(*make_cuda_backend(p));
  EXPECT_EQ(again.strain_energy, rg.strain_energy);
  EXPECT_EQ(again.kinetic, rg.kinetic);
  EXPECT_EQ(again.free_force2, rg.free_force2);
  for (int t = 0; t < 4; ++t) EXPECT_EQ(norm(again.tools[t].reaction - rg.tools[t].reaction), 0.0) << t;
  const double tol = 1e3 * pass_tol(p);
  for (int t = 0; t < 4; ++t) {
    SCOPED_TRACE(t);
    ASSERT_GT(rc.tools[t].contact, 3);
    EXPECT_EQ(rg.tools[t].contact, rc.tools[t].contact);
    EXPECT_EQ(rg.tools[t].grasped, 0);
    EXPECT_EQ(rg.tools[t].rigid, rc.tools[t].rigid);
    EXPECT_EQ(rg.tools[t].outside, rc.tools[t].outside);
    EXPECT_LT(rc.tools[t].reaction.z, 0) << "the pressed nodes' reaction points down (the tool feels minus it)";
    EXPECT_LT(norm(rg.tools[t].reaction - rc.tools[t].reaction), tol * norm(rc.tools[t].reaction));
  }
  EXPECT_TRUE(rg.finite);
  EXPECT_LT(std::fabs(rg.strain_energy - rc.strain_energy), tol * rc.strain_energy);
  EXPECT_LT(std::fabs(rg.kinetic - rc.kinetic), tol * rc.kinetic);
  EXPECT_LT(std::fabs(rg.free_force2 - rc.free_force2), tol * rc.free_force2);
  EXPECT_LT(std::fabs(rg.max_disp - rc.max_disp), tol * rc.max_disp);
  EXPECT_LT(norm(rg.internal - rc.internal), tol * (norm(rc.internal) + std::sqrt(rc.free_force2)));
  report("many-block reduction: strain energy", p, std::fabs(rg.strain_energy - rc.strain_energy) / rc.strain_energy);
}

/// A tool that keeps moving over many steps, against the cpu in every step
/// mode: pressed into the top, slid two ways (its triangles stop proposing
/// while their nodes are still pushed by others), grasping and lifting
/// (grasped corners' blocked penetrations), released and pressed in again
/// beside. The sweep stores only the proposals it has and the merge of a
/// proposed node clears its slots (cuda/contact.cuh): a proposal left from
/// an earlier step would push a node again here (a build that did not clear
/// them failed from the first phase, by 0.03-0.15). Compared after every
/// phase.
TEST_P(Stages, MovingContactMatchesCpuInEveryStepMode) {
  SKIP_WITHOUT_GPU();
  const Precision p = GetParam();
  const auto m = box_model(20, 20, 3, 0.04, 0.04, 0.012);
  const ToolShape shape[] = {{"probe", 0.004, 0.01}};
  const Vec3<double> z{0, 0, 1};
  struct Phase {
    Vec3<double> to;
    Vec3<double> axis;
    bool grasp;
  };
  // the top is at z = 0.012: the tip's sphere goes 1.6-2.1 mm into it, the lift takes it 0.2 mm above
  const Phase phases[] = {{{0.0171, 0.0183, 0.0144}, z, false},   {{0.0171, 0.0183, 0.0140}, z, false},
                          {{0.0221, 0.0191, 0.0140}, z, false},   {{0.0232, 0.0243, 0.0139}, {0.2, 0, 1}, false},
                          {{0.0232, 0.0243, 0.0139}, z, true},    {{0.0230, 0.0240, 0.0162}, z, true},
                          {{0.0230, 0.0240, 0.0177}, z, false},   {{0.0150, 0.0250, 0.0141}, z, false}};
  // (a ninth phase tilting the tool as it slides on left the float backends 0.11 apart, before and
  // after the sparse proposals alike: a node on a contact's edge went either way)
  struct Checkpoint {
    std::vector<ContactNode> contacts;
    Reductions r;
    std::vector<double> u;
  };
  auto run = [&](Backend& b) {
    std::vector<Checkpoint> out;
    b.upload(m);
    b.set_tools(shape);
    ToolPose at{{0.0171, 0.0183, 0.0160}, z};
    for (const Phase& ph : phases) {
      ToolMotion mv{at, {ph.to, ph.axis}, ph.grasp};
      b.move_tools(std::span<const ToolMotion>(&mv, 1));
      b.advance(12);
      at = mv.to;
      out.push_back({b.contacts(), b.reduce(), b.download().u});
    }
    return out;
  };
  auto cpu = make_cpu_backend(p);
  const std::vector<Checkpoint> cc = run(*cpu);
  index_t pushed = 0, grasped = 0;
  for (const Checkpoint& c : cc) {
    pushed = std::max(pushed, c.r.tools[0].contact);
    grasped = std::max(grasped, c.r.tools[0].grasped);
  }
  ASSERT_GT(pushed, 6) << "the tool presses the top";
  ASSERT_GT(grasped, 2) << "the grasp holds nodes";
  EXPECT_EQ(cc[6].r.tools[0].grasped, 0) << "released";
  for (CudaStepMode mode : {CudaStepMode::Launch, CudaStepMode::Graph, CudaStepMode::Grid, CudaStepMode::Cluster}) {
    SCOPED_TRACE(to_string(mode));
    auto gpu = make_cuda_backend(p);
    set_cuda_step_mode(*gpu, mode);
    const std::vector<Checkpoint> cg = run(*gpu);
    double worst = 0;
    for (size_t k = 0; k < cc.size(); ++k) {
      SCOPED_TRACE(::testing::Message() << "phase " << k);
      const double d = rel_diff(cg[k].u, cc[k].u);
      worst = std::max(worst, d);
      EXPECT_LT(d, p == Precision::Double ? 1e-8 : 1e-3);  // a proposal left over: 0.03-0.15 from phase 0
      if (p == Precision::Float) {  // float's rounding may move a node across a contact's edge over 100 steps
        EXPECT_NEAR(cg[k].r.tools[0].contact, cc[k].r.tools[0].contact, 1 + cc[k].r.tools[0].contact / 10);
        EXPECT_EQ(cg[k].r.tools[0].grasped, cc[k].r.tools[0].grasped);
        continue;
      }
      ASSERT_EQ(cg[k].contacts.size(), cc[k].contacts.size());
      for (size_t i = 0; i < cc[k].contacts.size(); ++i) {
        EXPECT_EQ(cg[k].contacts[i].node, cc[k].contacts[i].node);
        EXPECT_EQ(cg[k].contacts[i].kind, cc[k].contacts[i].kind);
        EXPECT_EQ(cg[k].contacts[i].tool, cc[k].contacts[i].tool);
      }
    }
    report((std::string("moving contact, step mode ") + to_string(mode)).c_str(), p, worst);
  }
}

/// An attribute of the current device (the queries' failures recorded; 0
/// then).
int device_attribute(cudaDeviceAttr attr) {
  int dev = 0, v = 0;
  EXPECT_EQ(cudaGetDevice(&dev), cudaSuccess);
  EXPECT_EQ(cudaDeviceGetAttribute(&v, attr, dev), cudaSuccess);
  return v;
}

/// Sets a process-wide test hook of the backend while it lives, and sets
/// it back to `restore` however the test ends.
template <class V>
class ScopedHook {
 public:
  ScopedHook(void (*set)(V), V value, V restore) : set_(set), restore_(restore) { set_(value); }
  ~ScopedHook() { set_(restore_); }
  ScopedHook(const ScopedHook&) = delete;
  ScopedHook& operator=(const ScopedHook&) = delete;

 private:
  void (*set_)(V);
  V restore_;
};

/// Caps the blocks of each element pass's launch that load before their
/// wait (set_cuda_element_first_wave; 0: every block waits first, -1: no
/// cap) while it lives.
struct ElementFirstWave : ScopedHook<index_t> {
  explicit ElementFirstWave(index_t blocks) : ScopedHook(set_cuda_element_first_wave, blocks, -1) {}
};

/// Runs every launch of passes 1 and 3 (but pass 3's streaming kernel) in
/// the smaller blocks of a launch of several waves
/// (set_cuda_small_element_blocks) while it lives.
struct SmallElementBlocks : ScopedHook<bool> {
  explicit SmallElementBlocks(bool always) : ScopedHook(set_cuda_small_element_blocks, always, false) {}
};

/// Law terms (core/material.hpp) in every step mode: a box half
/// Neo-Hookean, half fibre-reinforced and viscoelastic, its top pressed
/// for 90 steps, against the cpu (the persistent kernels take the law path
/// out of line, the pass kernels pick the law kernel at launch).
TEST_P(Stages, LawTermsMatchCpuInEveryStepMode) {
  SKIP_WITHOUT_GPU();
  const Precision p = GetParam();
  ModelInput in = test::mixed_law_box(4, 0.02);
  const test::PressedTop press = test::fix_bottom_press_top(in, -0.002);
  const std::vector<index_t>& top = press.nodes;
  const std::vector<double>& target = press.target;
  const auto m = build_model(in);
  ASSERT_TRUE(m.has_fibre() && m.has_visco());
  auto run = [&](Backend& b) {
    b.upload(m);
    b.set_driven(top, target);
    for (int k = 0; k < 3; ++k) {
      b.advance(30);
      b.reduce();  // the next steps start at pass 3 with the reduction's passes 1-2 (law kernels included)
    }
    return b.download().u;
  };
  auto cpu = make_cpu_backend(p);
  const std::vector<double> uc = run(*cpu);
  for (CudaGradients g : {CudaGradients::Stored, CudaGradients::Recomputed}) {
    std::vector<double> graph_u;
    for (CudaStepMode mode : {CudaStepMode::Launch, CudaStepMode::Graph, CudaStepMode::Grid, CudaStepMode::Cluster}) {
      SCOPED_TRACE(::testing::Message() << to_string(mode) << ", gradients " << to_string(g));
      auto gpu = make_cuda_backend(p);
      set_cuda_step_mode(*gpu, mode);
      set_cuda_gradients(*gpu, g);
      const std::vector<double> ug = run(*gpu);
      if (mode == CudaStepMode::Graph) graph_u = ug;
      const double d = rel_diff(ug, uc);
      report((std::string("law terms, step mode ") + to_string(mode) + ", gradients " + to_string(g)).c_str(), p, d);
      EXPECT_LT(d, p == Precision::Double ? 1e-9 : 1e-3);  // 90 dynamic steps
    }
    {  // the law kernel's second block (of two) loading after its wait, as blocks past the first wave do
      SCOPED_TRACE(::testing::Message() << "later blocks load after their wait, gradients " << to_string(g));
      const ElementFirstWave first_wave(1);
      auto gpu = make_cuda_backend(p);
      set_cuda_step_mode(*gpu, CudaStepMode::Graph);
      set_cuda_gradients(*gpu, g);
      ASSERT_GT(m.n_elems, 256);  // at least two blocks
      EXPECT_EQ(run(*gpu), graph_u);
    }
    {  // the law kernel in the smaller blocks of a launch of several waves, in either mode of loading
       // (passes 1-2 run fused on this box)
      for (const index_t wave : {index_t(-1), index_t(1)}) {
        SCOPED_TRACE(::testing::Message() << "smaller blocks, first wave " << wave << ", gradients " << to_string(g));
        const ElementFirstWave first_wave(wave);
        const SmallElementBlocks small_blocks(true);
        const std::int64_t small_before = cuda_small_element_block_launches().forces;
        auto gpu = make_cuda_backend(p);
        set_cuda_step_mode(*gpu, CudaStepMode::Graph);
        set_cuda_gradients(*gpu, g);
        EXPECT_EQ(run(*gpu), graph_u);
        EXPECT_GT(cuda_small_element_block_launches().forces, small_before);
      }
    }
  }
}

/// The law kernel takes one or two blocks of 256 an SM, so a law model's
/// pass 3 runs in several waves well below 1M tets and then takes the
/// smaller blocks unforced: a mixed-law box of 162,000 elements (633
/// blocks of 256, more than two a multiprocessor on any device of up to
/// 316), from a random displacement, two steps over the whole mesh.
TEST_P(Stages, LawKernelOfSeveralWavesTakesTheSmallerBlocks) {
  SKIP_WITHOUT_GPU();
  const Precision p = GetParam();
  const auto m = build_model(test::mixed_law_box(30, 0.06));
  ASSERT_EQ(m.n_elems, 162000);
  ASSERT_GT((m.n_elems + 255) / 256, 2 * device_attribute(cudaDevAttrMultiProcessorCount));
  for (CudaStepMode mode : {CudaStepMode::Launch, CudaStepMode::Graph}) {
    SCOPED_TRACE(to_string(mode));
    auto gpu = make_cuda_backend(p);
    set_cuda_step_mode(*gpu, mode);
    gpu->upload(m);
    gpu->set_displacements(random_field(m.n_nodes, 1e-5, 41));
    const CudaSmallElementBlockLaunches before = cuda_small_element_block_launches();
    gpu->advance(2);
    const Reductions red = gpu->reduce();
    const CudaSmallElementBlockLaunches after = cuda_small_element_block_launches();
    EXPECT_GT(after.forces, before.forces);
    EXPECT_TRUE(std::isfinite(red.strain_energy));
    EXPECT_GT(red.strain_energy, 0.0);
  }
}

/// Grasp on the device: the nodes in contact when the button goes down
/// follow the tool as it rises, as on the cpu.
TEST_P(Stages, GraspMatchesCpu) {
  SKIP_WITHOUT_GPU();
  const Precision p = GetParam();
  const auto m = box_model(8, 8, 4, 0.04, 0.04, 0.02);
  const ToolShape shape[] = {{"grasper", 0.004, 0.01}};
  auto run = [&](Backend& b) {
    b.upload(m);
    b.set_tools(shape);
    const Vec3<double> c{0.0203, 0.0196, 0.0235};
    ToolMotion mv{{c, {0, 0, 1}}, {c - Vec3<double>{0, 0, 0.001}, {0, 0, 1}}};
    b.move_tools(std::span<const ToolMotion>(&mv, 1));
    b.advance(20);
    mv = {mv.to, {mv.to.tip + Vec3<double>{0, 0, 0.004}, {0, 0.2, 1}}, true};
    b.move_tools(std::span<const ToolMotion>(&mv, 1));
    b.advance(20);
    return std::pair{b.contacts(), b.reduce()};
  };
  auto cpu = make_cpu_backend(p);
  auto gpu = make_cuda_backend(p);
  const auto [cc, rc] = run(*cpu);
  const auto [cg, rg] = run(*gpu);
  ASSERT_GT(rc.tools[0].grasped, 0);
  EXPECT_EQ(rg.tools[0].grasped, rc.tools[0].grasped);
  ASSERT_EQ(cg.size(), cc.size());
  for (size_t k = 0; k < cc.size(); ++k) {
    EXPECT_EQ(cg[k].node, cc[k].node);
    EXPECT_EQ(cg[k].kind, kGrasped);
  }
  EXPECT_LT(rel_diff(gpu->download().u, cpu->download().u), 1e3 * pass_tol(p));
  // the force on the tool is minus the reaction: the lifted tissue pulls the tool down
  EXPECT_GT(rc.tools[0].reaction.z, 0) << "the lifted tissue pulls back";
  EXPECT_GT(rg.tools[0].reaction.z, 0) << "the lifted tissue pulls back";
}

TEST_P(Stages, ReductionsMatchCpuUnderDrivenNodes) {
  SKIP_WITHOUT_GPU();
  const Precision p = GetParam();
  const auto m = box_model(5, 5, 3, 0.05, 0.05, 0.03);
  auto cpu = make_cpu_backend(p), gpu = make_cuda_backend(p);
  const index_t t = m.n_tris / 2;
  const index_t nodes[3] = {m.tris[t], m.tris[m.n_tris + t], m.tris[2 * m.n_tris + t]};
  const double target[9] = {1e-4, -2e-4, -1e-3, 2e-4, 0, -1e-3, -1e-4, 1e-4, -1.2e-3};
  for (int depth : {kDepthAll, 2}) {
    SCOPED_TRACE(depth);
    cpu->upload(m);
    gpu->upload(m);
    const auto u = random_field(m.n_nodes, 5e-5, 17);
    cpu->set_displacements(u);
    gpu->set_displacements(u);
    cpu->build_region(nodes, depth);
    gpu->build_region(nodes, depth);
    cpu->set_driven(nodes, target);
    gpu->set_driven(nodes, target);
    cpu->advance(6);
    gpu->advance(6);
    const Reductions rc = cpu->reduce(), rg = gpu->reduce();
    const double fscale = std::max(norm(rc.reaction), std::sqrt(rc.held_force2));
    ASSERT_GT(norm(rc.reaction), 0.0);
    const double tol = 10 * pass_tol(p);
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(rg.reaction[c], rc.reaction[c], tol * fscale);
      EXPECT_NEAR(rg.internal[c], rc.internal[c], tol * fscale);
    }
    report("reaction", p, norm(rg.reaction - rc.reaction) / fscale);
    EXPECT_NEAR(rg.free_force2, rc.free_force2, 20 * tol * rc.free_force2);
    EXPECT_NEAR(rg.held_force2, rc.held_force2, 20 * tol * rc.held_force2);
    // kinetic energy differences (u - u_prev) / dt of nearly equal values
    EXPECT_NEAR(rg.kinetic, rc.kinetic, (p == Precision::Float ? 1e-2 : 1e-6) * rc.kinetic);
    EXPECT_NEAR(rg.max_disp, rc.max_disp, tol * rc.max_disp);
    EXPECT_TRUE(rg.finite);
    EXPECT_EQ(rg.bad_elem, -1);
    EXPECT_GT(rg.kinetic, 0.0);
    ASSERT_GT(rc.strain_energy, 0.0);
    EXPECT_NEAR(rg.strain_energy, rc.strain_energy, 10 * tol * rc.strain_energy);
    report("strain energy", p, std::fabs(rg.strain_energy - rc.strain_energy) / rc.strain_energy);
    EXPECT_NEAR(rg.front_disp, rc.front_disp, tol * rc.max_disp);
    if (depth != kDepthAll) {
      EXPECT_GT(rc.front_disp, 0.0);
    }
    // release: the reaction sums no node any more
    cpu->clear_driven();
    gpu->clear_driven();
    cpu->advance(2);
    gpu->advance(2);
    EXPECT_EQ(norm(gpu->reduce().reaction), 0.0);
    EXPECT_NEAR(rel_diff(gpu->download().u, cpu->download().u), 0.0, pass_tol(p) * 10);
  }
}

/// A box on rollers (bottom nodes held in z only, one corner fully fixed),
/// three top nodes driven in different components (z; x and z; all, and one
/// of them given twice): u, f and the reductions match the cpu backend, and
/// held components stay exactly at their targets.
TEST_P(Stages, PerComponentConstraintsMatchCpu) {
  SKIP_WITHOUT_GPU();
  const Precision p = GetParam();
  ModelInput in;
  box_mesh(in, 4, 4, 3, 0.04, 0.04, 0.03);
  const double E = 3000, nu = 0.45;
  in.materials = {{E / (2 * (1 + nu)), E / (3 * (1 - 2 * nu)), 1000}};
  in.fixed_axes.assign(in.nodes.size() / 3, 0);
  for (size_t i = 0; i < in.fixed_axes.size(); ++i)
    if (in.nodes[3 * i + 2] == 0.0) in.fixed_axes[i] = kFixedZ >> 2;  // roller: z only
  in.fixed_axes[0] = kAllAxes;                                          // one corner pinned
  in.source = "roller box";
  const auto m = build_model(in);
  const index_t top[3] = {box_node(4, 4, 1, 1, 3), box_node(4, 4, 2, 1, 3), box_node(4, 4, 2, 2, 3)};
  const index_t nodes[4] = {top[0], top[1], top[2], top[1]};
  const double u[12] = {0, 0, -1e-3, 5e-4, 0, -8e-4, 2e-4, 2e-4, -6e-4, 1e-3, 0, -9e-4};
  const std::uint8_t axes[4] = {4, 4, 7, 1};  // top[1]: z, then x given again (union: x and z)
  for (int depth : {kDepthAll, 1}) {
    SCOPED_TRACE(depth);
    auto cpu = make_cpu_backend(p), gpu = make_cuda_backend(p);
    for (Backend* b : {cpu.get(), gpu.get()}) {
      b->upload(m);
      b->set_displacements(random_field(m.n_nodes, 2e-5, 41));
      b->build_region(top, depth);
      b->set_driven_axes(nodes, u, axes);
      b->advance(12);
    }
    const Fields fc = cpu->download(), fg = gpu->download();
    const double du = rel_diff(fg.u, fc.u), df = rel_diff(fg.f, fc.f);
    report("per-component u", p, du);
    EXPECT_LT(du, 10 * pass_tol(p));
    EXPECT_LT(df, 10 * pass_tol(p));
    const index_t n = m.n_nodes;
    EXPECT_EQ(fg.u[2 * n + top[0]], double(p == Precision::Float ? double(float(-1e-3)) : -1e-3));
    if (depth == kDepthAll) {
      EXPECT_EQ(fg.u[n + 0], 0.0);  // the pinned corner (outside a depth-1 region: frozen there)
    }
    for (index_t a = 0; a < n; ++a)
      if (m.X[2 * n + a] == 0.0 && gpu->region().role[a] != kOutside) {
        ASSERT_EQ(fg.u[2 * n + a], 0.0) << "roller node " << a << " left its plane";
      }
    const Reductions rc = cpu->reduce(), rg = gpu->reduce();
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(rg.reaction[c], rc.reaction[c], 10 * pass_tol(p) * norm(rc.reaction));
    EXPECT_NEAR(rg.held_force2, rc.held_force2, 20 * pass_tol(p) * rc.held_force2);
    EXPECT_NEAR(rg.free_force2, rc.free_force2, 20 * pass_tol(p) * rc.free_force2);
    // release: back to the fixed axes only
    cpu->clear_driven();
    gpu->clear_driven();
    cpu->advance(4);
    gpu->advance(4);
    EXPECT_LT(rel_diff(gpu->download().u, cpu->download().u), 10 * pass_tol(p));
    const std::uint8_t bad_axes[1] = {0};
    EXPECT_THROW(gpu->set_driven_axes(std::span<const index_t>(top, 1), std::span<const double>(u, 3), bad_axes),
                 std::invalid_argument);
  }
}

TEST_P(Stages, BadElementFlagNamesLowestInvertedElementAndClears) {
  SKIP_WITHOUT_GPU();
  const Precision p = GetParam();
  const auto m = box_model(3, 3, 3, 0.03, 0.03, 0.03);
  auto cpu = make_cpu_backend(p), gpu = make_cuda_backend(p);
  cpu->upload(m);
  gpu->upload(m);
  std::vector<double> u(3 * size_t(m.n_nodes), 0.0);
  const index_t node = box_node(3, 3, 1, 1, 1);  // interior: pushed through its neighbours
  u[2 * m.n_nodes + node] = -0.018;
  u[node] = 0.004;
  for (Backend* b : {cpu.get(), gpu.get()}) {
    b->set_displacements(u);
    b->element_pressure();
    b->nodal_pressure();
    b->element_forces();
  }
  const Reductions rc = cpu->reduce(), rg = gpu->reduce();
  ASSERT_GE(rc.bad_elem, 0);
  EXPECT_EQ(rg.bad_elem, rc.bad_elem);
  EXPECT_NEAR(rg.bad_J, rc.bad_J, 1e-4 * std::fabs(rc.bad_J) + 1e-6);
  // no element below it is inverted; it is (J <= 0 or its IANP Jbar <= 0)
  const Fields f = gpu->download();
  for (index_t e = 0; e < rg.bad_elem; ++e) EXPECT_GT(f.elem_J[e], 0.0) << "element " << e;
  EXPECT_LE(std::min(f.elem_J[rg.bad_elem], rg.bad_J), 0.0);
  EXPECT_EQ(gpu->reduce().bad_elem, -1);  // read and cleared
}

TEST_P(Stages, WritePositionsWritesDeformedNodesToDeviceMemory) {
  SKIP_WITHOUT_GPU();
  const auto m = box_model(4, 3, 2, 0.04, 0.03, 0.02);
  auto gpu = make_cuda_backend(GetParam());
  gpu->upload(m);
  const auto u = random_field(m.n_nodes, 1e-3, 23);
  gpu->set_displacements(u);
  float* dst = nullptr;
  ASSERT_EQ(cudaMalloc(&dst, 3 * sizeof(float) * m.n_nodes), cudaSuccess);
  ASSERT_EQ(cudaMemset(dst, 0xff, 3 * sizeof(float) * m.n_nodes), cudaSuccess);  // NaN poison
  gpu->write_positions(dst);
  std::vector<float> host(3 * size_t(m.n_nodes));
  ASSERT_EQ(cudaMemcpy(host.data(), dst, host.size() * sizeof(float), cudaMemcpyDeviceToHost), cudaSuccess);
  cudaFree(dst);
  const Fields f = gpu->download();
  for (index_t i = 0; i < m.n_nodes; ++i)
    for (int c = 0; c < 3; ++c)
      ASSERT_NEAR(host[3 * i + c], m.X[c * m.n_nodes + i] + f.u[c * m.n_nodes + i], 1e-6) << "node " << i;
  std::vector<float> on_host(3 * size_t(m.n_nodes));
  EXPECT_THROW(gpu->write_positions(on_host.data()), std::invalid_argument);
}

TEST_P(Stages, EveryStepModeGivesIdenticalBits) {
  SKIP_WITHOUT_GPU();
  const Precision p = GetParam();
  const auto m = box_model(6, 6, 4, 0.06, 0.06, 0.04);
  // the seeds: the top triangle under the tool (a region of depth 2 around it holds the contact)
  const Vec3<double> under_tool{0.031, 0.027, 0.04};
  index_t t = 0;
  double best = 1e300;
  for (index_t k = 0; k < m.n_tris; ++k) {
    Vec3<double> c{0, 0, 0};
    for (int v = 0; v < 3; ++v) {
      const index_t i = m.tris[v * m.n_tris + k];
      c = c + (1.0 / 3.0) * Vec3<double>{m.X[i], m.X[m.n_nodes + i], m.X[2 * m.n_nodes + i]};
    }
    if (norm(c - under_tool) < best) best = norm(c - under_tool), t = k;
  }
  // the region: around that triangle and the driven one (a triangle away from the tool: driven nodes
  // under the tool would be a rigid support, not contact)
  const index_t d = m.n_tris / 3;
  const index_t seeds[6] = {m.tris[t], m.tris[m.n_tris + t], m.tris[2 * m.n_tris + t],
                            m.tris[d], m.tris[m.n_tris + d], m.tris[2 * m.n_tris + d]};
  const index_t driven[3] = {seeds[3], seeds[4], seeds[5]};
  const auto u = random_field(m.n_nodes, 1e-4, 29);
  for (CudaGradients g : {CudaGradients::Stored, CudaGradients::Recomputed})
    for (int depth : {kDepthAll, 2}) {
      std::vector<double> ref_u, ref_f, ref_p, ref_J, ref_energy;
      struct Run {
        CudaStepMode mode;
        bool small_merge;  // the merge in blocks of 64, as on a surface larger than one wave of 256
        bool node_lanes;   // passes 2 and 4 apart, two lanes a thread, as on a region of several waves
      };
      for (const Run run : {Run{CudaStepMode::Grid, false, false}, Run{CudaStepMode::Launch, false, false},
                            Run{CudaStepMode::Graph, false, false}, Run{CudaStepMode::Cluster, false, false},
                            Run{CudaStepMode::Auto, false, false}, Run{CudaStepMode::Graph, true, false},
                            Run{CudaStepMode::Graph, false, true}, Run{CudaStepMode::Launch, false, true}}) {
        const CudaStepMode mode = run.mode;
        SCOPED_TRACE(::testing::Message() << "depth " << depth << " mode " << to_string(mode) << " gradients "
                                          << to_string(g) << (run.small_merge ? ", merge in blocks of 64" : "")
                                          << (run.node_lanes ? ", node passes two lanes a thread" : ""));
        auto gpu = make_cuda_backend(p);
        set_cuda_step_mode(*gpu, mode);
        EXPECT_GT(cuda_merge_wave_nodes(*gpu), m.n_nodes);  // this box's surface: blocks of 256 unless told
        if (run.small_merge) set_cuda_merge_wave_nodes(*gpu, 0);
        set_cuda_gradients(*gpu, g);
        gpu->upload(m);
        EXPECT_GT(cuda_lanes_node_min(*gpu), m.n_nodes);  // a box this small: eight threads a node unless told
        EXPECT_FALSE(cuda_discards_slots(*gpu));  // nor do its slots fill half an L2
        if (run.node_lanes) {  // and pass 4 over the whole mesh drops the slots it has read from the L2
          set_cuda_fused_force_blocks(*gpu, 0);
          set_cuda_lanes_node_min(*gpu, 0);
          set_cuda_discards_slots(*gpu, true);
        }
        gpu->set_displacements(u);
        gpu->build_region(seeds, depth);
        gpu->set_driven(driven, std::vector<double>(9, -5e-4));
        // a probe pressing the top, and a capsule lying across it and sinking in (many triangles, at
        // depth 2 many with corners outside the region: the sweep's lane groups take several each step)
        const ToolShape tool[] = {{"probe", 0.004, 0.01}, {"capsule", 0.003, 0.04}};
        gpu->set_tools(tool);
        const ToolMotion mv[] = {{{{0.031, 0.027, 0.0445}, {0, 0, 1}}, {{0.031, 0.027, 0.0425}, {0, 0, 1}}},
                                 {{{0.008, 0.04, 0.0428}, {0.94, 0.34, 0}}, {{0.009, 0.041, 0.0412}, {0.93, 0.36, 0.05}}}};
        gpu->move_tools(mv);
        const CudaNodePassLaunches before = cuda_node_pass_launches();
        // a reduce between advances (its own passes 1-2 at the current u into scratch) changes nothing in
        // the steps, in any mode
        gpu->advance(7);   // graph: a 7-step graph from phase 0
        std::vector<double> energies = {gpu->reduce().strain_energy};
        gpu->advance(1);   // then phase 1
        energies.push_back(gpu->reduce().strain_energy);
        gpu->advance(33);  // a 30-step chunk and 3 more
        const Reductions r = gpu->reduce();
        energies.push_back(r.strain_energy);
        EXPECT_GT(r.tools[0].contact, 0);
        EXPECT_GT(r.tools[1].contact + r.tools[1].outside, 3);
        // which node kernels ran: pass 4 apart two lanes a thread exactly where told (passes 1-2 stay
        // fused on this box; the persistent modes launch neither)
        const CudaNodePassLaunches after = cuda_node_pass_launches();
        EXPECT_EQ(after.updates_lanes > before.updates_lanes, run.node_lanes);
        EXPECT_EQ(after.pressures_lanes, before.pressures_lanes);
        const Fields f = gpu->download();
        if (ref_u.empty()) {
          ref_u = f.u;
          ref_f = f.f;
          ref_p = f.node_p;
          ref_J = f.elem_J;
          ref_energy = energies;
          continue;
        }
        EXPECT_EQ(f.u, ref_u);
        EXPECT_EQ(f.f, ref_f);
        EXPECT_EQ(f.node_p, ref_p);  // the last step's passes, in every mode
        EXPECT_EQ(f.elem_J, ref_J);
        EXPECT_EQ(energies, ref_energy);
      }
    }
}

/// Elements of node a of m, and the node with the most (the most slots of
/// a node sets the fused kernels' windows: cuda/tled.cuh run_packed).
index_t elements_of(const TissueModel<double>& m, index_t a) { return m.node_elem_start[a + 1] - m.node_elem_start[a]; }
index_t busiest_node(const TissueModel<double>& m) {
  index_t busiest = 0;
  for (index_t a = 0; a < m.n_nodes; ++a)
    if (elements_of(m, a) > elements_of(m, busiest)) busiest = a;
  return busiest;
}

/// A fan of 2 n tets around one centre node, numbered last: a ring of n
/// nodes in the plane z = 0 around it and an apex above and below, each
/// ring segment making a tet with the centre and either apex. The centre
/// touches 2 n elements, the apexes n, the ring nodes 4.
TissueModel<double> fan_model(int n) {
  ModelInput in;
  const double kPi = 3.14159265358979323846;
  for (int i = 0; i < n; ++i) {
    const double a = 2 * kPi * i / n;
    in.nodes.insert(in.nodes.end(), {0.01 * std::cos(a), 0.01 * std::sin(a), 0.0});
  }
  in.nodes.insert(in.nodes.end(), {0, 0, 0.01, 0, 0, -0.01, 0, 0, 0});
  const auto top = index_t(n), bottom = index_t(n + 1), centre = index_t(n + 2);
  for (int i = 0; i < n; ++i) {
    const auto a = index_t(i), b = index_t((i + 1) % n);
    in.tets.insert(in.tets.end(), {centre, a, b, top});
    in.tets.insert(in.tets.end(), {centre, b, a, bottom});
  }
  const double E = 3000, nu = 0.45;
  in.materials = {{E / (2 * (1 + nu)), E / (3 * (1 - 2 * nu)), 1000}};
  in.source = "test fan";
  return build_model(in);
}

/// Passes 1 and 2 as one kernel, and passes 3 and 4 as one (the Launch and
/// Graph modes: passes 1-2 on regions under 10,000 elements, the
/// reduction's too, passes 3-4 on regions whose windows' blocks the device
/// holds at once; docs/cuda.md, "Passes 1 and 2 as one kernel", "Passes 3
/// and 4 as one kernel") against the four passes of the Grid mode and of
/// the Graph mode with passes 3-4 held apart (set_cuda_fused_force_blocks(0)),
/// bit for bit. On the kidney, whose busiest nodes touch more than 32
/// elements (8 lanes sum each node's slots in turns: up to 8 each), with
/// loads on the seeds (the force kernel's load instantiation): over the
/// whole mesh and over a region of depth 2 around the busiest node, whose
/// windows hold nodes outside the region between the region's (slots no
/// thread computes), and in which a driven halo node moves: its elements
/// outside the region (no inner corner) are computed by no kernel, so
/// their slots keep the values of the region's build (the volume change at
/// the build's u, zero force) while the node moves, and the fused kernels
/// must read them, not compute them at the new position. On a box of 15,360
/// elements and 3,179 nodes the chained steps and the reduction run passes
/// 1-2 apart (above the size limit), passes 3-4 fused where the device
/// holds its windows' blocks. On a fan whose last node touches 80 elements
/// (windows of 49 slots: one lies inside that node's slots and holds no
/// node, its block returns at once) both fuse; on a fan whose centre
/// touches 140 (more than a block's 128 threads: no windows) the passes
/// run apart.
TEST_P(Stages, FusedPassesGiveTheSeparatePassesBits) {
  SKIP_WITHOUT_GPU();
  const Precision p = GetParam();
  enum Fuses { kMay, kMust, kNever };  // passes 3-4 in the Graph mode
  struct Case {
    std::string name;
    TissueModel<double> m;
    int depth;
    Fuses fuses;
    bool pressures_apart;  // passes 1-2 as two kernels in the chained steps and the reduction
  };
  std::vector<Case> cases;
  cases.push_back({"kidney, whole mesh", scene::load_model(io::default_kidney_scene()), kDepthAll, kMay, false});
  cases.push_back({"kidney, depth 2 around its busiest node, with a driven halo node", cases[0].m, 2, kMust, false});
  cases.push_back(
      {"box of 15,360 elements, whole mesh", box_model(16, 16, 10, 0.16, 0.16, 0.1), kDepthAll, kMay, true});
  cases.push_back({"fan of 80 elements around its last node", fan_model(40), kDepthAll, kMust, false});
  cases.push_back({"fan of 140 elements around its last node", fan_model(70), kDepthAll, kNever, true});
  ASSERT_EQ(cases[2].m.n_elems, 15360);
  ASSERT_EQ(elements_of(cases[3].m, cases[3].m.n_nodes - 1), 80);
  ASSERT_EQ(elements_of(cases[4].m, cases[4].m.n_nodes - 1), 140);
  const TissueModel<double>& kidney = cases[0].m;
  const index_t busiest = busiest_node(kidney);
  EXPECT_GT(elements_of(kidney, busiest), 32) << "the kidney no longer has a node of more than 32 elements";
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const TissueModel<double>& m = c.m;
    std::vector<index_t> seeds = {m.tris[0], m.tris[m.n_tris], m.tris[2 * m.n_tris]};
    std::vector<index_t> driven;
    std::vector<double> drive;
    if (c.depth != kDepthAll) {  // around the busiest node; a halo node with an element outside the region
      seeds = {busiest};
      const Region region = flood_fill(m, seeds, c.depth);
      ASSERT_EQ(region.role[busiest], kInner);
      for (index_t a : region.nodes) {
        if (region.role[a] != kHalo) continue;
        bool outside = false;
        for (index_t k = m.node_elem_start[a]; k < m.node_elem_start[a + 1]; ++k)
          outside = outside || !std::binary_search(region.elems.begin(), region.elems.end(), incident_element(m.node_elem[k]));
        if (outside) {
          driven = {a};
          drive = {2e-4, -1e-4, 1e-4};
          break;
        }
      }
      ASSERT_FALSE(driven.empty());
    }
    const auto u = random_field(m.n_nodes, 1e-5, 37);
    std::vector<double> ref_u, ref_f, ref_p, ref_J, ref_energy;
    struct Run {
      CudaStepMode mode;
      bool apart;       // passes 3-4 held apart
      bool node_lanes;  // and the node passes two lanes a thread
      bool late;        // every block of passes 1 and 3 but the first loads after its wait (in double:
                        // of pass 3's streaming kernel only)
      bool streaming;   // pass 3 (apart) in its streaming kernel
      bool small;       // passes 1 and 3 in the smaller blocks of a launch of several waves
    };
    for (const Run run : {Run{CudaStepMode::Grid, false, false, false, false, false},
                          Run{CudaStepMode::Graph, false, false, false, false, false},
                          Run{CudaStepMode::Launch, false, false, false, false, false},
                          Run{CudaStepMode::Graph, true, false, false, false, false},
                          Run{CudaStepMode::Graph, true, true, false, false, false},
                          Run{CudaStepMode::Launch, true, true, false, false, false},
                          Run{CudaStepMode::Graph, true, false, true, false, false},
                          Run{CudaStepMode::Launch, true, false, false, true, false},
                          Run{CudaStepMode::Graph, true, true, true, true, false},
                          Run{CudaStepMode::Graph, true, false, true, false, true},
                          Run{CudaStepMode::Launch, true, true, false, false, true}}) {
      if (run.late && !run.streaming && p == Precision::Double) continue;  // double's kernels have no late path
      SCOPED_TRACE(::testing::Message() << to_string(run.mode) << (run.apart ? ", passes 3-4 apart" : "")
                                        << (run.node_lanes ? ", node passes two lanes a thread" : "")
                                        << (run.late ? ", element passes' later blocks load after their wait" : "")
                                        << (run.streaming ? ", pass 3's streaming kernel" : "")
                                        << (run.small ? ", element passes in smaller blocks" : ""));
      const ElementFirstWave first_wave(run.late ? 1 : -1);
      const SmallElementBlocks small_blocks(run.small);
      auto gpu = make_cuda_backend(p);
      set_cuda_step_mode(*gpu, run.mode);
      if (run.apart) set_cuda_fused_force_blocks(*gpu, 0);
      // a region whose slots fill half the L2 streams them in double (float has no streaming kernel);
      // told here, so that the runs do not depend on the device's L2
      if (p == Precision::Float) {
        EXPECT_EQ(cuda_streaming_elems(*gpu), 0);
      } else {
        EXPECT_GT(cuda_streaming_elems(*gpu), 0);
      }
      set_cuda_streaming_elems(*gpu, run.streaming ? 1 : 0);
      gpu->upload(m);
      if (run.node_lanes) {  // and pass 4 over the whole mesh drops the slots it has read from the L2
        set_cuda_lanes_node_min(*gpu, 0);
        set_cuda_discards_slots(*gpu, true);
      }
      gpu->set_displacements(u);
      gpu->build_region(seeds, c.depth);
      if (run.mode == CudaStepMode::Graph) {
        const bool fused = cuda_fuses_forces(*gpu);
        if (run.apart || c.fuses == kNever) {
          EXPECT_FALSE(fused);
        } else {
          if (c.fuses == kMust) {
            EXPECT_TRUE(fused) << "the fused force kernel did not run";
          }
          std::printf("[measured] %s (%s): passes 3-4 %s (the device holds %d of its blocks)\n", c.name.c_str(),
                      p == Precision::Float ? "float" : "double", fused ? "fused" : "apart",
                      int(cuda_fused_force_blocks(*gpu)));
        }
      }
      if (!driven.empty()) gpu->set_driven(driven, drive);
      if (m.n_elems < 10000) {  // the kidney: loads on the seeds (region nodes at any depth)
        const double force[9] = {0.02, -0.01, 0.03, -0.02, 0.0, 0.01, 0.0, 0.04, -0.03};
        gpu->set_loads(seeds, std::span<const double>(force, 3 * seeds.size()));
      }
      const CudaNodePassLaunches before = cuda_node_pass_launches();
      const std::int64_t streaming_before = cuda_streaming_force_launches();
      const CudaSmallElementBlockLaunches small_before = cuda_small_element_block_launches();
      gpu->advance(5);
      std::vector<double> energies = {gpu->reduce().strain_energy};
      gpu->advance(4);
      energies.push_back(gpu->reduce().strain_energy);
      gpu->advance(1);
      const Fields f = gpu->download();
      ASSERT_TRUE(std::isfinite(energies.back()));
      // which node kernels ran: pass 4 two lanes a thread exactly where told, and pass 2 where passes
      // 1-2 run apart (the box of 15,360 elements and the fan of 140, which has no windows: the
      // reduction's in every mode, the steps' too in the chained ones)
      const CudaNodePassLaunches after = cuda_node_pass_launches();
      const bool chained = run.mode != CudaStepMode::Grid;
      EXPECT_EQ(after.updates_lanes > before.updates_lanes, run.node_lanes);
      EXPECT_EQ(after.updates > before.updates, chained && !run.node_lanes && !cuda_fuses_forces(*gpu));
      EXPECT_EQ(after.pressures_lanes > before.pressures_lanes, run.node_lanes && c.pressures_apart);
      EXPECT_EQ(after.pressures > before.pressures, !run.node_lanes && c.pressures_apart);
      EXPECT_EQ(cuda_streaming_force_launches() > streaming_before,
                run.streaming && chained && !cuda_fuses_forces(*gpu));
      // smaller blocks where told: pass 3 (every such run holds it apart) and pass 1 where passes 1-2
      // run apart; else none: these regions' element passes, at most 60 blocks of 256, fit one wave
      // on a device of 60 SMs or more (one block an SM would do)
      if (run.small || device_attribute(cudaDevAttrMultiProcessorCount) >= 60) {
        const CudaSmallElementBlockLaunches small_after = cuda_small_element_block_launches();
        EXPECT_EQ(small_after.forces > small_before.forces, run.small);
        EXPECT_EQ(small_after.pressures > small_before.pressures, run.small && c.pressures_apart);
      }
      if (ref_u.empty()) {
        ref_u = f.u, ref_f = f.f, ref_p = f.node_p, ref_J = f.elem_J, ref_energy = energies;
        if (!driven.empty()) {  // the driven node moved: the test has its stale slots
          const index_t a = driven[0];
          EXPECT_NE(f.u[a], u[a]);
        }
        continue;
      }
      EXPECT_EQ(f.u, ref_u);
      EXPECT_EQ(f.f, ref_f);
      EXPECT_EQ(f.node_p, ref_p);
      EXPECT_EQ(f.elem_J, ref_J);
      EXPECT_EQ(energies, ref_energy);
    }
  }
}

/// The fused force pass records a bad element as pass 3 does (corner 0's
/// visit of each element; the lowest element wins): a kidney node pushed
/// through its neighbours, one step over a region of depth 2 around it (a
/// region the force kernel fuses in either precision) in each mode, with
/// several elements inverted: the same element and J from the reduction as
/// the Grid mode's four passes, and the same bits; the same element as the
/// cpu's step.
TEST_P(Stages, FusedForcePassRecordsTheLowestBadElement) {
  SKIP_WITHOUT_GPU();
  const Precision p = GetParam();
  const auto m = scene::load_model(io::default_kidney_scene());
  ASSERT_LT(m.n_elems, 10000);  // the fused kernels' size
  // the node with the most elements, pushed 3 cm: several of its elements invert
  const index_t node = busiest_node(m);
  const index_t seeds[1] = {node};
  std::vector<double> u(3 * size_t(m.n_nodes), 0.0);
  u[node] = 0.03;
  u[2 * size_t(m.n_nodes) + node] = -0.02;
  index_t ref_bad = -2;
  double ref_J = 0;
  std::vector<double> ref_u;
  for (CudaStepMode mode : {CudaStepMode::Grid, CudaStepMode::Graph, CudaStepMode::Launch}) {
    SCOPED_TRACE(to_string(mode));
    auto gpu = make_cuda_backend(p);
    set_cuda_step_mode(*gpu, mode);
    gpu->upload(m);
    gpu->set_displacements(u);
    gpu->build_region(seeds, 2);
    if (mode == CudaStepMode::Graph) {
      EXPECT_TRUE(cuda_fuses_forces(*gpu));
    }
    gpu->advance(1);
    const Reductions r = gpu->reduce();
    const Fields f = gpu->download();
    if (ref_bad == -2) {
      ASSERT_GE(r.bad_elem, 0) << "no element inverted: the test pushes too little";
      int inverted = 0;  // several: the lowest must win
      for (double J : f.elem_J) inverted += J <= 0 ? 1 : 0;
      EXPECT_GT(inverted, 1);
      auto cpu = make_cpu_backend(p);
      cpu->upload(m);
      cpu->set_displacements(u);
      cpu->build_region(seeds, 2);
      cpu->advance(1);
      const Reductions rc = cpu->reduce();
      EXPECT_EQ(r.bad_elem, rc.bad_elem);
      EXPECT_NEAR(r.bad_J, rc.bad_J, 1e-4 * std::fabs(rc.bad_J) + 1e-6);
      ref_bad = r.bad_elem, ref_J = r.bad_J, ref_u = f.u;
      continue;
    }
    EXPECT_EQ(r.bad_elem, ref_bad);
    EXPECT_EQ(r.bad_J, ref_J);
    EXPECT_EQ(f.u, ref_u);
  }
}

/// The steps after a reduction take its passes 1-2 (run at the current u
/// into the scratch set of pass arrays) as their first step's, and start
/// at pass 3 (docs/cuda.md, "Passes 1-2 taken from the reduction"). Against
/// the same calls with a per-pass element_pressure() before every advance,
/// which makes the steps compute passes 1-2 themselves: the same bits in
/// every step mode, over the whole mesh and a region of depth 2 (whose
/// scratch set must hold the state's entries outside the region), through
/// advance, advance_reduce (one graph per tick) and the checked tick (whose
/// first pass 3 runs beside the region's check), with one step and with
/// more than a graph holds, after a tick the check refuses and after the
/// region is built again. In double the graph mode's run is also compared
/// with the cpu's (its take_passes), downloads included. A step that started
/// at pass 3 without the reduction's arrays, or with arrays left from before
/// the last step, would move every node of the region differently.
TEST_P(Stages, StepsTakingTheReductionsPassesGiveTheSameBits) {
  SKIP_WITHOUT_GPU();
  const Precision p = GetParam();
  const auto m = box_model(6, 6, 4, 0.06, 0.06, 0.04);
  const TissueModel<double> visco = [&] {  // the same box, viscoelastic (the law kernel's pass 3)
    ModelInput in;
    box_mesh(in, 6, 6, 4, 0.06, 0.06, 0.04);
    MaterialParams law{3000 / 2.9, 3000 / 0.3, 1000};
    law.prony_terms = 1;
    law.prony_g[0] = 0.3, law.prony_tau[0] = 0.01;
    in.materials = {law};
    in.fixed.assign(in.nodes.size() / 3, 0);
    for (size_t i = 0; i < in.fixed.size(); ++i) in.fixed[i] = in.nodes[3 * i + 2] == 0.0;
    return build_model(in);
  }();
  ASSERT_TRUE(visco.has_visco());
  const auto u = random_field(m.n_nodes, 1e-4, 31);
  const ToolShape tool[] = {{"probe", 0.004, 0.01}};
  const Vec3<double> z{0, 0, 1};
  struct Run {
    std::vector<double> energy, kinetic, free2, reaction_z;
    std::vector<Fields> fields;
  };
  auto run = [&](Backend& b, int depth, bool own_passes, const TissueModel<double>* model = nullptr) {
    b.upload(model ? *model : m);
    b.set_displacements(u);
    b.set_tools(tool);
    ToolPose at{{0.031, 0.027, 0.0445}, z};
    auto move = [&](Vec3<double> d) {
      const ToolMotion mv{at, {at.tip + d, z}};
      b.move_tools(std::span<const ToolMotion>(&mv, 1));
      at = mv.to;
    };
    const auto down = [](double dz) { return Vec3<double>{0, 0, dz}; };
    move(down(0));
    if (depth != kDepthAll) {  // the region: depth 2 around the surface under the tool
      b.build_region({}, depth);
      b.build_region(b.contact_candidates(), depth);
      EXPECT_LT(b.region().elems.size(), size_t(m.n_elems));
      EXPECT_GT(b.region().n_halo, 0);
    }
    Run out;
    auto record = [&](const Reductions& r) {
      out.energy.push_back(r.strain_energy);
      out.kinetic.push_back(r.kinetic);
      out.free2.push_back(r.free_force2);
      out.reaction_z.push_back(r.tools[0].reaction.z);
      out.fields.push_back(b.download());
    };
    // before steps: with own_passes, pass 1 run alone, so that the steps run passes 1-2 themselves (its
    // J_e, at this u, are the ones their first pass 1 writes again)
    auto steps_follow = [&] {
      if (own_passes) b.element_pressure();
    };
    move(down(-5e-4));
    b.advance(3);
    record(b.reduce());
    move(down(-2e-4));
    steps_follow();
    b.advance(1);  // one step: its pass arrays are the reduction's, and download() shows them
    out.fields.push_back(b.download());
    record(b.reduce());
    record(b.reduce());  // twice at one u
    move(down(-5e-4));
    steps_follow();
    b.advance(31);  // more than one graph holds: only the first starts at pass 3
    record(b.reduce());
    for (int tick = 0; tick < 3; ++tick) {
      move(down(-2e-4));
      steps_follow();
      record(b.advance_reduce(tick == 1 ? 1 : 4));
    }
    move(down(-1e-4));
    steps_follow();
    const std::optional<Reductions> checked = b.advance_reduce_in_region(4);
    EXPECT_TRUE(checked.has_value()) << "the tool stays inside its region";
    if (checked) record(*checked);
    if (depth != kDepthAll) {  // a slide out of the region: refused, nothing runs, the tool stays
      const ToolPose stay = at;
      move({0.02, 0, 0});
      const Fields before = b.download();
      EXPECT_FALSE(b.advance_reduce_in_region(4).has_value());
      const Fields after = b.download();
      EXPECT_EQ(after.u, before.u);
      EXPECT_EQ(after.f, before.f);
      EXPECT_EQ(after.node_p, before.node_p);  // the sets swapped back
      EXPECT_EQ(after.elem_J, before.elem_J);
      out.fields.push_back(after);
      at = stay;
      move(down(-1e-4));
      steps_follow();
      b.advance(2);  // the checked tick's reduction still holds: these steps start at pass 3
      out.fields.push_back(b.download());
      record(b.reduce());
    }
    b.build_region(b.region().seeds, depth);  // the state's arrays rewritten whole: the next reduction copies them
    record(b.reduce());
    steps_follow();
    b.advance(2);
    out.fields.push_back(b.download());
    EXPECT_GT(out.reaction_z.size(), 6u);
    EXPECT_NE(out.reaction_z.back(), 0.0) << "the tool presses the top";
    return out;
  };
  auto expect_same = [](const Run& a, const Run& b) {
    EXPECT_EQ(a.energy, b.energy);
    EXPECT_EQ(a.kinetic, b.kinetic);
    EXPECT_EQ(a.free2, b.free2);
    EXPECT_EQ(a.reaction_z, b.reaction_z);
    ASSERT_EQ(a.fields.size(), b.fields.size());
    for (size_t k = 0; k < b.fields.size(); ++k) {
      SCOPED_TRACE(k);
      EXPECT_EQ(a.fields[k].u, b.fields[k].u);
      EXPECT_EQ(a.fields[k].f, b.fields[k].f);
      EXPECT_EQ(a.fields[k].node_p, b.fields[k].node_p);  // download() sees the last step's passes
      EXPECT_EQ(a.fields[k].elem_J, b.fields[k].elem_J);
    }
  };
  for (int depth : {kDepthAll, 2}) {
    Run cpu;
    if (p == Precision::Double) cpu = run(*make_cpu_backend(p), depth, false);
    Run graph;
    for (CudaStepMode mode : {CudaStepMode::Launch, CudaStepMode::Graph, CudaStepMode::Grid, CudaStepMode::Cluster}) {
      SCOPED_TRACE(::testing::Message() << "depth " << depth << " mode " << to_string(mode));
      auto taken_b = make_cuda_backend(p), own_b = make_cuda_backend(p);
      set_cuda_step_mode(*taken_b, mode);
      set_cuda_step_mode(*own_b, mode);
      const Run taken = run(*taken_b, depth, false), own = run(*own_b, depth, true);
      expect_same(taken, own);
      if (mode == CudaStepMode::Graph) graph = taken;
      if (p != Precision::Double || mode != CudaStepMode::Graph) continue;
      ASSERT_EQ(cpu.fields.size(), taken.fields.size());
      double worst = 0;
      for (size_t k = 0; k < cpu.fields.size(); ++k) {
        SCOPED_TRACE(k);
        for (auto [g, c] : {std::pair{&taken.fields[k].u, &cpu.fields[k].u}, std::pair{&taken.fields[k].f, &cpu.fields[k].f},
                            std::pair{&taken.fields[k].node_p, &cpu.fields[k].node_p}}) {
          const double d = rel_diff(*g, *c);
          worst = std::max(worst, d);
          EXPECT_LT(d, 1e-9);
        }
        const double dJ = rel_diff(minus_one(taken.fields[k].elem_J), minus_one(cpu.fields[k].elem_J));
        worst = std::max(worst, dJ);
        EXPECT_LT(dJ, 1e-9);
      }
      for (size_t k = 0; k < cpu.energy.size(); ++k) {  // the reductions too
        EXPECT_NEAR(taken.energy[k], cpu.energy[k], 1e-9 * std::fabs(cpu.energy[k]));
        EXPECT_NEAR(taken.reaction_z[k], cpu.reaction_z[k], 1e-9 * std::fabs(cpu.reaction_z[k]) + 1e-15);
      }
      report("passes taken from the reduction, graph against the cpu", p, worst);
    }
    // every block of pass 3 (apart: in float its kernel, in double its streaming kernel) loading after
    // its wait, as blocks past the first wave do: the Graph run's bits, and nothing stored in the tick
    // the check refuses (those blocks must honour the skip after their wait)
    SCOPED_TRACE(::testing::Message() << "depth " << depth << ", graph, pass 3 apart, every block waiting first");
    const ElementFirstWave first_wave(0);
    auto taken_b = make_cuda_backend(p), own_b = make_cuda_backend(p);
    for (Backend* b : {taken_b.get(), own_b.get()}) {
      set_cuda_step_mode(*b, CudaStepMode::Graph);
      set_cuda_fused_force_blocks(*b, 0);
      if (p == Precision::Double) set_cuda_streaming_elems(*b, 1);
    }
    const std::int64_t streaming_before = cuda_streaming_force_launches();
    const Run taken = run(*taken_b, depth, false), own = run(*own_b, depth, true);
    expect_same(taken, own);
    expect_same(taken, graph);
    EXPECT_EQ(cuda_streaming_force_launches() > streaming_before, p == Precision::Double);
    // the law kernel (late in both precisions): a Prony state moved by the refused tick's blocks would
    // change every tick after it
    auto law_late_b = make_cuda_backend(p);
    set_cuda_step_mode(*law_late_b, CudaStepMode::Graph);
    const Run law_late = run(*law_late_b, depth, false, &visco);
    set_cuda_element_first_wave(-1);
    auto law_graph_b = make_cuda_backend(p);
    set_cuda_step_mode(*law_graph_b, CudaStepMode::Graph);
    expect_same(law_late, run(*law_graph_b, depth, false, &visco));
  }
}

/// Element gradients recomputed from double reference positions at every
/// pass (CudaGradients::Recomputed) against the stored ones and the cpu
/// (which loads the model's gradients rounded to T): 60 steps from a rough
/// random field, then the reductions. Sixty steps of that field amplify any
/// rounding difference alike (measured on an H100 in float: recomputed
/// against stored 3.0e-5 in u, 4.9e-5 in J - 1, 7.9e-5 in strain energy,
/// against the cpu 3.3e-5, where stored against the cpu is 3.5e-5; double
/// 5e-14 to 7e-13), hence the looser float bound here than pass_tol's
/// single pass; one pass 1 on a box 0.1 m from the origin is checked at
/// 1e-5. Auto: a small mesh loads them (identical bits to Stored), a whole
/// mesh of kRecomputeMinElements or more recomputes them (identical bits to
/// Recomputed) while a small region of it loads them (identical bits to
/// Stored, its whole-mesh pass 1 and energies included), and a large mesh
/// with a sliver keeps only the stored ones in float, where Recomputed
/// refuses it naming the sliver.
TEST_P(Stages, RecomputedGradientsMatchStoredOnes) {
  SKIP_WITHOUT_GPU();
  const Precision p = GetParam();
  const double tol = p == Precision::Double ? 1e-11 : 3e-4;
  auto step = [&](Backend& b, const TissueModel<double>& m, const std::vector<double>& u) {
    b.upload(m);
    b.set_displacements(u);
    b.advance(60);
    const Reductions r = b.reduce();
    return std::pair{b.download(), r};
  };
  struct Run {
    CudaGradients used;
    Fields fields;
    Reductions red;
  };
  auto run = [&](CudaGradients g, const TissueModel<double>& m, const std::vector<double>& u) {
    auto gpu = make_cuda_backend(p);
    set_cuda_gradients(*gpu, g);
    EXPECT_EQ(cuda_gradients(*gpu), g);  // before an upload: the selection
    auto [f, r] = step(*gpu, m, u);
    return Run{cuda_gradients(*gpu), std::move(f), r};
  };
  const auto m = box_model(6, 5, 4, 0.06, 0.05, 0.04);
  const auto u = random_field(m.n_nodes, 2e-4, 3);
  const Run stored = run(CudaGradients::Stored, m, u), recomputed = run(CudaGradients::Recomputed, m, u),
            automatic = run(CudaGradients::Auto, m, u);
  EXPECT_EQ(stored.used, CudaGradients::Stored);
  EXPECT_EQ(recomputed.used, CudaGradients::Recomputed);
  EXPECT_EQ(automatic.used, CudaGradients::Stored);  // 720 elements
  EXPECT_EQ(automatic.fields.u, stored.fields.u);
  ASSERT_GT(*std::max_element(stored.fields.elem_J.begin(), stored.fields.elem_J.end()), 1.0);
  const double du = rel_diff(recomputed.fields.u, stored.fields.u);
  const double dJ = rel_diff(minus_one(recomputed.fields.elem_J), minus_one(stored.fields.elem_J));
  const double dE = std::fabs(recomputed.red.strain_energy - stored.red.strain_energy) / stored.red.strain_energy;
  report("recomputed against stored gradients, u after 60 steps", p, du);
  report("recomputed against stored gradients, J - 1", p, dJ);
  report("recomputed against stored gradients, strain energy", p, dE);
  EXPECT_GT(du, 0.0);  // really another computation
  EXPECT_LT(du, tol);
  EXPECT_LT(dJ, tol);
  EXPECT_LT(dE, tol);
  EXPECT_TRUE(recomputed.red.finite);
  auto cpu = make_cpu_backend(p);
  const auto [fc, rc] = step(*cpu, m, u);
  report("stored gradients against the cpu, u after 60 steps", p, rel_diff(stored.fields.u, fc.u));
  const double dc = rel_diff(recomputed.fields.u, fc.u);
  report("recomputed gradients against the cpu, u after 60 steps", p, dc);
  EXPECT_LT(dc, tol);
  EXPECT_THROW(set_cuda_gradients(*cpu, CudaGradients::Stored), std::invalid_argument);
  EXPECT_THROW(cuda_gradients(*cpu), std::invalid_argument);

  // a mesh of kRecomputeMinElements or more: Auto recomputes over the whole
  // mesh, with Recomputed's bits, and loads over a small region
  const auto big = box_model(21, 20, 20, 0.105, 0.1, 0.1);
  ASSERT_GE(big.n_elems, kRecomputeMinElements);
  const auto ub = random_field(big.n_nodes, 2e-4, 5);
  const Run big_auto = run(CudaGradients::Auto, big, ub), big_recomputed = run(CudaGradients::Recomputed, big, ub);
  EXPECT_EQ(big_auto.used, CudaGradients::Recomputed);
  EXPECT_EQ(big_auto.fields.u, big_recomputed.fields.u);
  {
    // a region of depth 2 loads them, and its pass 1 over the whole mesh (after the build, as after new
    // displacements) too: Auto's bits are Stored's, the steps and the reductions alike
    const index_t seeds[3] = {big.tris[0], big.tris[big.n_tris], big.tris[2 * big.n_tris]};
    std::vector<double> ref_u, ref_J, ref_energy;
    for (CudaGradients g : {CudaGradients::Stored, CudaGradients::Auto}) {
      SCOPED_TRACE(to_string(g));
      auto gpu = make_cuda_backend(p);
      set_cuda_gradients(*gpu, g);
      gpu->upload(big);
      EXPECT_EQ(cuda_gradients(*gpu), g == CudaGradients::Auto ? CudaGradients::Recomputed : CudaGradients::Stored);
      gpu->build_region(seeds, 2);
      EXPECT_EQ(cuda_gradients(*gpu), CudaGradients::Stored);
      gpu->set_displacements(ub);
      gpu->advance(20);
      const double energy = gpu->reduce().strain_energy;
      const Fields f = gpu->download();
      if (ref_u.empty()) {
        ref_u = f.u;
        ref_J = f.elem_J;
        ref_energy = {energy};
        continue;
      }
      EXPECT_EQ(f.u, ref_u);
      EXPECT_EQ(f.elem_J, ref_J);
      EXPECT_EQ(std::vector<double>{energy}, ref_energy);
      gpu->build_region({}, kDepthAll);
      EXPECT_EQ(cuda_gradients(*gpu), CudaGradients::Recomputed);
    }
  }

  // one pass 1 on a box 0.1 m from the origin (1 mm cells): the gradients from edges differenced in double
  // give the J of the stored ones to float rounding
  {
    ModelInput in;
    box_mesh(in, 6, 6, 6, 0.006, 0.006, 0.006);
    in.materials = {{1000, 20000, 1000}};
    for (size_t i = 0; i < in.nodes.size(); ++i) in.nodes[i] += 0.1 + 0.01 * double(i % 3);
    const TissueModel<double> off = build_model(in);
    const auto uo = random_field(off.n_nodes, 2e-5, 9);  // strains of a few percent
    std::vector<double> J[2];
    int k = 0;
    for (CudaGradients g : {CudaGradients::Stored, CudaGradients::Recomputed}) {
      auto gpu = make_cuda_backend(p);
      set_cuda_gradients(*gpu, g);
      gpu->upload(off);
      gpu->set_displacements(uo);  // pass 1 over every element
      J[k++] = gpu->download().elem_J;
    }
    ASSERT_GT(*std::max_element(J[0].begin(), J[0].end()), 1.01);
    const double dJ = rel_diff(minus_one(J[1]), minus_one(J[0]));
    report("recomputed against stored gradients, one pass 1 at 0.1 m, J - 1", p, dJ);
    EXPECT_LT(dJ, p == Precision::Double ? 1e-12 : 1e-5);
  }

  // the same large mesh with a sliver beside it (tests/sliver.hpp): in float Auto keeps only the stored
  // gradients, and Recomputed is refused naming the sliver
  ModelInput in;
  box_mesh(in, 21, 20, 20, 0.105, 0.1, 0.1);
  in.materials = {{1000, 20000, 1000}};
  const index_t sliver = test::append_sliver(in, {0.2, 0.0, 0.0});
  const TissueModel<double> with_sliver = build_model(in);
  auto gpu = make_cuda_backend(p);
  gpu->upload(with_sliver);
  EXPECT_EQ(cuda_gradients(*gpu), p == Precision::Float ? CudaGradients::Stored : CudaGradients::Recomputed);
  gpu->advance(3);
  EXPECT_TRUE(gpu->reduce().finite);
  // Recomputed forced on a model: refused in float with a message holding every part, taken in double
  auto expect_refused_in_float = [&](const TissueModel<double>& model, const std::vector<std::string>& parts) {
    auto forced = make_cuda_backend(p);
    set_cuda_gradients(*forced, CudaGradients::Recomputed);
    if (p == Precision::Float) {
      try {
        forced->upload(model);
        ADD_FAILURE() << "recomputed gradients straying by more than the tolerance were accepted";
      } catch (const std::invalid_argument& e) {
        const std::string what = e.what();
        for (const std::string& part : parts)
          EXPECT_NE(what.find(part), std::string::npos) << part << " not in: " << what;
      }
    } else {
      forced->upload(model);
      EXPECT_EQ(cuda_gradients(*forced), CudaGradients::Recomputed);
    }
  };
  expect_refused_in_float(with_sliver,
                          {"gradients 'recomputed'", "element " + std::to_string(sliver), "sliver", "'stored'"});

  // a large mesh of 20-micrometre cells with one tet 3 m away: float's reference grid (a step of 2^-29 m,
  // 9.3e-5 of a cell; core ReferenceGrid) is too coarse for its cells, so in float Auto keeps the stored
  // gradients and Recomputed is refused naming the grid; double recomputes from its coordinates
  {
    constexpr double kCell = 2e-5;
    ModelInput fine;
    box_mesh(fine, 21, 20, 20, 21 * kCell, 20 * kCell, 20 * kCell);
    fine.materials = {{1000, 20000, 1000}};
    test::append_corner_tet(fine, {3.0, 0.0, 0.0}, kCell);
    const TissueModel<double> wide = build_model(fine);
    ASSERT_GE(wide.n_elems, kRecomputeMinElements);
    auto automatic_wide = make_cuda_backend(p);
    automatic_wide->upload(wide);
    EXPECT_EQ(cuda_gradients(*automatic_wide),
              p == Precision::Float ? CudaGradients::Stored : CudaGradients::Recomputed);
    expect_refused_in_float(wide, {"gradients 'recomputed'", "reference grid", "1.86265e-09 m", "'stored'"});
  }
}

TEST_P(Stages, PerTickTrafficIsFixedAndIndependentOfMeshSize) {
  SKIP_WITHOUT_GPU();
  const Precision p = GetParam();
  const size_t scalar = p == Precision::Float ? 4 : 8;
  // the tools' motion crosses as the head of ContactTools and one ToolStep
  const size_t tools_up = scalar == 4 ? offsetof(ContactTools<float>, tool) + sizeof(ToolStep<float>)
                                      : offsetof(ContactTools<double>, tool) + sizeof(ToolStep<double>);
  const Vec3<double> target = {0.0131, 0.0162, 0.022};  // a 2 mm sphere touching the top
  std::vector<TransferCounters> totals;
  for (int cells : {4, 12}) {
    for (int depth : {kDepthAll, 2}) {
      SCOPED_TRACE(::testing::Message() << cells << " cells, depth " << depth);
      const auto m = box_model(cells, cells, cells / 2, 0.04, 0.04, 0.02);
      auto gpu = make_cuda_backend(p);
      gpu->upload(m);
      SchedulerSettings st;
      st.depth = depth;
      Scheduler sched(*gpu, m, st);
      ScriptedDevice tool(press_path(target, {0, 0, -1}, 0.003, 0.005, 0.05, 0.1, 0.1, 0.05));
      const TransferCounters start = gpu->transfers();
      int steady = 0;
      while (sched.time() < 0.4 - 1e-9) {
        const TransferCounters before = gpu->transfers();
        const RegionSizes region_before = sched.region();
        sched.tick(tool);
        const TransferCounters after = gpu->transfers();
        const RegionSizes& r = sched.region();
        const bool rebuilt = r.n_inner != region_before.n_inner || r.n_halo != region_before.n_halo ||
                             r.n_elems != region_before.n_elems;
        const auto h2d = after.h2d - before.h2d, d2h = after.d2h - before.d2h;
        const auto h2d_bytes = after.h2d_bytes - before.h2d_bytes, d2h_bytes = after.d2h_bytes - before.d2h_bytes;
        if (rebuilt) {  // the checked graph that did nothing (3), the candidates' list, the seeds, the region's
                        // counts, then the tick's graph (2)
          EXPECT_LE(h2d + d2h, 9u);
          continue;
        }
        ++steady;
        EXPECT_EQ(h2d, 1u);  // the tools' motion
        EXPECT_EQ(h2d_bytes, tools_up);
        // the reductions, plus the region check's answer while the region is limited
        EXPECT_EQ(d2h, depth == kDepthAll ? 1u : 2u);
        EXPECT_EQ(d2h_bytes, sizeof(Reductions) + (depth == kDepthAll ? 0 : sizeof(int)));
      }
      EXPECT_GT(steady, 350);
      const TransferCounters end = gpu->transfers();
      if (depth == kDepthAll)
        totals.push_back({end.h2d - start.h2d, end.d2h - start.d2h, end.h2d_bytes - start.h2d_bytes,
                          end.d2h_bytes - start.d2h_bytes});
      std::printf("[measured] %d cells (%d tets), depth %d: %llu h2d (%llu B), %llu d2h (%llu B) over %ld ticks\n",
                  cells, m.n_elems, depth, (unsigned long long)(end.h2d - start.h2d),
                  (unsigned long long)(end.h2d_bytes - start.h2d_bytes), (unsigned long long)(end.d2h - start.d2h),
                  (unsigned long long)(end.d2h_bytes - start.d2h_bytes), sched.ticks());
    }
  }
  EXPECT_EQ(totals[0].h2d, totals[1].h2d);
  EXPECT_EQ(totals[0].d2h, totals[1].d2h);
  EXPECT_EQ(totals[0].h2d_bytes, totals[1].h2d_bytes);
  EXPECT_EQ(totals[0].d2h_bytes, totals[1].d2h_bytes);
}

TEST_P(Stages, BadInputGivesClearErrors) {
  SKIP_WITHOUT_GPU();
  auto gpu = make_cuda_backend(GetParam());
  EXPECT_THROW(gpu->advance(1), std::logic_error);  // before upload
  const auto m = box_model(4, 4, 2, 0.04, 0.04, 0.02);
  gpu->upload(m);
  const index_t n = m.n_nodes;
  EXPECT_THROW(gpu->set_displacements(std::vector<double>(3 * n - 1, 0.0)), std::invalid_argument);
  std::vector<double> u(3 * size_t(n), 0.0);
  u[5] = std::nan("");
  try {
    gpu->set_displacements(u);
    ADD_FAILURE() << "NaN displacement accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("node 5"), std::string::npos) << e.what();
  }
  const index_t bad_node[1] = {n};
  const double target[3] = {0, 0, 0};
  EXPECT_THROW(gpu->set_driven(bad_node, target), std::invalid_argument);
  const index_t one[1] = {3};
  const double nan3[3] = {0, std::nan(""), 0};
  EXPECT_THROW(gpu->set_driven(one, nan3), std::invalid_argument);
  EXPECT_THROW(gpu->set_driven(one, std::vector<double>(2, 0.0)), std::invalid_argument);
  EXPECT_THROW(gpu->build_region(one, -3), std::invalid_argument);
  EXPECT_THROW(gpu->build_region(bad_node, 1), std::out_of_range);
  // a node outside the region cannot be driven (found with one role download)
  const index_t seed[1] = {box_node(4, 4, 0, 0, 2)};
  gpu->build_region(seed, 0);
  const index_t far[1] = {box_node(4, 4, 4, 4, 2)};
  try {
    gpu->set_driven(far, target);
    ADD_FAILURE() << "drove a node outside the region";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("outside the deformation region"), std::string::npos) << e.what();
  }
  EXPECT_NO_THROW(gpu->set_driven(seed, target));
  EXPECT_THROW(gpu->advance(-1), std::invalid_argument);
  auto cpu = make_cpu_backend(GetParam());
  EXPECT_THROW(set_cuda_step_mode(*cpu, CudaStepMode::Graph), std::invalid_argument);
}

/// The node passes take two lanes a thread from two waves of the device's
/// resident threads at eight threads a node (ModelView::lanes_node_min).
TEST_P(Stages, NodePassesTakeTwoLanesAThreadFromTwoWaves) {
  SKIP_WITHOUT_GPU();
  const int sms = device_attribute(cudaDevAttrMultiProcessorCount),
            threads = device_attribute(cudaDevAttrMaxThreadsPerMultiProcessor);
  ASSERT_GT(sms, 0);
  ASSERT_GT(threads, 0);
  auto gpu = make_cuda_backend(GetParam());
  gpu->upload(box_model(4, 4, 4, 0.04, 0.04, 0.04));
  EXPECT_EQ(cuda_lanes_node_min(*gpu), index_t(2 * sms * threads / 8));
  set_cuda_lanes_node_min(*gpu, 7);
  EXPECT_EQ(cuda_lanes_node_min(*gpu), 7);
  gpu->upload(box_model(4, 4, 4, 0.04, 0.04, 0.04));  // the override lasts until the next upload
  EXPECT_EQ(cuda_lanes_node_min(*gpu), index_t(2 * sms * threads / 8));
}

/// Pass 2's and pass 4's two-lanes-a-thread kernels on the per-pass path
/// (Backend::nodal_pressure, node_update) over the whole box and regions of
/// depth 1 and 0: launched once a call where told (set_cuda_lanes_node_min
/// 0), never otherwise, with the eight-lane kernels' bits. Then the graphs:
/// a replay launches nothing, and an override drops them, so the next
/// advance captures the two-lane kernels; the steps keep their bits.
TEST_P(Stages, NodeLanesKernelsRunWhereToldWithTheEightLaneBits) {
  SKIP_WITHOUT_GPU();
  const Precision p = GetParam();
  const auto m = box_model(5, 4, 3, 0.05, 0.04, 0.03);
  const index_t seeds[3] = {m.tris[7], m.tris[m.n_tris + 7], m.tris[2 * m.n_tris + 7]};
  auto eight = make_cuda_backend(p), lanes = make_cuda_backend(p);
  eight->upload(m);
  lanes->upload(m);
  ASSERT_GT(cuda_lanes_node_min(*eight), m.n_nodes);
  set_cuda_lanes_node_min(*lanes, 0);
  unsigned seed = 3;
  for (int depth : {kDepthAll, 1, 0}) {
    SCOPED_TRACE(::testing::Message() << "depth " << depth);
    if (depth != kDepthAll) {
      EXPECT_EQ(lanes->build_region(seeds, depth).nodes(), eight->build_region(seeds, depth).nodes());
    }
    const auto u = random_field(m.n_nodes, 2e-4, seed++);
    std::vector<Fields> f;
    for (Backend* b : {eight.get(), lanes.get()}) {
      const bool told = b == lanes.get();
      b->set_displacements(u);
      b->element_pressure();
      const CudaNodePassLaunches c0 = cuda_node_pass_launches();
      b->nodal_pressure();
      const CudaNodePassLaunches c1 = cuda_node_pass_launches();
      b->element_forces();
      b->node_update();
      const CudaNodePassLaunches c2 = cuda_node_pass_launches();
      EXPECT_EQ(c1.pressures_lanes - c0.pressures_lanes, told ? 1 : 0);
      EXPECT_EQ(c1.pressures - c0.pressures, told ? 0 : 1);
      EXPECT_EQ(c2.updates_lanes - c1.updates_lanes, told ? 1 : 0);
      EXPECT_EQ(c2.updates - c1.updates, told ? 0 : 1);
      f.push_back(b->download());
    }
    EXPECT_GT(*std::max_element(f[0].node_p.begin(), f[0].node_p.end()), 0.0);  // really pressed
    EXPECT_EQ(f[1].node_p, f[0].node_p);
    EXPECT_EQ(f[1].f, f[0].f);
    EXPECT_EQ(f[1].u, f[0].u);
  }

  // the graphs: passes 3-4 apart, so that pass 4 is its own kernel
  const auto u = random_field(m.n_nodes, 1e-4, 11);
  lanes->upload(m);  // back to eight threads a node on this small box
  for (Backend* b : {eight.get(), lanes.get()}) {
    set_cuda_step_mode(*b, CudaStepMode::Graph);
    set_cuda_fused_force_blocks(*b, 0);
    b->build_region(seeds, kDepthAll);
    b->set_displacements(u);
  }
  ASSERT_FALSE(cuda_fuses_forces(*lanes));
  const CudaNodePassLaunches c0 = cuda_node_pass_launches();
  lanes->advance(3);  // captures a 3-step graph
  const CudaNodePassLaunches c1 = cuda_node_pass_launches();
  lanes->advance(3);  // the same phase: replays it
  const CudaNodePassLaunches c2 = cuda_node_pass_launches();
  set_cuda_lanes_node_min(*lanes, 0);
  lanes->advance(3);  // the override dropped the graph: captures the two-lane kernels
  const CudaNodePassLaunches c3 = cuda_node_pass_launches();
  EXPECT_EQ(c1.updates - c0.updates, 3);
  EXPECT_EQ(c1.updates_lanes, c0.updates_lanes);
  EXPECT_EQ(c2.updates, c1.updates);
  EXPECT_EQ(c2.updates_lanes, c1.updates_lanes);
  EXPECT_EQ(c3.updates_lanes - c2.updates_lanes, 3);
  EXPECT_EQ(c3.updates, c2.updates);
  eight->advance(9);
  EXPECT_EQ(lanes->download().u, eight->download().u);
}

/// Pass 4 over the whole mesh drops the force slots' lines it has read
/// from the L2 (ModelView::discard_slots) where the slots exceed half the
/// device's L2: a box just past that size in float (on an H100, 413k
/// elements and 74k nodes, whose node passes take two lanes a thread),
/// stepped with and without the drop in the Graph and Launch modes (pass 4
/// apart: the region is too large to fuse), two lanes a thread and eight
/// threads a node, and in the Grid mode (no drop), bit for bit; then a few
/// steps at depth 2 (DroppedSlotsAreNeverARegions below checks that no
/// region drops). The steps after a drop read no dropped slot: pass 3
/// writes every slot of the whole mesh before pass 4 reads it.
TEST_P(Stages, PassFourDropsTheSlotsItReadWhereTheyExceedHalfTheL2) {
  SKIP_WITHOUT_GPU();
  const Precision p = GetParam();
  const int l2 = device_attribute(cudaDevAttrL2CacheSize);
  ASSERT_GT(l2, 0);
  // 2 x 4 slots x 16 bytes (float) an element > L2: 6 n^3 elements > L2 / 128
  const int n = static_cast<int>(std::cbrt(double(l2) / 128 / 6)) + 1;
  const auto m = box_model(n, n, n, 0.1, 0.1, 0.1);
  const auto u = random_field(m.n_nodes, 2e-5, 43);
  const index_t seeds[1] = {m.tris[0]};
  std::vector<double> ref_u, ref_f, ref_p, ref_energy;
  struct Run {
    CudaStepMode mode;
    bool discard;
    bool eight;  // eight threads a node (the node kernels' other lane count)
  };
  for (const Run run : {Run{CudaStepMode::Graph, false, false}, Run{CudaStepMode::Graph, true, false},
                        Run{CudaStepMode::Launch, true, false}, Run{CudaStepMode::Graph, true, true},
                        Run{CudaStepMode::Grid, true, false}}) {
    SCOPED_TRACE(::testing::Message() << to_string(run.mode) << (run.discard ? ", slots dropped" : "")
                                      << (run.eight ? ", eight threads a node" : ""));
    auto gpu = make_cuda_backend(p);
    set_cuda_step_mode(*gpu, run.mode);
    gpu->upload(m);
    EXPECT_TRUE(cuda_discards_slots(*gpu)) << m.n_elems << " elements, L2 " << l2 << " bytes";
    if (!run.discard) set_cuda_discards_slots(*gpu, false);
    if (run.eight) set_cuda_lanes_node_min(*gpu, m.n_nodes + 1);
    gpu->set_displacements(u);
    const CudaNodePassLaunches before = cuda_node_pass_launches();
    const CudaSmallElementBlockLaunches small_before = cuda_small_element_block_launches();
    gpu->advance(4);
    std::vector<double> energies = {gpu->reduce().strain_energy};
    gpu->advance(3);
    const CudaNodePassLaunches after = cuda_node_pass_launches();
    const bool chained = run.mode != CudaStepMode::Grid;  // pass 4 apart: the region is too large to fuse
    const bool lanes = m.n_nodes >= cuda_lanes_node_min(*gpu);  // two lanes a thread (on an H100 unless told)
    EXPECT_EQ(after.updates > before.updates, chained && !lanes);
    EXPECT_EQ(after.updates_lanes > before.updates_lanes, chained && lanes);
    // the whole mesh's element passes run several waves, so they take the smaller blocks: pass 1 in
    // every mode (the reduction's), pass 3 where the steps run it apart in float (in double its
    // slots stream: the streaming kernel, in blocks of 256)
    const CudaSmallElementBlockLaunches small_after = cuda_small_element_block_launches();
    EXPECT_GT(small_after.pressures, small_before.pressures) << m.n_elems << " elements";
    EXPECT_EQ(small_after.forces > small_before.forces, chained && p == Precision::Float);
    gpu->build_region(seeds, 2);
    gpu->advance(2);
    energies.push_back(gpu->reduce().strain_energy);
    const Fields f = gpu->download();
    ASSERT_TRUE(std::isfinite(energies.back()));
    if (ref_u.empty()) {
      ref_u = f.u, ref_f = f.f, ref_p = f.node_p, ref_energy = energies;
      continue;
    }
    EXPECT_EQ(energies, ref_energy);
    EXPECT_EQ(f.u, ref_u);
    EXPECT_EQ(f.f, ref_f);
    EXPECT_EQ(f.node_p, ref_p);
  }
}

/// Writes twice the device's L2 of scratch memory: every dirty line the L2
/// held is written back to memory.
void flush_l2() {
  const int l2 = device_attribute(cudaDevAttrL2CacheSize);
  ASSERT_GT(l2, 0);
  void* scratch = nullptr;
  ASSERT_EQ(cudaMalloc(&scratch, 2 * std::size_t(l2)), cudaSuccess);
  EXPECT_EQ(cudaMemset(scratch, 0x5a, 2 * std::size_t(l2)), cudaSuccess);
  EXPECT_EQ(cudaDeviceSynchronize(), cudaSuccess);
  EXPECT_EQ(cudaFree(scratch), cudaSuccess);
}

/// The slots pass 4 drops from the L2 are never those of a region: a
/// region's build writes zero into the slots of the elements it leaves
/// out, which its steps read but never write, and which memory may not hold
/// yet. On a small box: whole-mesh steps leave forces in every slot, the L2
/// is flushed (memory holds those forces), a region of depth 1 is built
/// (its zeros are in the L2 only), and it steps with the drop on, against
/// a backend that never drops: the same bits. Dropping a region's lines
/// would read the old forces back from memory.
TEST_P(Stages, DroppedSlotsAreNeverARegions) {
  SKIP_WITHOUT_GPU();
  const Precision p = GetParam();
  const auto m = box_model(8, 8, 6, 0.08, 0.08, 0.06);
  const auto u = random_field(m.n_nodes, 1e-4, 47);
  const index_t seeds[3] = {m.tris[3], m.tris[m.n_tris + 3], m.tris[2 * m.n_tris + 3]};
  std::vector<Fields> f;
  for (bool drop : {false, true}) {
    SCOPED_TRACE(drop ? "dropping" : "never dropping");
    auto gpu = make_cuda_backend(p);
    set_cuda_step_mode(*gpu, CudaStepMode::Graph);
    gpu->upload(m);
    set_cuda_fused_force_blocks(*gpu, 0);  // pass 4 its own kernel
    gpu->set_displacements(u);
    gpu->advance(4);
    const Fields whole = gpu->download();
    ASSERT_GT(*std::max_element(whole.f.begin(), whole.f.end()), 0.0);
    ASSERT_NO_FATAL_FAILURE(flush_l2());
    const RegionSizes r = gpu->build_region(seeds, 1);
    ASSERT_LT(r.n_elems, m.n_elems);
    set_cuda_discards_slots(*gpu, drop);
    gpu->advance(3);
    f.push_back(gpu->download());
  }
  EXPECT_EQ(f[1].u, f[0].u);
  EXPECT_EQ(f[1].f, f[0].f);
}

TEST(NoGpu, BackendRefusesWithReason) {
  std::string why;
  if (cuda_available(&why)) GTEST_SKIP() << "a GPU is present: " << why;
  EXPECT_FALSE(why.empty());
  EXPECT_THROW(make_cuda_backend(Precision::Float), std::runtime_error);
  try {
    create_backend("cuda", Precision::Float);
    ADD_FAILURE() << "created a cuda backend without a GPU";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("cannot run here"), std::string::npos) << e.what();
  }
  bool listed = false;
  for (const auto& b : list_backends())
    if (b.name == "cuda") {
      listed = true;
      EXPECT_TRUE(b.built);
      EXPECT_FALSE(b.available);
      EXPECT_EQ(b.detail, why);
    }
  EXPECT_TRUE(listed);
}

TEST(Gpu, AvailableNamesTheDeviceAndMeasuresBandwidth) {
  SKIP_WITHOUT_GPU();
  std::string why;
  ASSERT_TRUE(cuda_available(&why));
  EXPECT_FALSE(why.empty());
  auto gpu = make_cuda_backend(Precision::Float);
  EXPECT_EQ(gpu->name(), "cuda");
  EXPECT_NE(gpu->device_name().find(why), std::string::npos);
  const double bw = cuda_copy_bandwidth();
  std::printf("[measured] device %s copy bandwidth %.1f GB/s\n", why.c_str(), bw * 1e-9);
  // a measurement, not a speed check: how fast is the bench's business (tissue bench), and
  // a timed bound fails under compute-sanitizer or on a shared GPU
  EXPECT_TRUE(std::isfinite(bw)) << bw;
  EXPECT_GT(bw, 0.0);
}

}  // namespace
}  // namespace tissue::cuda_test
