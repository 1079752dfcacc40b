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
//
// Soak runs (scripts/soak, docs/reliability.md): --device soak moves the
// tool through endless random press / drag / grasp / release cycles
// (apps/viewer/soak_device.hpp) with no rebuild; every --sample-every
// seconds the session records its resident memory (/proc/self/statm), the
// backend's device memory, late ticks and the tick p99, and checks every
// display frame for a non-finite force. With --flat-mb M it fails (exit 1)
// when the resident or device memory moves by more than M MiB after the
// warm-up, or when a force was ever non-finite.
#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <tbb/global_control.h>

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <optional>
#include <thread>
#include <vector>

#include "apps/commands.hpp"
#include "apps/viewer/mouse_device.hpp"
#include "apps/viewer/path_device.hpp"
#include "apps/viewer/session.hpp"
#include "apps/viewer/soak_device.hpp"
#include "haptics/haptic_loop.hpp"
#include "io/atomic_file.hpp"

namespace {

using namespace tissue;
using Clock = std::chrono::steady_clock;

struct Options {
  std::string scene = "@kidney", backend, precision, depth, device = "scripted";
  double seconds = 5;
  int tbb_threads = 0;
  bool no_rebuild = false;
  bool realtime = false;
  double sample_every = 10;  ///< s between memory samples
  double warmup = -1;        ///< s before the flatness check starts (-1: min(30 s, a fifth of the run))
  double flat_mb = -1;       ///< MiB the memory may move after the warm-up (-1: report only)
  std::string csv;           ///< the samples as CSV
  std::uint64_t seed = 1;    ///< soak device
  double pull = 0;           ///< soak device: grasp pull in press depths (0: sideways)
  double soak_start = 0;     ///< soak device: start this many seconds into its series
};

/// Resident set size of this process (bytes), from /proc/self/statm (0 where unavailable).
double resident_bytes() {
  std::FILE* f = std::fopen("/proc/self/statm", "r");
  if (!f) return 0;
  long pages = 0, resident = 0;
  const int got = std::fscanf(f, "%ld %ld", &pages, &resident);
  std::fclose(f);
  return got == 2 ? double(resident) * double(sysconf(_SC_PAGESIZE)) : 0;
}

/// One memory sample of the session.
struct Sample {
  double t = 0;               ///< wall s
  long ticks = 0, late = 0;
  double rss = 0;             ///< bytes
  double gpu_held = -1;       ///< bytes held by the backend's arrays (-1: no device)
  double gpu_used = -1;       ///< bytes in use on the device, all processes
  double p99 = 0;             ///< tick work p99 over the window (s)
  long nonfinite = 0;         ///< display frames that saw a non-finite force so far
};

constexpr double kMiB = 1024.0 * 1024.0;

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
      loop.post([this](Engine& sim) {  // sized on the haptic thread: a cut changes the node count
            staging.resize(3 * std::size_t(sim.model->n_nodes));
            sim.backend->write_positions(staging.data());
          }).get();
    }
    if (s.region_version != region_version) {
      region_version = s.region_version;
      loop.post([this](Engine& sim) { roles = sim.backend->region().role; }).get();
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

/// The soak's summary: memory ranges after the warm-up, late ticks, NaN.
/// Writes the CSV; returns 1 when --flat-mb is exceeded or a force was not finite.
int soak_verdict(const Options& o, const std::vector<Sample>& samples, long nonfinite) {
  if (!o.csv.empty()) {
    std::string text = "t_s,ticks,late,rss_bytes,gpu_held_bytes,gpu_used_bytes,tick_p99_s,nonfinite_frames\n";
    for (const Sample& x : samples)
      text += fmt::format("{:.3f},{},{},{:.0f},{:.0f},{:.0f},{:.6g},{}\n", x.t, x.ticks, x.late, x.rss, x.gpu_held,
                          x.gpu_used, x.p99, x.nonfinite);
    io::write_file_atomic(o.csv, text);
  }
  const double warmup = o.warmup >= 0 ? o.warmup : std::min(30.0, 0.2 * o.seconds);
  double lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300};
  int n = 0;
  for (const Sample& x : samples) {
    if (x.t < warmup) continue;
    const double v[3] = {x.rss, x.gpu_held, x.gpu_used};
    for (int k = 0; k < 3; ++k) lo[k] = std::min(lo[k], v[k]), hi[k] = std::max(hi[k], v[k]);
    ++n;
  }
  if (n < 2) {
    fmt::print(stderr, "soak: fewer than two samples after the {:.0f} s warm-up: run longer or sample more often\n",
               warmup);
    return 1;
  }
  const Sample& last = samples.back();
  const char* names[3] = {"resident memory", "GPU memory held by the backend", "GPU memory in use"};
  fmt::print("soak: {:.0f} s, {} ticks, {} late ({:.3f} %), {} display frames with a non-finite force\n", last.t,
             last.ticks, last.late, last.ticks ? 100.0 * last.late / last.ticks : 0.0, nonfinite);
  int rc = nonfinite > 0 ? 1 : 0;
  for (int k = 0; k < 3; ++k) {
    if (hi[k] < 0) continue;  // no device
    const double moved = (hi[k] - lo[k]) / kMiB;
    const bool flat = o.flat_mb < 0 || moved <= o.flat_mb;
    fmt::print("soak: {} after the {:.0f} s warm-up: {:.2f} .. {:.2f} MiB ({:.3f} MiB range over {} samples){}\n",
               names[k], warmup, lo[k] / kMiB, hi[k] / kMiB, moved, n,
               o.flat_mb < 0 ? "" : flat ? fmt::format(": flat within {:g} MiB", o.flat_mb)
                                         : fmt::format(": NOT FLAT (limit {:g} MiB)", o.flat_mb));
    if (!flat) rc = 1;
  }
  return rc;
}

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
  } else if (o.device == "soak") {
    auto d = std::make_unique<viewer::SoakDevice>(session.tool_start, session.press_dir, session.approach,
                                                  session.tool_radius, o.seed, o.pull);
    d->set_start(o.soak_start);
    device = std::move(d);
  } else {
    throw std::invalid_argument(fmt::format("--device '{}' is none of scripted, mouse and soak", o.device));
  }
  const bool soak = o.device == "soak";
  HapticLoop::Options opt;
  opt.realtime = o.realtime;
  HapticLoop loop(*device, session.factory(), session.params, opt);
  Display display{loop, mouse, session, std::vector<float>(session.scene.nodes.size()),
                  session.scene.solver.backend == "cpu", {}};
  fmt::print("haptic session: {} on {} ({}), {} device, {:.1f} s\n", session.scene.source, session.scene.solver.backend,
             to_string(session.params.precision), o.device, o.seconds);
  std::vector<Sample> samples;
  long nonfinite = 0;
  auto sample = [&](double t) {
    const HapticSnapshot s = loop.snapshot();
    DeviceMemory dm;  // read on the haptic thread, between two ticks
    loop.post([&dm](Engine& sim) { dm = sim.backend->device_memory(); }).get();
    Sample x{t, s.stats.ticks, s.stats.late, resident_bytes(), double(dm.held),
             dm.total >= 0 ? double(dm.total - dm.free) : -1.0, s.stats.work_p99, nonfinite};
    const auto mib = [](double b) { return b < 0 ? std::string("     n/a") : fmt::format("{:8.2f}", b / kMiB); };
    fmt::print("  {:7.0f} s  {:9} ticks  RSS {:8.2f} MiB  GPU held {} MiB  GPU used {} MiB  late {:6}  "
               "p99 {:6.3f} ms  contact {:4}  non-finite {}\n",
               x.t, x.ticks, x.rss / kMiB, mib(x.gpu_held), mib(x.gpu_used), x.late, 1e3 * x.p99,
               s.contact_nodes, nonfinite);
    std::fflush(stdout);
    samples.push_back(x);
  };
  loop.start();
  const auto t0 = Clock::now();
  bool rebuilt = o.no_rebuild || soak;
  double next_sample = 0;
  for (long k = 0;; ++k) {
    const double t = std::chrono::duration<double>(Clock::now() - t0).count();
    if (soak) {
      const HapticSnapshot s = loop.snapshot();
      if (!std::isfinite(s.rendered_force.x + s.rendered_force.y + s.rendered_force.z + s.max_disp)) ++nonfinite;
      if (t >= next_sample || t > o.seconds) {
        sample(t);
        next_sample += o.sample_every;
      }
    }
    if (t > o.seconds) break;
    if (soak && !loop.status().empty()) {  // the solver stopped: a last sample, then the verdict
      sample(t);
      break;
    }
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
             "{} rebuilds, {} cuts since the last (re)build, {} nodes, final |F| = {:.4f} N\n",
             s.stats.ticks, o.seconds, s.stats.session_rate_hz, s.steps_per_tick, display.frames,
             display.region_downloads, s.sim_version - 1, s.cuts, display.staging.size() / 3, norm(s.rendered_force));
  int rc = 0;
  if (!loop.status().empty()) {
    fmt::print(stderr, "haptic session: {}\n", loop.status());
    rc = 1;
  }
  if (soak) rc = std::max(rc, soak_verdict(o, samples, nonfinite));
  return rc;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"tissue_haptic_session: the 1 kHz haptic loop with a display-like reader thread, without OpenGL"};
  Options o;
  app.add_option("scene", o.scene, "Scene XML file, or @kidney (default)");
  app.add_option("--backend", o.backend, "cpu | cuda (default: the scene's)");
  app.add_option("--precision", o.precision, "float | double (default: the scene's)");
  app.add_option("--depth", o.depth, "Region depth N or 'all'");
  app.add_option("--device", o.device,
                 "scripted (the scene's path, repeated) | mouse (moved by the reader thread) | soak (random press, "
                 "drag, grasp and release cycles)");
  app.add_option("--seconds", o.seconds, "Wall seconds to run")->default_val(5)->check(CLI::PositiveNumber);
  app.add_option("--tbb-threads", o.tbb_threads, "Cap TBB's threads (0: all cores)");
  app.add_flag("--no-rebuild", o.no_rebuild, "Skip the half-way parameter change");
  app.add_flag("--realtime", o.realtime, "SCHED_FIFO priority for the haptic thread (needs CAP_SYS_NICE)");
  app.add_option("--sample-every", o.sample_every, "Soak: seconds between memory samples")
      ->default_val(10)->check(CLI::PositiveNumber);
  app.add_option("--warmup", o.warmup, "Soak: seconds before the flatness check (default: min(30, a fifth of the run))")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--flat-mb", o.flat_mb, "Soak: fail when memory moves by more than this many MiB after the warm-up")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--csv", o.csv, "Soak: write the memory samples as CSV");
  app.add_option("--seed", o.seed, "Soak: the random motion's seed")->default_val(1);
  app.add_option("--soak-start", o.soak_start, "Soak: start this many seconds into the motion's series (a late "
                                               "cycle at once)")->default_val(0)->check(CLI::NonNegativeNumber);
  app.add_option("--pull", o.pull, "Soak: the grasp pulls back by this many press depths before the release (0: "
                                   "it moves sideways)")->default_val(0)->check(CLI::NonNegativeNumber);
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
