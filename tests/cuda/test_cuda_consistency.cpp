// Cross-backend consistency (docs/design.md section 5): the same
// scene (a box, a box dragged under a tool with friction, and the default
// kidney of io/kidney.hpp; each with a depth-N
// region and the whole mesh) driven through core Scheduler by the same
// ScriptedDevice path on the cpu and the cuda backend, tick by tick, in
// float and double. Checked:
// the same contact sets (Backend::contacts(): nodes, kinds, tools) -- every
// tick in double; in float a node at the very edge of the tool may be
// rounded in on one backend and out on the other, so the node counts may
// differ by one node on at most 2 % of the ticks --, identical region sizes
// every tick and identical region node/element sets (Backend::region())
// after contact starts and at the end; displacements and the tool force
// equal within the tolerance below; equilibrium first reached within +-1 tick.
//
// Tolerances (relative to the largest displacement / reaction of the run),
// measured on NVIDIA GPUs (docs/cuda.md, "Cross-backend consistency"). Both backends run
// the same core functions over the same element orders; what differs is
// rounding: nvcc contracts a * b + c into FMAs (so does the cpu backend's
// AVX2 / AVX-512 element kernels, not its SSE2 fallback nor its node loops),
// the device's cbrt differs from core's cube_root by an ulp or two, and the
// cuda backend adds a node's element values in 8 pairwise-combined partial
// sums (the cpu sequentially). Those differences enter each step at ~1 ulp
// and accumulate over the run's 10^3..3 x 10^3 steps.
//   double: 1e-9. Measured <= 1.5e-14 (displacements) and <= 2.5e-14
//     (force) on every scene: five orders of margin, still far below any
//     physical significance.
//   float: 1e-3 on the box (measured <= 1.0e-5 displacements, <= 5.5e-5
//     force). The kidney in float: 1e-2 (measured 4.7e-3 displacements and
//     4.8e-3 force, H100, 4 steps per tick), and 0.1 for the force on the
//     ticks whose contact counts differ (measured 5.5e-2). A node resting on
//     the tool's surface sits at the contact threshold at every step of the
//     press and hold; in float rounding puts it in on one backend and out on
//     the other now and then (4-5 of ~760 ticks here), which changes that
//     tick's force by the node's share and the node's velocity by the
//     contact's impact rule, and the runs drift apart from there. In double
//     the kidney agrees to 1e-13 once its path avoids an exact tie (below).
// Equilibrium (first tick of the held contact with Scheduler's equilibrium
// flag): within +-1 tick in double and float on the box (measured: the
// same tick), +-2 ticks for the float kidney (measured: the same tick).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <string>

#include "core/device.hpp"
#include "core/scheduler.hpp"
#include "io/kidney.hpp"
#include "scene/validate.hpp"
#include "tests/cuda/cuda_test_support.hpp"

