// tissue_haptic_session: the haptic loop and a display-like thread, without
// OpenGL. The haptic thread runs the scene at 1 kHz through the virtual
// coupling; the main thread plays the display's part at 60 Hz: it copies
// snapshots, has the positions written into a staging array (as the
// viewer's host path does), downloads the region roles when the region
// changes, moves the mouse tool (with --device mouse), and once, half way,
// changes the parameters (a rebuild on the haptic thread). At the end it
// prints the loop's timing (rate, tick p50/p99/max, jitter, late ticks).
// scripts/tsan builds it with -fsanitize=thread and runs it; it also
// measures the haptic rate of a scene on a machine without a display.
#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <tbb/global_control.h>

#include <chrono>
#include <cmath>
#include <memory>
#include <optional>
#include <thread>
#include <vector>

#include "apps/commands.hpp"
#include "apps/viewer/mouse_device.hpp"
#include "apps/viewer/path_device.hpp"
#include "apps/viewer/session.hpp"
#include "core/haptic_loop.hpp"

namespace {

using namespace tissue;
using Clock = std::chrono::steady_clock;

struct Options {
  std::string scene = "@kidney", backend, precision, depth, device = "scripted";
  double seconds = 5;
  int tbb_threads = 0;
  bool no_rebuild = false;
  bool realtime = false;
};

/// The display's side, every frame: snapshot, positions, region roles, mouse.
struct Display {
  HapticLoop& loop;
  viewer::MouseDevice* mouse;
  viewer::Session& session;
  std::vector<float> staging;
  bool host_positions = true;
  std::vector<std::uint8_t> roles;
  long region_version = -1;
  long frames = 0, region_downloads = 0;

  void frame(double t) {
    const HapticSnapshot s = loop.snapshot();
    if (host_positions) {  // a device backend writes device memory only: the viewer maps a GL buffer for it
      float* dst = staging.data();
      loop.post([dst](Simulation& sim) { sim.backend->write_positions(dst); }).get();
    }
    if (s.region_version != region_version) {
      region_version = s.region_version;
      loop.post([this](Simulation& sim) { roles = sim.backend->region().role; }).get();
      ++region_downloads;
    }
    if (mouse) {  // from the start to 4 mm past the surface target and back, once a second
      const double reach = session.approach + 0.004;
      const double d = 0.5 * reach * (1 - std::cos(2 * 3.14159265358979 * t));
      mouse->set_target(session.tool_start + d * session.press_dir);
    }
    ++frames;
  }
};

int run(const Options& o) {
  std::optional<tbb::global_control> threads;
  if (o.tbb_threads > 0) threads.emplace(tbb::global_control::max_allowed_parallelism, o.tbb_threads);
  viewer::Session session = viewer::make_session(app::load_scene_arg(o.scene), o.backend, o.precision, o.depth);
  std::unique_ptr<Device> device;
  viewer::MouseDevice* mouse = nullptr;
  if (o.device == "mouse") {
    auto m = std::make_unique<viewer::MouseDevice>(session.tool_start, 0.25);
    mouse = m.get();
    device = std::move(m);
  } else if (o.device == "scripted") {
    if (session.scene.tools.empty() || session.scene.tools.front().path.empty())
      throw std::runtime_error(session.scene.source + ": no scripted tool path to play");
    device = std::make_unique<viewer::PathDevice>(session.scene.tools.front().path, true);
  } else {
    throw std::invalid_argument(fmt::format("--device '{}' is neither scripted nor mouse", o.device));
  }
  HapticLoop::Options opt;
  opt.realtime = o.realtime;
  HapticLoop loop(*device, session.factory(), session.params, opt);
  Display display{loop, mouse, session, std::vector<float>(session.scene.nodes.size()),
                  session.scene.solver.backend == "cpu", {}};
  fmt::print("haptic session: {} on {} ({}), {} device, {:.1f} s\n", session.scene.source, session.scene.solver.backend,
             to_string(session.params.precision), o.device, o.seconds);
  loop.start();
  const auto t0 = Clock::now();
  bool rebuilt = o.no_rebuild;
  for (long k = 0;; ++k) {
    const double t = std::chrono::duration<double>(Clock::now() - t0).count();
    if (t > o.seconds) break;
    if (!rebuilt && t > 0.5 * o.seconds) {  // a parameter change, applied by the haptic thread
      LiveParams p = loop.snapshot().params;
      p.precision = p.precision == Precision::Float ? Precision::Double : Precision::Float;
      loop.request_params(p);
      rebuilt = true;
    }
    display.frame(t);
    std::this_thread::sleep_until(t0 + std::chrono::microseconds(16667 * (k + 1)));
  }
  loop.stop();
  const HapticSnapshot s = loop.snapshot();
  fmt::print("{}\n", describe(s.stats));
  fmt::print("haptic thread: {}\n", s.realtime ? "SCHED_FIFO (real-time)" : "normal priority");
  fmt::print("session: {} ticks in {:.2f} s ({:.1f} Hz), TLED {} steps/tick, {} display frames, {} region downloads, "
             "{} rebuilds, final |F| = {:.4f} N\n",
             s.stats.ticks, o.seconds, s.stats.session_rate_hz, s.steps_per_tick, display.frames,
             display.region_downloads, s.sim_version - 1, norm(s.rendered_force));
  if (!loop.status().empty()) {
    fmt::print(stderr, "haptic session: {}\n", loop.status());
    return 1;
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"tissue_haptic_session: the 1 kHz haptic loop with a display-like reader thread, without OpenGL"};
  Options o;
  app.add_option("scene", o.scene, "Scene XML file, or @kidney (default)");
  app.add_option("--backend", o.backend, "cpu | cuda (default: the scene's)");
  app.add_option("--precision", o.precision, "float | double (default: the scene's)");
  app.add_option("--depth", o.depth, "Region depth N or 'all'");
  app.add_option("--device", o.device, "scripted (the scene's path, repeated) | mouse (moved by the reader thread)");
  app.add_option("--seconds", o.seconds, "Wall seconds to run")->default_val(5);
  app.add_option("--tbb-threads", o.tbb_threads, "Cap TBB's threads (0: all cores)");
  app.add_flag("--no-rebuild", o.no_rebuild, "Skip the half-way parameter change");
  app.add_flag("--realtime", o.realtime, "SCHED_FIFO priority for the haptic thread (needs CAP_SYS_NICE)");
  try {
    app.parse(argc, argv);
    return run(o);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const std::exception& e) {
    fmt::print(stderr, "tissue_haptic_session: error: {}\n", e.what());
    return 1;
  }
}
