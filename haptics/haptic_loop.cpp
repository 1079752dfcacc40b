#include "haptics/haptic_loop.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>
#include <type_traits>

#if defined(__linux__)
#include <pthread.h>
#include <sched.h>
#endif

namespace tissue {
namespace {

using Clock = std::chrono::steady_clock;

static_assert(std::is_trivially_copyable_v<HapticSnapshot>, "snapshots are copied under a short lock");

/// Session histogram of tick work times: kHistBin-wide bins up to kHistBins * kHistBin.
constexpr double kHistBin = 5e-6;  // s
constexpr int kHistBins = 20000;   // 100 ms

double now_s() { return std::chrono::duration<double>(Clock::now().time_since_epoch()).count(); }

/// The q-quantile (0..1) of v, reordering v.
double quantile(std::vector<double>& v, double q) {
  if (v.empty()) return 0;
  const size_t k = std::min(v.size() - 1, static_cast<size_t>(std::ceil(q * double(v.size())) - 1));
  std::nth_element(v.begin(), v.begin() + long(k), v.end());
  return v[k];
}

/// The q-quantile of the session histogram (upper edge of the bin), or `max` past the last bin.
double histogram_quantile(const std::vector<std::uint32_t>& h, long total, double q, double max) {
  if (total <= 0) return 0;
  const long want = std::max(1L, static_cast<long>(std::ceil(q * double(total))));
  long seen = 0;
  for (int b = 0; b < kHistBins; ++b) {
    seen += h[b];
    if (seen >= want) return std::min(max, (b + 1) * kHistBin);
  }
  return max;
}

/// SCHED_FIFO at `priority` for the calling thread; false when refused.
bool make_realtime(int priority) {
#if defined(__linux__)
  sched_param sp{};
  sp.sched_priority = priority;
  return pthread_setschedparam(pthread_self(), SCHED_FIFO, &sp) == 0;
#else
  (void)priority;
  return false;
#endif
}

Simulated checked(Simulated s) {
  const Engine& e = s.engine();
  if (!e.model || !e.backend || !e.scheduler)
    throw std::invalid_argument("haptic loop: the simulation factory returned an incomplete simulation");
  return s;
}

}  // namespace

std::string describe(const HapticStats& s) {
  const double ms = 1e3;
  if (!s.paced)
    return fmt::format("haptic ticks run offline (no deadlines): {} ticks, tick work p50 {:.3f} ms, p99 {:.3f} ms, "
                       "max {:.3f} ms ({:.1f} ticks/s)",
                       s.ticks, ms * s.work_p50, ms * s.work_p99, ms * s.work_max, s.rate_hz);
  std::string line = fmt::format(
      "haptic {:.1f} Hz (target {:.0f} Hz), tick work p50 {:.3f} ms, p99 {:.3f} ms, max {:.3f} ms, "
      "wake-up jitter p99 {:.3f} ms; late {} of the last {} ticks (session: {} late, {} overruns, {} skipped "
      "of {} ticks, work p99 {:.3f} ms)",
      s.rate_hz, 1.0 / s.period, ms * s.work_p50, ms * s.work_p99, ms * s.work_max, ms * s.wake_p99, s.window_late,
      s.window_ticks, s.late, s.overruns, s.skipped, s.ticks, ms * s.session_p99);
  if (s.keeping_up) return line;
  if (s.work_p99 > s.period)
    return fmt::format(
        "SOLVER CANNOT KEEP UP: {} of the last {} ticks ended after the next deadline and the loop runs at {:.1f} Hz "
        "instead of {:.0f} Hz: tick work p99 {:.3f} ms exceeds the {:.3f} ms period. Reduce the region depth, use "
        "float, or a faster backend. {}",
        s.window_late, s.window_ticks, s.rate_hz, 1.0 / s.period, ms * s.work_p99, ms * s.period, line);
  return fmt::format(
      "HAPTIC DEADLINES MISSED: {} of the last {} ticks ended after the next deadline although the tick work (p99 "
      "{:.3f} ms) fits the {:.3f} ms period: the haptic thread was not scheduled in time (wake-up jitter p99 {:.3f} "
      "ms). The machine is busy (other processes, a software renderer) or short of a core for this thread; "
      "real-time scheduling (HapticLoop::Options::realtime) helps. {}",
      s.window_late, s.window_ticks, ms * s.work_p99, ms * s.period, ms * s.wake_p99, line);
}

HapticLoop::HapticLoop(std::vector<Device*> devices, EngineFactory factory, LiveParams params, Options options)
    : devices_(std::move(devices)),
      factory_(std::move(factory)),
      options_(options),
      params_(params),
      sim_(checked(factory_(params))),
      period_(engine().scheduler->settings().tick) {
  if (options_.window < 2 || options_.stats_every < 1 || options_.max_lag < 1)
    throw std::invalid_argument(fmt::format(
        "haptic loop: window = {} must be >= 2, stats_every = {} >= 1 and max_lag = {} >= 1", options_.window,
        options_.stats_every, options_.max_lag));
  if (devices_.size() != std::size_t(engine().scheduler->n_tools()))
    throw std::invalid_argument(fmt::format("haptic loop: {} devices for the scene's {} tools (one device per tool)",
                                            devices_.size(), engine().scheduler->n_tools()));
  options_.coupling.period = period_;
  for (Device* d : devices_) {
    if (d == nullptr) throw std::invalid_argument("haptic loop: a tool's device is null");
    clocks_.push_back(std::make_unique<SessionClock>(*d, clock_offset_));
    coupled_.push_back(std::make_unique<CoupledDevice>(*clocks_.back(), options_.coupling));
    coupled_ptrs_.push_back(coupled_.back().get());
  }
  if (sim_.session) sim_.session->drive_with(coupled_ptrs_);
  for (auto* v : {&work_ring_, &wake_ring_, &start_ring_, &scratch_}) v->assign(options_.window, 0.0);
  late_ring_.assign(options_.window, 0);
  histogram_.assign(kHistBins, 0);
  local_.params = params_;
  local_.n_tools = engine().scheduler->n_tools();
  for (int t = 0; t < local_.n_tools; ++t) {
    const ToolSetting& tool = engine().scheduler->settings().tools[t];
    local_.tools[t].radius = tool.shape.radius;
    local_.tools[t].shaft = tool.shape.shaft;
    local_.tools[t].axis = tool.axis;
  }
  local_.sim_version = 1;
  local_.mesh_version = 1;
  local_.region = engine().scheduler->region();
  local_.steps_per_tick = engine().scheduler->steps_per_tick();
  local_.stats.period = period_;
  last_region_ = local_.region;
  session_start_ = now_s();
  publish();
}

HapticLoop::~HapticLoop() { stop(); }

void HapticLoop::start() {
  if (running_) return;
  ring_pos_ = ring_count_ = 0;
  std::fill(histogram_.begin(), histogram_.end(), 0);
  const HapticStats fresh{.period = period_, .paced = true};
  local_.stats = fresh;
  session_start_ = now_s();
  stop_ = false;
  running_ = true;
  thread_ = std::thread(&HapticLoop::thread_main, this);
}

void HapticLoop::stop() {
  if (!running_) return;
  {
    std::lock_guard lk(req_mutex_);
    stop_ = true;
  }
  req_cv_.notify_all();
  thread_.join();
  running_ = false;
  serve_requests();  // nobody else will: run what the display still waits for
  publish();
}

void HapticLoop::run_ticks(long n) {
  if (running_) throw std::logic_error("HapticLoop::run_ticks: stop the haptic thread first");
  serve_requests();
  local_.stats.paced = false;
  for (long k = 0; k < n; ++k) {
    const double t0 = now_s();
    const bool ok = tick_once();
    record_timing(now_s() - t0, 0.0, false);
    if (!ok) {
      publish();
      throw SimulationError(status());
    }
  }
  update_stats();
  publish();
}

HapticSnapshot HapticLoop::snapshot() const {
  std::lock_guard lk(snap_mutex_);
  return published_;
}

void HapticLoop::request_params(const LiveParams& params) {
  if (!running_) {
    rebuild(params);
    publish();
    return;
  }
  {
    std::lock_guard lk(req_mutex_);
    pending_params_ = params;
    has_requests_ = true;
  }
  req_cv_.notify_all();
}

std::future<void> HapticLoop::post(std::function<void(Engine&)> task) {
  std::packaged_task<void(Engine&)> job(std::move(task));
  std::future<void> done = job.get_future();
  if (!running_) {
    job(engine());
    return done;
  }
  {
    std::lock_guard lk(req_mutex_);
    tasks_.push_back(std::move(job));
    has_requests_ = true;
  }
  req_cv_.notify_all();
  return done;
}

void HapticLoop::set_friction(double mu) {
  if (const std::string e = tool_friction_error("every tool", mu); !e.empty()) throw std::invalid_argument(e);
  post([this, mu](Engine& e) {
    for (int t = 0; t < e.scheduler->n_tools(); ++t)
      if (sim_.session) sim_.session->set_tool_friction(t, mu);  // kept across its cuts
      else e.scheduler->set_tool_friction(t, mu);
    params_.friction = mu;
    local_.params = params_;
    publish();
  });
}

std::string HapticLoop::status() const {
  std::lock_guard lk(req_mutex_);
  return status_;
}

void HapticLoop::set_status(std::string s) {
  std::lock_guard lk(req_mutex_);
  status_ = std::move(s);
}

void HapticLoop::serve_requests() {
  std::vector<std::packaged_task<void(Engine&)>> tasks;
  std::optional<LiveParams> params;
  {
    std::lock_guard lk(req_mutex_);
    tasks.swap(tasks_);
    params.swap(pending_params_);
    has_requests_ = false;
  }
  if (params) rebuild(*params);
  for (auto& t : tasks) t(engine());
}

void HapticLoop::rebuild(const LiveParams& params) {
  Simulated next;
  try {
    next = checked(factory_(params));
    const Scheduler& sched = *next.engine().scheduler;
    if (std::abs(sched.settings().tick - period_) > 1e-12)
      throw std::invalid_argument(fmt::format("the haptic tick changed from {} s to {} s", period_,
                                              sched.settings().tick));
    if (sched.n_tools() != int(devices_.size()))
      throw std::invalid_argument(fmt::format("the scene's tools changed from {} to {}", devices_.size(),
                                              sched.n_tools()));
    if (next.session) next.session->drive_with(coupled_ptrs_);
  } catch (const std::exception& e) {
    set_status(fmt::format("parameters refused (E = {} Pa, nu = {}, depth {}, {}); keeping the running simulation: {}",
                           params.E, params.nu, params.depth == kDepthAll ? "all" : std::to_string(params.depth),
                           to_string(params.precision), e.what()));
    return;
  }
  clock_offset_ += engine().scheduler->time();
  sim_ = Simulated{};  // the old one goes first (its scheduler before the backend and model it refers to)
  sim_ = std::move(next);
  params_ = params;
  failed_ = false;
  set_status("");
  local_.params = params_;
  local_.failed = false;
  local_.tick = -1;
  local_.contact_nodes = 0;
  local_.tissue_force = {};
  for (ToolView& t : local_.tools) t.tissue_force = {};
  local_.sim_version += 1;
  local_.mesh_version += 1;
  local_.cuts = 0;
  local_.region_version += 1;
  local_.region = last_region_ = engine().scheduler->region();
  local_.steps_per_tick = engine().scheduler->steps_per_tick();
  last_seeds_.clear();
}

bool HapticLoop::tick_once() {
  try {
    // a session's tick may cut: the scheduler then steps a new mesh
    const TickReport rep = sim_.session ? sim_.session->tick() : engine().scheduler->tick(coupled_ptrs_);
    Scheduler& sched = *engine().scheduler;
    if (sim_.session && sim_.session->cuts() != local_.cuts) {
      local_.cuts = sim_.session->cuts();
      local_.mesh_version += 1;
      local_.region_version += 1;
    }
    local_.tick = sched.ticks();
    local_.time = clock_offset_ + rep.time;
    local_.n_tools = rep.n_tools;
    for (int t = 0; t < rep.n_tools; ++t) {
      const CouplingState& c = coupled_[t]->state();
      const ToolShape& shape = sched.settings().tools[t].shape;
      local_.tools[t] = {c.device, rep.tools[t].tip, rep.tools[t].axis, rep.tools[t].force, c.rendered,
                         shape.radius, shape.shaft, rep.tools[t].contact_nodes, rep.tools[t].grasped,
                         rep.tools[t].grasp, c.clamped};
    }
    const ToolView& first = local_.tools[0];
    local_.device = first.device;
    local_.tool = first.tool;
    local_.tissue_force = first.tissue_force;
    local_.rendered_force = first.rendered_force;
    local_.clamped = first.clamped;
    local_.contact_nodes = rep.contact_nodes;
    local_.max_disp = rep.max_disp;
    local_.residual = rep.residual;
    local_.equilibrium = rep.equilibrium;
    const RegionSizes& r = sched.region();
    if (r.depth != last_region_.depth || r.n_inner != last_region_.n_inner || r.n_halo != last_region_.n_halo ||
        r.n_elems != last_region_.n_elems || sched.seeds() != last_seeds_) {
      last_region_ = r;
      last_seeds_ = sched.seeds();
      local_.region = r;
      local_.region_version += 1;
    }
    return true;
  } catch (const std::exception& e) {
    failed_ = true;
    local_.failed = true;
    set_status(fmt::format("the solver stopped at tick {}: {}", engine().scheduler->ticks(), e.what()));
    return false;
  }
}

void HapticLoop::record_timing(double work, double wake, bool late) {
  const long w = options_.window;
  const long i = ring_pos_;
  work_ring_[i] = work;
  wake_ring_[i] = wake;
  start_ring_[i] = now_s();
  late_ring_[i] = late ? 1 : 0;
  ring_pos_ = (i + 1) % w;
  ring_count_ = std::min(ring_count_ + 1, w);
  const int bin = std::min(kHistBins - 1, static_cast<int>(work / kHistBin));
  histogram_[bin] += 1;
  HapticStats& s = local_.stats;
  s.ticks += 1;
  s.late += late ? 1 : 0;
  s.overruns += work > period_ ? 1 : 0;
  s.session_max = std::max(s.session_max, work);
  if (s.ticks % options_.stats_every == 0) update_stats();
}

void HapticLoop::update_stats() {
  HapticStats& s = local_.stats;
  const long n = ring_count_;
  s.window_ticks = n;
  if (n == 0) return;
  scratch_.assign(work_ring_.begin(), work_ring_.begin() + n);
  s.work_p50 = quantile(scratch_, 0.50);
  s.work_p99 = quantile(scratch_, 0.99);
  s.work_max = *std::max_element(scratch_.begin(), scratch_.end());
  scratch_.assign(wake_ring_.begin(), wake_ring_.begin() + n);
  s.wake_p99 = quantile(scratch_, 0.99);
  s.wake_max = *std::max_element(scratch_.begin(), scratch_.end());
  s.window_late = 0;
  for (long k = 0; k < n; ++k) s.window_late += late_ring_[k];
  // oldest entry: ring_pos_ once the ring is full, else 0; newest: just before ring_pos_
  const long w = options_.window;
  const double oldest = start_ring_[n < w ? 0 : ring_pos_];
  const double newest = start_ring_[(ring_pos_ + w - 1) % w];
  s.rate_hz = n > 1 && newest > oldest ? double(n - 1) / (newest - oldest) : 0;
  s.steps_per_s = s.rate_hz * local_.steps_per_tick;
  s.session_p50 = histogram_quantile(histogram_, s.ticks, 0.50, s.session_max);
  s.session_p99 = histogram_quantile(histogram_, s.ticks, 0.99, s.session_max);
  const double elapsed = now_s() - session_start_;
  s.session_rate_hz = elapsed > 0 ? double(s.ticks) / elapsed : 0;
  const bool rate_ok = !running_ || n < 100 || s.rate_hz >= 0.98 / period_;
  s.keeping_up = s.window_late * 100 <= n && rate_ok;
}

void HapticLoop::publish(bool haptic_thread) {
  std::unique_lock lk(snap_mutex_, std::defer_lock);
  if (haptic_thread) {
    if (!lk.try_lock()) return;  // the display is copying: the next tick publishes
  } else {
    lk.lock();
  }
  published_ = local_;
}

void HapticLoop::thread_main() {
  local_.realtime = options_.realtime && make_realtime(options_.realtime_priority);
  const auto T = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(period_));
  const Clock::time_point t0 = Clock::now();
  long k = 0;  // index of the next deadline t0 + k T
  while (!stop_) {
    if (has_requests_) {
      const long sim_before = local_.sim_version;
      serve_requests();
      if (local_.sim_version != sim_before) {
        // a rebuild paused the loop: resume at the next grid point, not late
        k = std::max(k, static_cast<long>((Clock::now() - t0) / T) + 1);
        publish(true);
      }
    }
    if (failed_) {
      publish();  // blocking: the failure must reach the display
      std::unique_lock lk(req_mutex_);
      req_cv_.wait(lk, [&] { return stop_ || has_requests_; });
      continue;
    }
    Clock::time_point deadline = t0 + k * T;
    const Clock::time_point now = Clock::now();
    if (now - deadline > options_.max_lag * T) {
      const long behind = static_cast<long>((now - deadline) / T);
      local_.stats.skipped += behind;
      k += behind;
      deadline = t0 + k * T;
    }
    std::this_thread::sleep_until(deadline);
    const Clock::time_point start = Clock::now();
    tick_once();
    const Clock::time_point end = Clock::now();
    const double work = std::chrono::duration<double>(end - start).count();
    const double wake = std::chrono::duration<double>(start - deadline).count();
    record_timing(work, wake, end > deadline + T);
    publish(true);
    ++k;
  }
}

}  // namespace tissue
