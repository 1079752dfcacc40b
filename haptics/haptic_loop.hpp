// The haptic loop (docs/design.md section 3, "Loops"): its own thread runs one
// Scheduler tick per period (1 ms) on a steady clock, with the tool driven
// through the virtual coupling of haptics/force_coupling.hpp.
//
// Timing. Deadline k is t0 + k T (T = the scheduler's tick); the thread
// sleeps until it (std::this_thread::sleep_until on steady_clock), runs the
// tick, and moves to deadline k + 1, so timing errors never accumulate
// (no drift). A tick is *late* when it ends after the next tick's deadline
// (its work took longer than the period, or it started too late); an
// *overrun* is a tick whose work alone exceeded T. When the loop has fallen
// more than `max_lag` periods behind it drops the missed deadlines (counted
// as skipped) instead of running a burst of ticks: the grid stays the same,
// and simulated time (one T per executed tick) falls behind wall time. The
// loop measures its achieved rate, the tick work time (p50, p99, max) and the
// start lateness (jitter), over a sliding window and over the whole session,
// and says clearly when the solver cannot keep up (describe()).
//
// Sharing with the display thread, without data races:
// - the haptic thread publishes a HapticSnapshot (tool, forces, contact,
//   region, statistics) after every tick: it copies it under a mutex taken
//   with try_lock, so it never waits for the display (if the display is
//   copying at that instant, the next tick publishes); the display's copy
//   holds the mutex for the time of a ~400-byte memcpy;
// - everything else that touches the simulation (Backend::write_positions
//   into a mapped vertex buffer, Backend::region() when the region changed)
//   is posted as a task, which the haptic thread runs between two ticks; the
//   display waits on the returned future, the haptic thread never waits;
// - parameter changes (E, nu, region depth, precision) are requested by the
//   display and applied by the haptic thread between ticks: it builds anew
//   through the factory (an Engine, or a Session where the scene has a
//   blade, whose ticks may cut: a new model and backend; the tissue
//   restarts from rest, the device's clock and the coupling go on), and
//   keeps the old one, reporting why, when the factory throws.
// The owner thread (the one that constructs the loop) calls start, stop,
// post, request_params and run_ticks; snapshot() may be called from any
// thread.
#pragma once

#include <array>
#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <future>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "core/backend.hpp"
#include "haptics/force_coupling.hpp"
#include "core/scheduler.hpp"
#include "session/engine.hpp"
#include "session/session.hpp"

