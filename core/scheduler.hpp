// The Scheduler runs one haptic tick on the active backend, as a list of
// stages: read devices -> move tools -> seed the region -> N TLED steps
// (each with its contact stage) -> reductions -> forces to devices. It knows
// nothing of CUDA, TBB or Embree.
//
// Tools (docs/contact.md): each tool is a capsule driven by its own device.
// A tick moves every tool linearly from its pose at the previous tick to the
// pose its device reports for the end of this tick, across the tick's TLED
// steps; the backend's contact stage pushes the surface out of the tools
// after every step (core/contact.hpp) and reduces each tool's reaction.
// The force sent to a device is minus its tool's reaction. A device without
// an orientation gets the scene's shaft direction. The grasp button grasps
// the nodes in contact when it goes down and releases them when it comes up.
//
// Region (depth N or auto): before each tick's steps, the surface nodes that
// the tools' motion comes within a radius of and that are not yet inner
// region nodes (Backend::contact_candidates) join the seeds, and the region
// is rebuilt from all seeds: it grows to cover everything the tools touch
// and never shrinks, so touched tissue can relax after release.
//
// Adaptive region (depth = kDepthAuto): the first contact builds the region
// with auto_start rings; after every tick's reduction, while the largest
// displacement on the region's front ring (its outermost inner nodes,
// Reductions::front_disp) exceeds auto_tol times the largest displacement in
// the region, the region grows by one ring (same seeds), up to the whole
// connected mesh. The halo beyond the front is held where it is, so the
// front's displacement bounds how much the truncation holds back.
#pragma once

#include <array>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/backend.hpp"
#include "core/device.hpp"
#include "core/step_guard.hpp"
#include "core/tool.hpp"

namespace tissue {

/// A tool of the scene as the Scheduler drives it.
struct ToolSetting {
  ToolShape shape;
  Vec3<double> axis = {0, 0, 1};  ///< shaft direction (unit) when the device has no orientation
  bool blade = false;             ///< its button cuts (the caller's: Session), not grasps
};

/// How fast a tool whose first pose already presses the tissue (deeper than
/// kEntryDepth) is brought in to its device's pose (m/s): from a pose
/// retracted along its axis out of contact, at the speed of a scene's
/// scripted press (a tool that appears inside the tissue would have its
/// contact push the surface a press deep in one step, and the elements under
/// it invert).
inline constexpr double kEntrySpeed = 0.025;
/// A first pose that touches the tissue by less than this many radii (along
/// the tool's axis) starts where it is: a press begun at the surface.
inline constexpr double kEntryDepth = 0.1;

struct SchedulerSettings {
  int depth = 5;               ///< region rings from the contact; kDepthAll = whole mesh;
                               ///< kDepthAuto = adaptive (see above)
  double auto_tol = 0.02;      ///< depth auto: grow while front_disp > auto_tol * max_disp (dimensionless)
  int auto_start = 2;          ///< depth auto: rings of the region built at the first contact (>= 0)
  double tick = 1e-3;          ///< haptic period (s)
  double residual_tol = 1e-3;  ///< equilibrium: |f_free| / max(|f_held|, force_floor)
  double kinetic_tol = 1e-6;   ///< equilibrium: kinetic / max(energy scale, energy_floor)
  double force_floor = 1e-9;   ///< N
  std::vector<ToolSetting> tools = {ToolSetting{}};  ///< one per device (at most kMaxTools)
  ContactOptions contact;      ///< face contact, contact check spacing
  BodyContactSpec body_contact;  ///< bodies that touch each other (empty: none); needs depth kDepthAll
  /// After a cut (remesh), its lips keep out of each other (body_contact.lips,
  /// at lip_friction): a cut's two faces are one body's surfaces, which
  /// nothing else keeps from crossing.
  bool lip_contact = false;
  double lip_friction = 0;
  /// Mass scaling carried on under the tools as they crush small elements
  /// (core/step_guard.hpp).
  StepGuardSettings step_guard;
};

/// One tool in one tick.
struct ToolReport {
  Vec3<double> tip = {};       ///< m, at the end of the tick
  Vec3<double> axis = {};      ///< unit shaft axis
  Vec3<double> force = {};     ///< force on the tool: minus its reaction (N)
  index_t contact_nodes = 0;   ///< surface nodes in contact (pushed or grasped)
  index_t grasped = 0;         ///< of which grasped
  index_t rigid_nodes = 0;     ///< fixed nodes inside the tool (a rigid support)
  bool grasp = false;          ///< the button held (a blade's: cutting on)
  bool cut = false;            ///< a blade's cut was made after this tick (Session)
};

/// What one tick did (one CSV row).
struct TickReport {
  long tick = 0;
  double time = 0;             ///< simulated time at the end of the tick (s)
  int n_tools = 0;
  std::array<ToolReport, kMaxTools> tools = {};
  Vec3<double> tool = {};      ///< tools[0].tip (m)
  Vec3<double> force = {};     ///< tools[0].force (N)
  index_t contact_nodes = 0;   ///< nodes in contact with any tool
  Vec3<double> internal = {};  ///< sum of internal forces less the applied loads over inner nodes (N)
  index_t region_nodes = 0, region_elems = 0;
  double residual = 0;         ///< relative free-node residual
  double kinetic = 0;          ///< J
  double kinetic_rel = 0;      ///< kinetic / (0.5 |f_held| max|u|): the equilibrium test's kinetic measure
  double strain_energy = -1;   ///< J, over the computed elements; -1 = the backend does not compute it
  double max_disp = 0;         ///< m
  double front_disp = -1;      ///< max |u| on the region's front ring (m); -1 = not computed
  int depth = kDepthAll;       ///< region depth in use at the end of the tick (rings; kDepthAll = whole)
  double visco_power = 0;      ///< W dissipated by the Prony terms at the end of the tick (0 without)
  double visco_stored = 0;     ///< J stored in their Maxwell branches
  double dissipated = 0;       ///< J dissipated by the Prony terms since the first tick (the trapezoid rule
                               ///< over the ticks' visco_power)
  bool equilibrium = false;
  int steps = 0;               ///< TLED steps in this tick
};

/// NaN/Inf or an inverted element appeared mid-run.
struct SimulationError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

class Scheduler {
 public:
  /// The backend must already hold `model` (Backend::upload); the
  /// constructor gives it the settings' tools. Throws std::invalid_argument
  /// for bad settings (tick, depth auto, tools: more than kMaxTools, a
  /// radius <= 0 or larger than the body, a zero axis), naming the rule.
  Scheduler(Backend& backend, const TissueModel<double>& model, SchedulerSettings settings);

