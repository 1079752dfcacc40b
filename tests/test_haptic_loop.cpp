// The haptic loop (haptics/haptic_loop.hpp): synchronous ticks, the haptic
// thread's start/stop, snapshots, tasks posted by the display, parameter
// changes applied between ticks (and refused ones), late-tick detection with
// a deliberately slow backend, and a solver failure. No assertion depends on
// how fast this machine is: the slow backend is slower than the period by
// construction, and waits poll the published snapshot with a generous limit.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <string>
#include <thread>

#include "backends/registry.hpp"
#include "core/box_mesh.hpp"
#include "haptics/haptic_loop.hpp"

#if defined(__SANITIZE_THREAD__)
#include <tbb/global_control.h>
#endif

namespace tissue {
namespace {

using namespace std::chrono_literals;

#if defined(__SANITIZE_THREAD__)
// scripts/tsan: TBB's runtime is not instrumented, so TSan cannot see the
// synchronisation of its worker pool and reports false races in its
// partitioner; the cpu backend's loops run on one TBB thread here (the
// threads under test, the haptic thread and this one, remain).
const tbb::global_control one_tbb_thread(tbb::global_control::max_allowed_parallelism, 1);
#endif

/// A 2 x 2 x 1 cm soft box fixed at its base, with E and nu from `p`.
std::unique_ptr<TissueModel<double>> box_model(const LiveParams& p) {
  if (!(p.nu > -1 && p.nu < 0.5)) throw std::invalid_argument("nu must lie in (-1, 0.5)");
  ModelInput in;
  box_mesh(in, 4, 4, 2, 0.02, 0.02, 0.01);
  in.materials = {{p.E / (2 * (1 + p.nu)), p.E / (3 * (1 - 2 * p.nu)), 1000}};
  in.fixed.assign(in.nodes.size() / 3, 0);
  for (size_t i = 0; i < in.fixed.size(); ++i) in.fixed[i] = in.nodes[3 * i + 2] < 1e-9 ? 1 : 0;
  return std::make_unique<TissueModel<double>>(build_model(in));
}

/// A backend that does nothing but take `work` per batch of steps and,
/// from tick `fail_at` on, report non-finite values. Counts write_positions.
class StubBackend : public Backend {
 public:
  StubBackend(std::chrono::microseconds work, long fail_at) : work_(work), fail_at_(fail_at) {}
  std::string name() const override { return "stub"; }
  Precision precision() const override { return Precision::Double; }
  std::string device_name() const override { return "test stub"; }

 protected:
  void do_upload(const TissueModel<double>& m) override { n_ = m.n_nodes; }
  void do_set_motion(std::span<const double>, std::span<const double>) override {}
  void do_set_masses(const NodeMasses&) override {}
  std::vector<double> do_previous_displacements() override { return std::vector<double>(3 * std::size_t(n_), 0.0); }
  RegionSizes do_build_region(std::span<const index_t>, int depth) override { return {depth, n_, 0, 0}; }
  Region do_region() override { return {}; }
  std::vector<std::uint8_t> do_roles(std::span<const index_t> nodes) override {
    return std::vector<std::uint8_t>(nodes.size(), kInner);
  }
  void do_set_driven(std::span<const index_t>, std::span<const double>, std::span<const std::uint8_t>) override {}
  void do_clear_driven() override {}
  void do_set_loads(std::span<const double>) override {}
  void do_begin_grasp(int, const ToolPose&) override {}
  void do_end_grasp(int) override {}
  void do_reset_contacts() override {}
  void do_element_pressure() override {}
  void do_nodal_pressure() override {}
  void do_element_forces() override {}
  void do_node_update() override {}
  void do_advance(int, const ContactTools<double>&) override {
    if (work_.count() > 0) std::this_thread::sleep_for(work_);
  }
  std::vector<index_t> do_contact_candidates(const ContactTools<double>&) override { return {}; }
  std::vector<ContactNode> do_contacts() override { return {}; }
  Reductions do_reduce() override {
    Reductions r;
    r.finite = ++batches_ < fail_at_;
    return r;
  }
  Fields do_download() override { return {}; }
  void do_write_positions(float* dst) override { dst[0] = float(++writes_); }