namespace tissue {

/// Solver parameters the display may change while the loop runs.
struct LiveParams {
  double E = 3000;    ///< Young's modulus for every element set (Pa); <= 0: keep the scene's materials
  double nu = 0.45;   ///< Poisson's ratio (with E)
  int depth = 5;      ///< region depth; kDepthAll = whole mesh, kDepthAuto = adaptive
  Precision precision = Precision::Float;
  /// The law's optional terms (docs/materials.md), for every element set;
  /// < 0: keep the scene's.
  double fibre_eta = -1;   ///< fibre stiffness (Pa; 0 = none); a set without a direction gets x
  int prony_terms = -1;    ///< Prony terms (0 = elastic), with prony_g / prony_tau
  double prony_g[kMaxProny] = {}, prony_tau[kMaxProny] = {};
  /// Every tool's Coulomb friction coefficient (docs/contact.md); < 0: the
  /// scene's. Changed live by HapticLoop::set_friction, without a rebuild.
  double friction = -1;
  /// The first tool becomes a blade (docs/cutting.md, "The blade"): the
  /// viewer's scalpel. Its edge runs along the tool's direction for
  /// kScalpelLength from the tip, kScalpelThickness thick; the loop's device
  /// button (the mouse's right button) cuts.
  bool scalpel = false;
};

/// The scalpel's edge length and thickness (m).
inline constexpr double kScalpelLength = 0.02;
inline constexpr double kScalpelThickness = 1e-3;

/// What the loop runs: an Engine (session/engine.hpp: the model, a backend
/// holding it, the Scheduler over both; built together, destroyed
/// together), or a Session over one, which also makes its blades' cuts
/// (docs/cutting.md) and so replaces the engine's mesh, model and backend
/// between two ticks (HapticSnapshot::mesh_version counts the changes).
struct Simulated {
  Simulated() = default;
  Simulated(Engine e) : own(std::move(e)) {}                      // NOLINT: an engine is a simulation
  Simulated(std::unique_ptr<Session> s) : session(std::move(s)) {}  // NOLINT: so is a session
  Engine& engine() { return session ? session->engine() : own; }
  Engine own;
  std::unique_ptr<Session> session;
};

/// Builds what the loop runs for the parameters (the app supplies it, with
/// build_engine, or a Session for a scene with a blade). Throws, with a
/// message naming the rule broken, for parameters it cannot use.
using EngineFactory = std::function<Simulated(const LiveParams&)>;

/// Timing of the loop. Window figures cover the last `window` ticks;
/// session figures every tick since start() (or the first run_ticks()).
struct HapticStats {
  double period = 1e-3;        ///< T (s)
  long ticks = 0;              ///< ticks run this session
  long late = 0;               ///< ticks that ended after the next tick's deadline
  long overruns = 0;           ///< ticks whose work alone took longer than T
  long skipped = 0;            ///< deadlines dropped after falling > max_lag periods behind
  long window_ticks = 0;       ///< ticks in the window
  long window_late = 0;        ///< late ticks in the window
  double rate_hz = 0;          ///< achieved tick rate over the window (1/s)
  double work_p50 = 0, work_p99 = 0, work_max = 0;           ///< tick work time, window (s)
  double wake_p99 = 0, wake_max = 0;                         ///< start lateness (jitter), window (s)
  double session_p50 = 0, session_p99 = 0, session_max = 0;  ///< tick work time, session (s)
  double session_rate_hz = 0;  ///< ticks per wall second since start (1/s)
  double steps_per_s = 0;      ///< TLED steps per wall second over the window
  bool keeping_up = true;      ///< window: <= 1% late and rate within 2% of 1/T
  bool paced = false;          ///< ticks ran on the haptic thread against deadlines (false: run_ticks,
                               ///< as fast as possible, no deadlines: rate and lateness mean nothing)
};

/// One line: rate, work percentiles, jitter and late ticks. When keeping_up
/// is false it starts with the cause: "SOLVER CANNOT KEEP UP" (the tick work
/// p99 exceeds the period) or "HAPTIC DEADLINES MISSED" (the work fits, the
/// thread was not scheduled in time).
std::string describe(const HapticStats& s);

/// One tool as the display sees it.
struct ToolView {
  Vec3<double> device = {};            ///< device (hand) position (m)
  Vec3<double> tool = {};              ///< proxy: the tool tip the tissue feels (m)
  Vec3<double> axis = {0, 0, 1};       ///< shaft axis (unit)
  Vec3<double> tissue_force = {};      ///< raw solver force on the tool (N)
  Vec3<double> rendered_force = {};    ///< force sent to the device: coupled and clamped (N)
  double radius = 0, shaft = 0;        ///< the tool's shape (m)
  index_t contact_nodes = 0;           ///< surface nodes in contact
  index_t grasped = 0;                 ///< of which grasped
  bool grasp = false;                  ///< grasp button held
  bool clamped = false;                ///< the coupling force exceeded the device maximum
};

/// What the display reads after each tick.
struct HapticSnapshot {
  long tick = -1;                      ///< scheduler ticks done (-1: none yet)
  double time = 0;                     ///< simulated time of the session, across rebuilds (s)
  int n_tools = 0;
  std::array<ToolView, kMaxTools> tools = {};  ///< per tool (scene order)
  Vec3<double> device = {};            ///< tools[0].device
  Vec3<double> tool = {};              ///< tools[0].tool
  Vec3<double> tissue_force = {};      ///< tools[0].tissue_force
  Vec3<double> rendered_force = {};    ///< tools[0].rendered_force
  bool clamped = false;                ///< tools[0].clamped
  index_t contact_nodes = 0;           ///< surface nodes in contact with any tool
  RegionSizes region;                  ///< current deformation region
  long region_version = 0;             ///< changes whenever the region changes
  long sim_version = 0;                ///< changes on every (re)build of the simulation
  long mesh_version = 0;               ///< changes on every (re)build and every cut: the mesh is new
  long cuts = 0;                       ///< the blades' cuts since the (re)build
  int steps_per_tick = 0;              ///< TLED steps per tick
  double max_disp = 0;                 ///< m
  double residual = 0;                 ///< relative free-node residual
  bool equilibrium = false;
  bool failed = false;                 ///< the solver stopped (see HapticLoop::status())
  bool realtime = false;               ///< the haptic thread runs with SCHED_FIFO priority
  LiveParams params;                   ///< parameters of the running simulation
  HapticStats stats;
};

class HapticLoop {
 public:
  struct Options {
    CouplingParams coupling;  ///< its period is replaced by the scheduler's tick
    int window = 1000;        ///< ticks in the statistics window
    int stats_every = 100;    ///< ticks between statistics updates
    int max_lag = 10;         ///< periods behind before deadlines are dropped
    /// Ask for SCHED_FIFO priority `realtime_priority` for the haptic thread
    /// (Linux; needs CAP_SYS_NICE or an rtprio limit). Refused: the thread
    /// runs at normal priority and HapticSnapshot::realtime stays false.
    /// Beware that a real-time thread whose solver cannot keep up never
    /// sleeps; the kernel's RT throttling (95% by default) still lets the
    /// rest of the machine run.
    bool realtime = false;
    int realtime_priority = 80;
  };