  /// One haptic tick, one device per tool (in settings order); throws
  /// SimulationError naming tick, steps and element.
  TickReport tick(std::span<Device* const> devices);
  /// The same for a scene with one tool.
  TickReport tick(Device& device);
  /// tick() in two halves (Backend::start_tick): begin_tick reads the
  /// devices, moves the tools and starts the backend's tick; end_tick waits
  /// for it, grows the region if the tools reached beyond it, checks health
  /// and returns the report (sending the forces to the same devices). A
  /// batch begins every scene's tick before it ends any, so that device
  /// backends run them side by side. tick() = begin_tick + end_tick.
  void begin_tick(std::span<Device* const> devices);
  TickReport end_tick();

  int steps_per_tick() const { return steps_per_tick_; }
  long ticks() const { return tick_; }
  long total_steps() const { return total_steps_; }
  double time() const { return tick_ * settings_.tick; }
  bool in_contact() const { return in_contact_; }
  const RegionSizes& region() const { return region_; }
  /// How many times the region was built again after the first: grown to the tools' contact candidates
  /// or the loads, by a ring at depth auto, or for a cut mesh that its preparation did not build it for.
  long region_rebuilds() const { return region_rebuilds_; }
  /// Rings of the current region (kDepthAll = whole); under depth auto, the
  /// depth it has grown to.
  int depth() const { return depth_; }
  const std::vector<index_t>& seeds() const { return seeds_; }
  const SchedulerSettings& settings() const { return settings_; }
  int n_tools() const { return static_cast<int>(settings_.tools.size()); }

  /// Applies constant loads (Backend::set_loads: N, 3 per node) from the
  /// next tick on. A region of limited depth is seeded with the loaded
  /// nodes as well as the contacts, so that they move.
  void set_loads(std::span<const index_t> nodes, std::span<const double> force);