 private:
  std::chrono::microseconds work_;
  long fail_at_;
  long batches_ = 0;
  index_t n_ = 0;
  int writes_ = 0;
};

/// Factory over the box: the cpu backend, or the stub (work per tick, failure tick).
EngineFactory box_factory(bool stub, std::chrono::microseconds work = 0us, long fail_at = 1L << 40) {
  return [=](const LiveParams& p) {
    Engine s;
    s.model = box_model(p);
    s.backend = stub ? std::make_unique<StubBackend>(work, fail_at) : create_backend("cpu", p.precision);
    s.backend->upload(*s.model);
    SchedulerSettings settings;
    settings.depth = p.depth;
    s.scheduler = std::make_unique<Scheduler>(*s.backend, *s.model, settings);
    return s;
  };
}

/// Press 2 mm into the box's top face and back, in 0.4 s.
ScriptedDevice press_device() { return ScriptedDevice(press_path({0.011, 0.009, 0.012}, {0, 0, -1}, 0.002, 0.002,
                                                                  0.05, 0.1, 0.15, 0.1)); }

/// Polls until pred(snapshot) holds; false after `limit`.
template <class Pred>
bool wait_for(const HapticLoop& loop, Pred pred, std::chrono::milliseconds limit = 20000ms) {
  const auto end = std::chrono::steady_clock::now() + limit;
  while (std::chrono::steady_clock::now() < end) {
    if (pred(loop.snapshot())) return true;
    std::this_thread::sleep_for(2ms);
  }
  return false;
}

TEST(HapticLoop, RunTicksPressesTheTissueAndPublishes) {
  ScriptedDevice dev = press_device();
  LiveParams params;
  params.depth = 2;
  params.precision = Precision::Double;
  HapticLoop loop(dev, box_factory(false), params);
  const HapticSnapshot s0 = loop.snapshot();
  EXPECT_EQ(s0.tick, -1);
  EXPECT_EQ(s0.sim_version, 1);
  EXPECT_EQ(s0.region.nodes(), 0);  // depth 2: empty until contact
  loop.run_ticks(150);              // approach + press
  const HapticSnapshot s1 = loop.snapshot();
  EXPECT_EQ(s1.tick, 150);
  EXPECT_NEAR(s1.time, 0.15, 1e-12);
  EXPECT_GT(s1.contact_nodes, 0);
  EXPECT_GT(s1.region.nodes(), 0);
  EXPECT_GT(s1.region_version, s0.region_version);
  EXPECT_GT(s1.tissue_force.z, 0);  // the tissue pushes the tool back up
  EXPECT_GT(s1.rendered_force.z, 0);
  EXPECT_LT(s1.tool.z - 0.002, 0.01);  // the proxy (a 2 mm sphere) reaches below the original surface
  EXPECT_EQ(s1.stats.ticks, 150);
  EXPECT_EQ(s1.stats.late, 0);      // no deadlines without the thread
  EXPECT_FALSE(s1.stats.paced);
  EXPECT_EQ(describe(s1.stats).rfind("haptic ticks run offline (no deadlines): 150 ticks", 0), 0u);
  EXPECT_LE(s1.stats.work_p50, s1.stats.work_p99);
  EXPECT_LE(s1.stats.work_p99, s1.stats.work_max);
  EXPECT_EQ(s1.steps_per_tick, loop.snapshot().steps_per_tick);
  EXPECT_EQ(loop.status(), "");
}

TEST(HapticLoop, ThreadStartsTicksAndStopsCleanly) {
  ScriptedDevice dev = press_device();
  HapticLoop loop(dev, box_factory(false), LiveParams{});
  loop.start();
  EXPECT_TRUE(loop.running());
  ASSERT_TRUE(wait_for(loop, [](const HapticSnapshot& s) { return s.tick >= 300; }));
  loop.stop();
  EXPECT_FALSE(loop.running());
  const HapticSnapshot a = loop.snapshot();
  std::this_thread::sleep_for(20ms);
  const HapticSnapshot b = loop.snapshot();
  EXPECT_EQ(a.tick, b.tick);  // nothing ticks after stop()
  EXPECT_GE(a.tick, 300);
  EXPECT_EQ(a.stats.ticks, a.tick);
  EXPECT_TRUE(a.stats.paced);
  EXPECT_GT(a.stats.rate_hz, 0);
  EXPECT_LE(a.stats.work_p50, a.stats.work_max);
  EXPECT_GT(a.stats.session_p99, 0);
  // a second session continues the same simulation, with fresh statistics
  loop.start();
  ASSERT_TRUE(wait_for(loop, [&](const HapticSnapshot& s) { return s.tick >= a.tick + 50; }));
  loop.stop();
  const HapticSnapshot c = loop.snapshot();
  EXPECT_EQ(c.stats.ticks, c.tick - a.tick);
}

TEST(HapticLoop, PostedTasksRunOnTheHapticThreadBetweenTicks) {
  ScriptedDevice dev = press_device();
  HapticLoop loop(dev, box_factory(false), LiveParams{});
  loop.start();
  ASSERT_TRUE(wait_for(loop, [](const HapticSnapshot& s) { return s.tick >= 10; }));
  std::thread::id ran_on;
  long before = -1, after = -2;
  std::vector<float> xyz(3 * 75);  // 5 x 5 x 3 nodes
  loop.post([&](Engine& sim) {
        ran_on = std::this_thread::get_id();
        before = sim.scheduler->ticks();
        sim.backend->write_positions(xyz.data());
        std::this_thread::sleep_for(5ms);  // no tick may run meanwhile
        after = sim.scheduler->ticks();
      }).get();
  EXPECT_NE(ran_on, std::this_thread::get_id());
  EXPECT_EQ(before, after);
  EXPECT_NEAR(xyz[3 * 74 + 2], 0.01, 1e-3);  // the last node sits near the top face (z = 1 cm)
  // an exception in a task reaches the display through the future
  std::future<void> bad = loop.post([](Engine&) { throw std::runtime_error("task failed"); });
  EXPECT_THROW(bad.get(), std::runtime_error);
  EXPECT_TRUE(wait_for(loop, [&](const HapticSnapshot& s) { return s.tick > after + 5; }));  // still ticking
  loop.stop();
  // stopped: the task runs on the calling thread
  loop.post([&](Engine&) { ran_on = std::this_thread::get_id(); }).get();
  EXPECT_EQ(ran_on, std::this_thread::get_id());
}

TEST(HapticLoop, ParameterChangesAreAppliedBetweenTicksOrRefused) {
  ScriptedDevice dev = press_device();
  HapticLoop loop(dev, box_factory(false), LiveParams{});
  loop.start();
  ASSERT_TRUE(wait_for(loop, [](const HapticSnapshot& s) { return s.tick >= 20; }));
  LiveParams p;
  p.E = 6000;
  p.nu = 0.3;
  p.depth = 3;
  p.precision = Precision::Double;
  loop.request_params(p);
  ASSERT_TRUE(wait_for(loop, [](const HapticSnapshot& s) { return s.sim_version == 2 && s.tick >= 5; }));
  HapticSnapshot s = loop.snapshot();
  EXPECT_EQ(s.params.E, 6000);
  EXPECT_EQ(s.params.depth, 3);
  EXPECT_EQ(s.params.precision, Precision::Double);
  EXPECT_EQ(loop.status(), "");
  std::string backend_precision;
  loop.post([&](Engine& sim) { backend_precision = to_string(sim.backend->precision()); }).get();
  EXPECT_EQ(backend_precision, "double");
  // nu = 0.6 is refused: the running simulation stays, the status says why
  LiveParams bad = p;
  bad.nu = 0.6;
  loop.request_params(bad);
  const auto refused = [&] { return loop.status().find("parameters refused") != std::string::npos; };
  for (int k = 0; k < 5000 && !refused(); ++k) std::this_thread::sleep_for(2ms);
  EXPECT_TRUE(refused()) << loop.status();
  EXPECT_NE(loop.status().find("nu must lie in (-1, 0.5)"), std::string::npos) << loop.status();
  const long t = loop.snapshot().tick;
  EXPECT_TRUE(wait_for(loop, [&](const HapticSnapshot& q) { return q.tick > t + 10; }));
  EXPECT_EQ(loop.snapshot().sim_version, 2);
  EXPECT_EQ(loop.snapshot().params.nu, 0.3);
  loop.stop();
  // stopped: applied at once
  p.depth = kDepthAll;
  loop.request_params(p);
  EXPECT_EQ(loop.snapshot().sim_version, 3);
  EXPECT_TRUE(loop.snapshot().region.whole());
}

TEST(HapticLoop, FrictionChangesBetweenTicksWithoutARebuild) {
  ScriptedDevice dev = press_device();
  HapticLoop loop(dev, box_factory(false), LiveParams{});
  loop.start();
  ASSERT_TRUE(wait_for(loop, [](const HapticSnapshot& s) { return s.tick >= 10; }));
  loop.set_friction(0.35);
  ASSERT_TRUE(wait_for(loop, [](const HapticSnapshot& s) { return s.params.friction == 0.35; }));
  double got = -1;
  loop.post([&](Engine& sim) { got = sim.backend->tools().at(0).friction; }).get();
  EXPECT_EQ(got, 0.35);
  EXPECT_EQ(loop.snapshot().sim_version, 1) << "no rebuild";
  EXPECT_THROW(loop.set_friction(-1), std::invalid_argument);
  EXPECT_THROW(loop.set_friction(NAN), std::invalid_argument);
  loop.stop();
}

/// Records the times it is read at.
struct ClockProbe : Device {
  std::vector<double> t;
  ToolInput read(double time) override {
    t.push_back(time);
    return {{0.011, 0.009, 0.03}};  // 2 cm above the box: no contact
  }
  void send_force(const Vec3<double>&) override {}
};

TEST(HapticLoop, TheDeviceClockGoesOnAcrossRebuilds) {
  ClockProbe dev;
  HapticLoop loop(dev, box_factory(true), LiveParams{});
  loop.run_ticks(30);
  loop.request_params(LiveParams{});  // a new scheduler: its own time starts at 0
  loop.run_ticks(20);
  ASSERT_EQ(dev.t.size(), 50u);
  for (size_t k = 0; k < dev.t.size(); ++k) EXPECT_NEAR(dev.t[k], 1e-3 * (k + 1), 1e-12) << "read " << k;
  EXPECT_NEAR(loop.snapshot().time, 0.05, 1e-12);
  EXPECT_EQ(loop.snapshot().tick, 20);  // the running scheduler's ticks
}

TEST(HapticLoop, ASolverSlowerThanThePeriodIsReportedLate) {
  ScriptedDevice dev = press_device();
  HapticLoop::Options opt;
  opt.window = 50;
  opt.stats_every = 10;
  opt.max_lag = 1;
  HapticLoop loop(dev, box_factory(true, 3000us), LiveParams{}, opt);  // 3 ms of work per 1 ms tick
  loop.start();
  ASSERT_TRUE(wait_for(loop, [](const HapticSnapshot& s) { return s.stats.ticks >= 40; }));
  loop.stop();
  const HapticStats st = loop.snapshot().stats;
  EXPECT_GE(st.late, st.ticks - 1);  // every tick but perhaps the first ends after the next deadline
  EXPECT_EQ(st.overruns, st.ticks);
  EXPECT_GT(st.skipped, 0);          // > 1 period behind: deadlines dropped, not bursts
  EXPECT_FALSE(st.keeping_up);
  EXPECT_GT(st.work_p50, 2.9e-3);
  EXPECT_LT(st.rate_hz, 500);
  EXPECT_EQ(describe(st).rfind("SOLVER CANNOT KEEP UP", 0), 0u) << describe(st);
}

TEST(HapticLoop, ASolverFailureStopsTicksUntilNewParameters) {
  ScriptedDevice dev = press_device();
  int built = 0;
  EngineFactory stub = box_factory(true, 0us, 30);  // non-finite from the 30th tick
  EngineFactory counting = [&](const LiveParams& p) {
    ++built;
    return built == 1 ? stub(p) : box_factory(true)(p);
  };
  HapticLoop loop(dev, counting, LiveParams{});
  loop.start();
  ASSERT_TRUE(wait_for(loop, [](const HapticSnapshot& s) { return s.failed; }));
  EXPECT_NE(loop.status().find("non-finite"), std::string::npos) << loop.status();
  const long stuck = loop.snapshot().tick;
  EXPECT_EQ(stuck, 29);
  std::this_thread::sleep_for(20ms);
  EXPECT_EQ(loop.snapshot().tick, stuck);
  loop.request_params(LiveParams{});  // a rebuild recovers
  ASSERT_TRUE(wait_for(loop, [](const HapticSnapshot& s) { return !s.failed && s.tick >= 40; }));
  EXPECT_EQ(loop.status(), "");
  loop.stop();
  // synchronous runs throw the failure
  ScriptedDevice dev2 = press_device();
  HapticLoop sync(dev2, box_factory(true, 0us, 5), LiveParams{});
  EXPECT_THROW(sync.run_ticks(10), SimulationError);
  EXPECT_TRUE(sync.snapshot().failed);
}

TEST(HapticLoop, DescribeNamesRateAndPercentiles) {
  HapticStats s;
  s.paced = true;
  s.period = 1e-3;
  s.rate_hz = 999.7;
  s.work_p50 = 2.1e-4;
  s.work_p99 = 3.5e-4;
  s.work_max = 9e-4;
  s.window_ticks = 1000;
  const std::string line = describe(s);
  EXPECT_EQ(line.rfind("haptic 999.7 Hz (target 1000 Hz), tick work p50 0.210 ms, p99 0.350 ms", 0), 0u) << line;
  s.keeping_up = false;
  s.window_late = 37;
  EXPECT_EQ(describe(s).rfind("HAPTIC DEADLINES MISSED: 37 of the last 1000 ticks", 0), 0u) << describe(s);
  s.work_p99 = 1.7e-3;  // the work itself exceeds the period
  EXPECT_EQ(describe(s).rfind("SOLVER CANNOT KEEP UP: 37 of the last 1000 ticks", 0), 0u) << describe(s);
}

TEST(HapticLoop, FactoryErrorsReachTheConstructor) {
  ScriptedDevice dev = press_device();
  LiveParams bad;
  bad.nu = 0.5;
  EXPECT_THROW(HapticLoop(dev, box_factory(false), bad), std::invalid_argument);
  EngineFactory empty = [](const LiveParams&) { return Engine{}; };
  EXPECT_THROW(HapticLoop(dev, empty, LiveParams{}), std::invalid_argument);
}

}  // namespace
}  // namespace tissue