  /// Builds the first simulation synchronously (factory exceptions reach the
  /// caller). One device per tool of the scene, in its order, each behind
  /// its own virtual coupling; the devices must outlive the loop; they are
  /// read and sent forces on the haptic thread only, so a device shared with
  /// the display must synchronise itself (viewer's MouseDevice does).
  HapticLoop(std::vector<Device*> devices, EngineFactory factory, LiveParams params, Options options);
  HapticLoop(Device& device, EngineFactory factory, LiveParams params, Options options)
      : HapticLoop(std::vector<Device*>{&device}, std::move(factory), params, options) {}
  HapticLoop(Device& device, EngineFactory factory, LiveParams params)
      : HapticLoop(device, std::move(factory), params, Options{}) {}
  ~HapticLoop();
  HapticLoop(const HapticLoop&) = delete;
  HapticLoop& operator=(const HapticLoop&) = delete;

  /// Starts the haptic thread (no-op when running); statistics restart.
  void start();
  /// Stops and joins the haptic thread, then runs requests still queued.
  void stop();
  bool running() const { return running_; }

  /// Runs n ticks on the calling thread as fast as possible (headless
  /// pictures, tests); the loop must be stopped. Throws SimulationError.
  void run_ticks(long n);

  /// The latest published snapshot (any thread).
  HapticSnapshot snapshot() const;

  /// Requests new parameters; applied between ticks (immediately when
  /// stopped). A failed rebuild keeps the running simulation; status() says why.
  void request_params(const LiveParams& params);

  /// Every tool's friction coefficient from the next tick on (between two
  /// ticks, no rebuild: the contacts stay), and in the parameters a later
  /// rebuild uses. Throws std::invalid_argument (at once) for a value that
  /// is not finite and >= 0.
  void set_friction(double mu);

  /// Runs task(simulation) on the haptic thread between two ticks (on the
  /// calling thread when stopped). The future carries its exception.
  std::future<void> post(std::function<void(Engine&)> task);

  /// "" when all is well; otherwise why the solver stopped or a parameter
  /// change was refused (any thread).
  std::string status() const;

  /// The coupled device of a tool the scheduler drives (owner thread, loop stopped).
  const CoupledDevice& coupled(int tool = 0) const { return *coupled_.at(tool); }
  double period() const { return period_; }

 private:
  void thread_main();
  void serve_requests();
  void rebuild(const LiveParams& params);
  bool tick_once();  ///< one tick + publish; false when the solver failed
  void record_timing(double work, double wake, bool late);
  void update_stats();
  void publish(bool haptic_thread = false);  ///< haptic thread: try_lock, may skip
  void set_status(std::string s);

  /// The device on the session's clock: a rebuilt simulation restarts its
  /// own time at 0, the device's time goes on (a scripted path continues
  /// instead of jumping back to its start).
  class SessionClock : public Device {
   public:
    SessionClock(Device& d, const double& offset) : device_(d), offset_(offset) {}
    ToolInput read(double t) override { return device_.read(t + offset_); }
    void send_force(const Vec3<double>& f) override { device_.send_force(f); }
    bool finished(double t) const override { return device_.finished(t + offset_); }

   private:
    Device& device_;
    const double& offset_;
  };

  // owned by the haptic thread while running, by the owner otherwise
  // (declaration order matters: sim_ is built before coupled_ needs its tick)
  std::vector<Device*> devices_;
  EngineFactory factory_;
  Options options_;
  LiveParams params_;
  Simulated sim_;
  Engine& engine() { return sim_.engine(); }
  double period_ = 1e-3;
  double clock_offset_ = 0;  ///< simulated time of the simulations before the running one (s)
  std::vector<std::unique_ptr<SessionClock>> clocks_;     ///< per tool
  std::vector<std::unique_ptr<CoupledDevice>> coupled_;   ///< per tool, around clocks_
  std::vector<Device*> coupled_ptrs_;                     ///< what the scheduler ticks
  HapticSnapshot local_;
  std::vector<index_t> last_seeds_;
  RegionSizes last_region_;
  std::vector<double> work_ring_, wake_ring_, start_ring_;
  std::vector<std::uint8_t> late_ring_;
  std::vector<double> scratch_;
  std::vector<std::uint32_t> histogram_;  ///< session work times, kHistBin bins
  long ring_pos_ = 0, ring_count_ = 0;
  double session_start_ = 0;
  bool failed_ = false;

  // shared
  std::thread thread_;
  std::atomic<bool> running_{false};
  std::atomic<bool> stop_{false};
  mutable std::mutex snap_mutex_;
  HapticSnapshot published_;
  mutable std::mutex req_mutex_;
  std::condition_variable req_cv_;
  std::atomic<bool> has_requests_{false};
  std::vector<std::packaged_task<void(Engine&)>> tasks_;
  std::optional<LiveParams> pending_params_;
  std::string status_;
};

}  // namespace tissue