  /// Tool t's Coulomb coefficient from the next tick on (Backend::set_tool_friction:
  /// finite, >= 0); its contacts and grasp stay.
  void set_tool_friction(int t, double friction);

  /// The step guard's work so far (core/step_guard.hpp): elements given
  /// mass (counted once per lift) and the mass added (kg), since the
  /// Scheduler was made or the last remesh.
  index_t guard_lifts() const { return guard_lifts_; }
  double guard_added_mass() const { return guard_.added_mass(); }

  /// Carries the run over to a new mesh of the same scene (a cut,
  /// core/cut.hpp), which the backend already holds (Backend::upload):
  /// node i of `model` comes from old nodes node_from[i] (the same one
  /// twice for a kept or copied node). Keeps the time, the tools' poses and
  /// notes, the region's depth and its seeds (a new node is a seed where it
  /// comes from one), gives the backend the tools again and takes the steps
  /// per tick from the new model's dt. The caller then sets the loads and
  /// the motion (Backend::set_motion). `model` must outlive the Scheduler or
  /// the next remesh. Throws std::logic_error between begin_tick and
  /// end_tick.
  void remesh(const TissueModel<double>& model, std::span<const std::array<index_t, 2>> node_from);
  /// What was made ready for a remesh off the tick's thread: the region the backend holds already
  /// (Backend::build_region of `seeds` at `depth`) and the new model's median surface edge.
  struct PreparedRemesh {
    std::vector<index_t> seeds;
    int depth = kDepthAll;
    RegionSizes sizes;
    double surface_edge = 0;  ///< median_surface_edge of the new model (m)
  };
  /// remesh onto `fresh`, a backend that holds the new model already and
  /// replaces the Scheduler's from now on (the caller owns it and keeps the
  /// old one until this returns). Its region is `prepared` where the seeds
  /// and depth are still those it was built with, else built again.
  void remesh(const TissueModel<double>& model, std::span<const std::array<index_t, 2>> node_from, Backend& fresh,
              const PreparedRemesh& prepared);
  /// The seeds of the region after a remesh (a new node is one where it comes from one).
  static std::vector<index_t> seeds_after(std::span<const index_t> seeds,
                                          std::span<const std::array<index_t, 2>> node_from);
  /// Holds the lips' contact off (true) or lets it on again (false), for a
  /// blade's stroke: its edge parts the lips where they still meet, and
  /// pushes a node of the lips' plane to whichever side is nearer.
  void suspend_lip_contact(bool suspend);
  /// The region's current depth (rings; kDepthAll for the whole mesh).
  int region_depth() const { return region_.whole() ? kDepthAll : depth_; }
  /// The depth remesh builds the region at: the whole mesh where the lips
  /// will touch (as bodies touching do: a region's edge across the lips held
  /// a lip node still against its moving twin, and the kidney cut across at
  /// depth auto stopped within two steps), else region_depth().
  int depth_after_cut() const { return settings_.lip_contact ? kDepthAll : region_depth(); }

  /// Notices since the last call (a tool pressing a rigid support, naming
  /// its nodes; a tool starting inside the body; a tool moving more than
  /// half the surface's median edge per TLED step in contact; a tool whose
  /// contact ended inside the tissue): one line each.
  std::vector<std::string> take_notes();
  /// Adds a notice of the caller's (a blade's refused cut: Session).
  void note(std::string text) { notes_.push_back(std::move(text)); }