namespace tissue::cuda_test {
namespace {


/// A scene for the suite: its model, scheduler settings and tool path.
struct ConsistencyScene {
  std::string name;
  std::function<TissueModel<double>()> model;
  SchedulerSettings settings;
  std::vector<Waypoint> path;
  double duration = 0;  ///< s simulated
  bool expect_equilibrium = true;  ///< the held indentation settles within the run (checked on the cpu)
  /// allowed difference of the first equilibrium tick in float: where a slowly decaying residual crosses its
  /// tolerance, which the backends' different float rounding (fma, approximate division, the carried update
  /// bits' quantum on the device) moves by a tick or two (measured: the box at depth 3, cpu 381, cuda 379)
  int float_equilibrium_ticks = 2;
  /// worst |du| / max |u| and |dF| / max |F| allowed, double and float
  double tol_double = 1e-9, tol_float = 1e-3;
  double tol_edge = 1e-3;  ///< float force on ticks whose contact counts differ by one node
};

/// 60 x 60 x 30 mm box (10 x 10 x 5 cells, 3000 tets), bottom fixed, pressed
/// 4 mm into its top face at a point inside a triangle, held, released.
ConsistencyScene box_scene(int depth) {
  ConsistencyScene s;
  s.name = depth == kDepthAll ? "box_all" : "box_depth" + std::to_string(depth);
  s.model = [] { return box_model(10, 10, 5, 0.06, 0.06, 0.03); };
  s.settings.depth = depth;
  // the default tool, a 2 mm sphere, touching the top at 0.1005 s
  s.path = press_path({0.0261, 0.0334, 0.032}, {0, 0, -1}, 0.004, 0.005, 0.1005, 0.2, 0.4, 0.1);
  s.duration = 1.0;
  return s;
}

/// The box of box_scene under a sphere with Coulomb friction (mu 0.3):
/// pressed 3 mm, dragged 6 mm along x at 15 mm/s (the contact nodes stick,
/// then slide), held, lifted off.
ConsistencyScene box_drag_scene(int depth) {
  ConsistencyScene s = box_scene(depth);
  s.name = depth == kDepthAll ? "box_drag_all" : "box_drag_depth" + std::to_string(depth);
  s.settings.tools.at(0).shape.friction = 0.3;
  const Vec3<double> touch{0.0261, 0.0334, 0.032}, down{0, 0, -0.003}, along{0.006, 0, 0};
  s.path = {{0.0, touch + Vec3<double>{0, 0, 0.005}}, {0.1005, touch}, {0.25, touch + down},
            {0.65, touch + down + along}, {0.9, touch + down + along}, {1.0, touch + along + Vec3<double>{0, 0, 0.005}}};
  s.expect_equilibrium = false;  // the drag ends at 0.65 s; the tool's held contact is short
  // float: whether a node at the edge of the Coulomb cone sticks or slides in a step is a threshold that
  // rounding decides, as contact entry is; measured on an H200: 1.7e-3 of max |u|, 7.3e-4 of max |F|
  // (double: 1.1e-14 and 6.9e-13)
  s.tol_float = 5e-3;
  return s;
}

/// The built-in default kidney (io/kidney.hpp: ~8,400 tets, fixed hilum),
/// its own scripted press on the lateral side and its solver settings, with
/// the region depth overridden.
ConsistencyScene kidney_scene(int depth) {
  ConsistencyScene s;
  s.name = depth == kDepthAll ? "kidney_all" : "kidney_depth" + std::to_string(depth);
  const scene::Scene sc = io::default_kidney_scene();
  s.model = [] { return scene::load_model(io::default_kidney_scene()); };
  s.settings = scene::scheduler_settings(sc);
  s.settings.depth = depth;
  // The scene's path, moved 3 um back along the tool's axis. Unmoved, the tip sphere reaches
  // the surface node at the kidney's pole (node 490 before the meshes were numbered for locality; where the tool is aimed) exactly at the 0.1 s waypoint, a
  // step boundary: whether that node is in contact in that step is a tie that rounding decides, and
  // it decides it differently on the two backends. The first contact sets the node's velocity to the
  // tool's (the kinematic contact's impact rule), so a contact one step earlier moves it by v dt
  // (25 um at the approach's 0.1 m/s): that was the 1.1e-3 (double) and 2.9e-2..5.2e-2 (float)
  // disagreement measured before, on an H100, with the same contact sets at every tick's end. 3 um
  // at the press's 25 mm/s is 120 us: the touch falls inside a step, and no tie is left.
  s.path = sc.tools.at(0).path;
  const Vec3<double> back = unit_or(s.path.at(1).p - s.path.at(2).p, Vec3<double>{0, 0, 0});  // out of the tissue
  for (Waypoint& w : s.path) w.p = w.p + 3e-6 * back;
  s.duration = s.path.back().t;
  s.expect_equilibrium = false;  // whether the kidney settles within its hold is the scene's business
  s.tol_float = 1e-2;
  s.tol_edge = 0.1;
  return s;
}

struct Param {
  Precision precision;
  ConsistencyScene scene;
};

class Consistency : public ::testing::TestWithParam<Param> {};

INSTANTIATE_TEST_SUITE_P(Scenes, Consistency,
                         ::testing::Values(Param{Precision::Double, box_scene(3)}, Param{Precision::Float, box_scene(3)},
                                           Param{Precision::Double, box_scene(kDepthAll)},
                                           Param{Precision::Float, box_scene(kDepthAll)},
                                           Param{Precision::Double, box_drag_scene(3)},
                                           Param{Precision::Float, box_drag_scene(3)},
                                           Param{Precision::Double, kidney_scene(5)},
                                           Param{Precision::Float, kidney_scene(5)},
                                           Param{Precision::Double, kidney_scene(kDepthAll)},
                                           Param{Precision::Float, kidney_scene(kDepthAll)}),
                         [](const auto& info) { return info.param.scene.name + "_" + name_of(info.param.precision); });

void expect_same_region(Backend& cpu, Backend& gpu, long tick) {
  const Region rc = cpu.region(), rg = gpu.region();
  EXPECT_EQ(rg.nodes, rc.nodes) << "tick " << tick;
  EXPECT_EQ(rg.elems, rc.elems) << "tick " << tick;
  EXPECT_EQ(rg.role, rc.role) << "tick " << tick;
  EXPECT_EQ(rg.n_inner, rc.n_inner) << "tick " << tick;
  EXPECT_EQ(rg.n_halo, rc.n_halo) << "tick " << tick;
}

TEST_P(Consistency, SameRegionContactDisplacementForceAndEquilibrium) {
  SKIP_WITHOUT_GPU();
  const Precision p = GetParam().precision;
  const ConsistencyScene& sc = GetParam().scene;
  const TissueModel<double> m = sc.model();
  auto cpu = make_cpu_backend(p), gpu = make_cuda_backend(p);
  cpu->upload(m);
  gpu->upload(m);
  Scheduler sc_cpu(*cpu, m, sc.settings), sc_gpu(*gpu, m, sc.settings);
  ScriptedDevice dev_cpu(sc.path), dev_gpu(sc.path);

  double max_u = 0, max_f = 0, worst_u = 0, worst_f = 0, worst_f_edge = 0;
  long first_eq_cpu = -1, first_eq_gpu = -1, contact_ticks = 0, count_mismatches = 0, worst_f_tick = -1;
  bool was_in_contact = false;
  while (sc_cpu.time() < sc.duration - 1e-9) {
    const TickReport rc = sc_cpu.tick(dev_cpu), rg = sc_gpu.tick(dev_gpu);
    if (p == Precision::Double || rc.tick % 50 == 0) {
      const std::vector<ContactNode> cc = cpu->contacts(), cg = gpu->contacts();
      if (p == Precision::Double) {
        ASSERT_EQ(cg.size(), cc.size()) << "tick " << rc.tick;
        for (size_t k = 0; k < cc.size(); ++k) {
          ASSERT_EQ(cg[k].node, cc[k].node) << "tick " << rc.tick;
          ASSERT_EQ(cg[k].kind, cc[k].kind) << "tick " << rc.tick;
          ASSERT_EQ(cg[k].tool, cc[k].tool) << "tick " << rc.tick;
        }
      }
    }
    if (rg.contact_nodes != rc.contact_nodes) {
      ++count_mismatches;
      EXPECT_EQ(p, Precision::Float) << "tick " << rc.tick;
      EXPECT_LE(std::abs(rg.contact_nodes - rc.contact_nodes), 1) << "tick " << rc.tick;
    }
    ASSERT_EQ(rg.region_nodes, rc.region_nodes) << "tick " << rc.tick;
    ASSERT_EQ(rg.region_elems, rc.region_elems) << "tick " << rc.tick;
    if (rc.contact_nodes > 0) ++contact_ticks;
    if (rc.contact_nodes > 0 && !was_in_contact) expect_same_region(*cpu, *gpu, rc.tick);
    was_in_contact = rc.contact_nodes > 0;
    // reaction force, relative to the largest seen so far
    max_f = std::max(max_f, norm(rc.force));
    // (on a tick whose contact counts differ -- float, a node at the tool's surface rounded in on one
    // backend and out on the other -- the force differs by that node's share: reported apart)
    if (max_f > 0) {
      const double d = norm(rg.force - rc.force) / max_f;
      if (rg.contact_nodes != rc.contact_nodes) {
        worst_f_edge = std::max(worst_f_edge, d);
      } else if (d > worst_f) {
        worst_f = d;
        worst_f_tick = rc.tick;
      }
    }
    if (rc.contact_nodes > 0 && rc.equilibrium && first_eq_cpu < 0) first_eq_cpu = rc.tick;
    if (rg.contact_nodes > 0 && rg.equilibrium && first_eq_gpu < 0) first_eq_gpu = rg.tick;
    if (rc.tick % 20 == 0 || rc.tick + 1 == long(std::lround(sc.duration / sc.settings.tick))) {
      const Fields fc = cpu->download(), fg = gpu->download();
      for (double v : fc.u) max_u = std::max(max_u, std::fabs(v));
      if (max_u > 0) {
        double d = 0;
        for (size_t i = 0; i < fc.u.size(); ++i) d = std::max(d, std::fabs(fg.u[i] - fc.u[i]));
        worst_u = std::max(worst_u, d / max_u);
      }
    }
  }
  expect_same_region(*cpu, *gpu, sc_cpu.ticks());
  std::printf("[measured] %s %s: max |u| %.3g m, max |F| %.3g N, worst du/max|u| %.3g, worst dF/max|F| %.3g (tick %ld), "
              "first equilibrium tick cpu %ld cuda %ld, %ld contact ticks, %ld contact-count mismatches (worst dF/max|F| "
              "there %.3g)\n",
              sc.name.c_str(), to_string(p), max_u, max_f, worst_u, worst_f, worst_f_tick, first_eq_cpu, first_eq_gpu,
              contact_ticks, count_mismatches, worst_f_edge);
  EXPECT_GT(contact_ticks, 300);
  EXPECT_LE(count_mismatches, contact_ticks / 50);
  EXPECT_GT(max_u, 1e-3);  // the tool really pressed
  const double tol = p == Precision::Double ? sc.tol_double : sc.tol_float;
  EXPECT_LT(worst_u, tol);
  EXPECT_LT(worst_f, tol);
  EXPECT_LT(worst_f_edge, sc.tol_edge);
  if (sc.expect_equilibrium) {
    ASSERT_GE(first_eq_cpu, 0) << "the cpu run never reached equilibrium under the held tool";
  }
  EXPECT_EQ(first_eq_gpu < 0, first_eq_cpu < 0) << "one backend reached equilibrium, the other never did";
  if (first_eq_cpu >= 0) {
    const double ticks = p == Precision::Double ? 1.0 : double(sc.float_equilibrium_ticks);
    EXPECT_NEAR(double(first_eq_gpu), double(first_eq_cpu), ticks);
  }
}

}  // namespace
}  // namespace tissue::cuda_test