 private:
  /// Gives the backend the settings' tools and bodies (after an upload).
  void give_backend_tools();
  /// Whether the lips touch now: lip_contact, after a cut, unless suspended.
  bool lips_on() const { return settings_.lip_contact && remeshed_ && !lips_suspended_; }
  bool remeshed_ = false;        ///< a cut was made (remesh)
  bool lips_suspended_ = false;  ///< suspend_lip_contact's
  /// Both remeshes: onto `backend` (the Scheduler's own or a fresh one), with the region it holds already, if any.
  void remesh_onto(const TissueModel<double>& model, std::span<const std::array<index_t, 2>> node_from,
                   Backend& backend, const PreparedRemesh* prepared);
  void seed_region();
  bool grow_region(const Reductions& r);
  void check_health(const Reductions& r, long first_step) const;
  /// The step guard's check after a tick (every settings.step_guard.interval ticks in contact).
  void guard_steps(const Reductions& r);
  StepGuard guard_;
  std::vector<double> guard_mass_;  ///< the nodal masses with the guard's (kg), while it watches
  index_t guard_lifts_ = 0;
  bool guard_after_remesh_ = false;   ///< a remesh's cut mesh is checked after its first tick in contact
  bool guard_refused_noted_ = false;  ///< the budget's end was noted
  void note_contacts(const Reductions& r);
  /// The tools that moved more than follow_step_ per TLED step this tick, as
  /// a sentence naming them ("" when none): for the failure message and notes.
  std::string fast_tools(bool in_contact_only, const Reductions& r) const;
  /// How far tool t moved this tick: the farther of its tip and its shaft's end (m).
  double tick_move(std::size_t t) const;
  void note_fast_tools(const Reductions& r);
  /// A tool whose contact ended while it lies inside the tissue's deformed
  /// surface went through that surface: noted, naming it, once per episode.
  void note_passed_through(const Reductions& r);

  Backend* backend_;
  const TissueModel<double>* model_;
  SchedulerSettings settings_;
  int steps_per_tick_ = 1;
  /// The region built again around seeds_ at `depth` (the backend's build), counted in region_rebuilds_.
  void rebuild_region(int depth);
  long region_rebuilds_ = 0;
  int depth_ = kDepthAll;       ///< current rings (settings_.depth, or the grown depth under auto)
  bool auto_depth_ = false;
  long tick_ = 0;
  long total_steps_ = 0;
  bool has_prev_ = false;
  bool in_contact_ = false;
  std::vector<ToolPose> prev_;  ///< each tool's pose at the end of the last tick
  std::vector<char> entering_;  ///< 1: the tool started in contact and is brought in (kEntrySpeed)
  std::vector<ToolMotion> motion_;
  std::vector<index_t> rigid_reported_;  ///< per tool: rigid count last reported (0 = none)
  std::vector<index_t> last_contact_;    ///< per tool: contact nodes at the end of the last tick
  std::vector<double> last_force_;       ///< per tool: |force| at the end of the last tick (N)
  std::vector<char> through_reported_;   ///< per tool: its pass through the surface was noted
  std::vector<char> fast_reported_;      ///< per tool: its speed in contact was noted
  double follow_step_ = 0;               ///< m: the most a tool may move per TLED step in contact unnoted
  RegionSizes region_;
  std::vector<index_t> seeds_;  ///< seeds of the current region (sorted)
  double visco_power_ = 0;      ///< the last tick's Reductions::visco_power (W)
  double dissipated_ = 0;       ///< J, TickReport::dissipated
  std::vector<std::string> notes_;
  // the tick between begin_tick and end_tick
  bool pending_ = false;
  TickReport pending_report_;
  std::vector<Device*> pending_devices_;
  long pending_first_step_ = 0;
};

/// True when p lies inside the closed surface of the model's reference
/// configuration (ray parity along +x; points on the surface count as
/// outside). For the start-inside notice and tests.
bool inside_reference_surface(const TissueModel<double>& m, Vec3<double> p);
/// The same for the surface displaced by u (3 x n_nodes, components in
/// blocks of n_nodes, as Fields::u).
bool inside_surface(const TissueModel<double>& m, std::span<const double> u, Vec3<double> p);

/// True when the capsule of `shape` at `pose` reaches within its radius of
/// the model's undeformed surface.
bool touches_reference_surface(const TissueModel<double>& model, const ToolShape& shape, const ToolPose& pose);

/// Most steps retracted_from_reference_surface takes.
inline constexpr int kMaxRetractSteps = 1000;

/// `pose` moved back along the unit direction `dir`, `step` metres at a
/// time, until its capsule no longer touches the undeformed surface
/// (`pose` itself when it does not); none when it still touches after
/// kMaxRetractSteps steps.
std::optional<ToolPose> retracted_from_reference_surface(const TissueModel<double>& model, const ToolShape& shape,
                                                         ToolPose pose, Vec3<double> dir, double step);

/// Largest extent of the model's reference bounding box (m).
double body_extent(const TissueModel<double>& m);

}  // namespace tissue
