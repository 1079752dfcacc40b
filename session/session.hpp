// One scene assembled for running: scene -> model -> backend -> Scheduler,
// with one host-driven device per tool. The embedding facade's Simulation
// and every scene of a Batch are Sessions (docs/batch.md).
#pragma once

#include <chrono>
#include <functional>
#include <future>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "core/backend.hpp"
#include "core/cut.hpp"
#include "core/device.hpp"
#include "core/model.hpp"
#include "core/scheduler.hpp"
#include "scene/scene.hpp"
#include "scene/validate.hpp"
#include "session/engine.hpp"

namespace tissue {

/// A tool's device: the scene's scripted path until the host sets a pose,
/// the host's pose from then on. The grasp button is the path's or the
/// host's (either held).
class HostDevice final : public Device {
 public:
  explicit HostDevice(std::vector<Waypoint> path) : script_(std::move(path)) {}

  ToolInput read(double t) override;
  void send_force(const Vec3<double>&) override {}  // the Scheduler's report carries it

  void set_pose(Vec3<double> tip, Vec3<double> axis) {
    tip_ = tip;
    axis_ = axis;
    host_ = true;
  }
  void set_grasp(bool down) { grasp_ = down; }
  /// Back to the path (the scene's, or set_path's).
  void follow_path() { host_ = false; }
  /// A new scripted path (ScriptedDevice's rules), followed from now on.
  void set_path(std::vector<Waypoint> path) {
    script_ = ScriptedDevice(std::move(path));
    host_ = false;
  }

 private:
  ScriptedDevice script_;
  bool host_ = false;
  bool grasp_ = false;
  Vec3<double> tip_ = {}, axis_ = {};
};

/// What Session::cut did.
struct SessionCut {
  CutResult cut;            ///< the counts and maps (cut.nodes: the new reference positions)
  double dt_before = 0;     ///< the TLED step before and after (s)
  double dt_after = 0;
  double dt_crit_before = 0;  ///< the critical step without mass scaling before and after (s)
  double dt_crit_after = 0;
  double added_mass_before = 0;  ///< mass scaling's added mass before and after (kg)
  double added_mass_after = 0;
  index_t nodes_before = 0, elements_before = 0;
};

class Session {
 public:
  /// Validates the scene and builds its model (scene::load_model).
  explicit Session(scene::Scene scene);
  /// A scene whose model is already built (several sessions of one mesh and
  /// material share the scene and the model) on a backend already created.
  /// Throws std::runtime_error for a scene without a tool, and what the
  /// Scheduler throws for bad settings. Uploads the model and starts at rest.
  Session(std::shared_ptr<const scene::Scene> scene, std::shared_ptr<const TissueModel<double>> model,
          std::unique_ptr<Backend> backend);
  Session(Session&&) = delete;

  /// Back to rest: u = 0, tick 0, every grasp released, no failure, the
  /// mesh as it was before any cut; keeps the host's tool modes and loads
  /// (set_loads, else the scene's).
  void restart();

  /// One haptic tick (begin_tick + end_tick). A SimulationError is kept as
  /// failure() and rethrown; ticks are refused until restart().
  TickReport tick();
  /// The two halves of tick() (Scheduler::begin_tick): a batch begins every
  /// scene's tick before it ends any.
  void begin_tick();
  TickReport end_tick();

  /// Constant loads from the next tick on, kept across restart() (they
  /// replace the scene's). Throws std::invalid_argument naming the scene.
  void set_loads(std::vector<index_t> nodes, std::vector<double> forces);

  const scene::Scene& scene() const { return *scene_; }
  const std::string& name() const { return scene_->source; }
  const TissueModel<double>& model() const { return *engine_.model; }
  const std::shared_ptr<const TissueModel<double>>& shared_model() const { return engine_.model; }
  Backend& backend() { return *engine_.backend; }
  const Backend& backend() const { return *engine_.backend; }
  Scheduler& scheduler() { return *engine_.scheduler; }
  const Scheduler& scheduler() const { return *engine_.scheduler; }
  const SchedulerSettings& settings() const { return settings_; }
  int n_tools() const { return static_cast<int>(devices_.size()); }
  HostDevice& device(int tool) { return devices_.at(std::size_t(tool)); }
  /// The tools read these devices from the next tick on, one per tool in
  /// order (a haptic loop's couplings), instead of the host's poses and the
  /// scene's paths; empty: the session's own devices again. They must
  /// outlive their use. Throws std::invalid_argument naming the scene for a
  /// count that is not the tools' or a null device.
  void drive_with(std::vector<Device*> devices);
  /// The engine (model, backend, Scheduler) the session runs, for a host
  /// that reads its backend between two ticks (the haptic loop's tasks). A
  /// cut replaces its model and backend: keep no reference into them across
  /// a tick.
  Engine& engine() { return engine_; }
  /// Throws std::invalid_argument naming the scene when tool is not one of its tools.
  void check_tool(int tool) const;
  /// Tool `tool`'s Coulomb coefficient from the next tick on, also across
  /// restart() (the scene's `friction` until then). Throws std::invalid_argument naming the scene
  /// and the tool for a tool that does not exist or a coefficient that is
  /// not finite and >= 0.
  void set_tool_friction(int tool, double friction);
  double tool_friction(int tool) const;
  /// The host drives tool `tool` to this pose from the next tick on (HostDevice::set_pose). Throws
  /// std::invalid_argument, naming the tool and the value, for a tool that does not exist, a pose that is
  /// not finite, or a tip farther from the mesh than a scene's waypoints may be (scene::kToolReach).
  void set_tool_pose(int tool, Vec3<double> tip, Vec3<double> axis);
  /// set_tool_pose's checks alone.
  void check_tool_pose(int tool, Vec3<double> tip, Vec3<double> axis) const;

  /// Cuts the tissue where it is now along `surface` (given in the
  /// deformed configuration, where the host sees the blade) between two
  /// ticks, and runs on with the cut mesh (core cut_moving; `space`
  /// Reference: `surface` given in the reference configuration,
  /// docs/cutting.md): the reference mesh, its element sets, supports and
  /// loads follow the cut; the model is built again (masses, IANP's nodal
  /// averaging, the surface and its BVH, the step) and uploaded to the same
  /// backend; the motion carries over (u and the velocity, the FE field's
  /// values at the new nodes), as do the time, the tools and the region's
  /// seeds; restart() goes back to the mesh before any cut. Forgotten: the Prony history, grasps (a held grasp takes no
  /// nodes until its button goes down again) and the contacts' friction
  /// anchors. Throws CutError for a bad cut and SceneError (scene
  /// validate.hpp) for a scene of bodies, leaving the session as it was.
  /// A blade's cut in preparation takes effect first.
  SessionCut cut(const CutSurface& surface, const CutOptions& options = {}, CutSpace space = CutSpace::Deformed);
  /// The same cut, prepared on another thread while the ticks run on: the
  /// cut and the model's rebuild are made from the motion of now, and the
  /// cut takes effect at the end of tick `due` (the tick's thread waits
  /// there if it is not ready), with the motion of that moment carried over
  /// through the cut's transfer (MovingCut::Transfer: the same material
  /// points, so a cut in the reference configuration is then the cut that
  /// cut() would have made there). One at a time: throws std::logic_error
  /// while one is pending. A cut found bad is refused when it takes effect:
  /// the tick (or cut()) that makes it throws its CutError or ModelError,
  /// the session as it was.
  void begin_cut(const CutSurface& surface, const CutOptions& options, CutSpace space, long due);
  /// Whether a cut is in preparation (begin_cut, or a blade's).
  bool cut_pending() const { return pending_.has_value(); }
  /// The blades' cuts (end_tick makes them, docs/cutting.md "The blade"):
  /// for each blade whose button is down, once the force against its
  /// motion per metre of edge in contact reaches its cut resistance, the
  /// crack runs from its front to a thickness plus an element beyond the
  /// blade's edge; its cut is prepared meanwhile and takes effect the
  /// blade's cut-delay later. The last cut's times (s): on the tick's
  /// thread (the whole cut for cut(), the commit for a prepared one) and
  /// its preparation (the cut and the model's rebuild; 0 for cut()); the
  /// count since the start.
  double last_cut_seconds() const { return last_cut_seconds_; }
  double last_cut_prepare_seconds() const { return last_cut_prepare_seconds_; }
  /// The last cut's carry-over on the tick's thread, in its parts (s; `tissue bench --cut`): the motion of
  /// now downloaded and carried to the cut mesh (0 for cut(), whose cut is made at the motion of now), the
  /// swap onto the prepared backend (the old one handed to its release; for cut(), the upload of the cut
  /// model), the loads set, the motion uploaded.
  struct CommitTimes {
    double download = 0, transfer = 0, swap = 0, loads = 0, upload = 0;
  };
  const CommitTimes& last_commit_times() const { return last_commit_times_; }
  long cuts() const { return cuts_; }

  /// Whether the mesh was cut since the start or the last restart().
  bool was_cut() const { return uncut_scene_ != nullptr; }

  /// The last tick's report (a zero report before the first).
  const TickReport& last() const { return last_; }
  /// Why the last tick failed ("" while running).
  const std::string& failure() const { return failure_; }
  bool failed() const { return !failure_.empty(); }

  /// The store's fields after the last tick (downloaded on the first call after it).
  const Fields& fields();

 private:
  void check_running() const;
  /// end_tick's cuts by the blades whose button is down (see cuts()).
  void cut_with_blades();
  /// Makes a cut (`make`: cut() or finish_cut()) and counts it; a blade's (tool `blade`, cutting along
  /// `ahead`; -1: the host's) then has its lips set outside it and its report says so. A blade's cut that
  /// opens nothing is dropped, one whose mesh is refused is noted (Scheduler::note); the host's are rethrown.
  void land_cut(int blade, Vec3<double> ahead, const std::function<SessionCut()>& make);
  /// The cut in preparation takes effect (land_cut of finish_cut).
  void take_pending_cut();
  /// While a cut's preparation or a replaced backend's release runs on another thread, the ticks leave that
  /// thread a core (Backend::lend_cores); once neither runs, they take it back (checked after each tick).
  void share_cores();
  /// After a blade's cut: each node of the faces it opened that lies inside the blade (its capsule: tip,
  /// unit axis, length, radius) goes to the blade's surface along the normal of its plane (across: the
  /// edge times its motion), on the side of its own elements.
  void open_lips(const SessionCut& made, Vec3<double> tip, Vec3<double> axis, double length, double radius,
                 Vec3<double> across);
  /// What a cut is made from: the scene, its motion at tick `tick`, the cut; for one prepared on another
  /// thread (begin_cut), the backend to make (name, precision) and the region's seeds and depth.
  struct CutInput {
    std::shared_ptr<const scene::Scene> scene;
    std::vector<double> u, u_prev;
    CutSurface surface;
    CutOptions options;
    CutSpace space = CutSpace::Deformed;
    long tick = 0;
    std::string backend;  ///< "" : none (cut() uploads to the session's own)
    Precision precision = Precision::Float;
    std::vector<index_t> seeds;
    int depth = kDepthAll;
  };
  /// A cut made ready (on any thread): the cut mesh, its scene and its model; for begin_cut's, a backend
  /// holding the cut model with the cut motion, its region built and warmed up.
  struct PreparedCut {
    MovingCut made;
    std::shared_ptr<const scene::Scene> scene;
    std::shared_ptr<const TissueModel<double>> model;
    long tick = 0;
    double seconds = 0;  ///< its preparation's time
    std::unique_ptr<Backend> backend;
    Scheduler::PreparedRemesh region;
  };
  static PreparedCut prepare_cut(CutInput in);
  /// The cut's input of now (the motion downloaded), for cut() (no backend) and begin_cut.
  CutInput cut_input(const CutSurface& surface, const CutOptions& options, CutSpace space);
  /// Checks that the scene may be cut now and that its mesh is its model's.
  void check_cut_now() const;
  /// Makes a prepared cut take effect on the motion of now (cut()'s carry-over).
  SessionCut commit_cut(PreparedCut&& p);
  /// A cut begun (begin_cut, or a blade's): waits for it, makes it take effect. Rethrows its CutError or
  /// SceneError, the session as it was.
  SessionCut finish_cut();
  /// Keeps a stop as failure(), with the scene checks' likely causes appended, and throws it.
  [[noreturn]] void fail(const SimulationError& e);

  std::shared_ptr<const scene::Scene> scene_;
  Engine engine_;
  std::shared_ptr<const scene::Scene> uncut_scene_;  ///< before the first cut (null: none yet)
  std::shared_ptr<const TissueModel<double>> uncut_model_;
  scene::MeshBox box_;  ///< the reach host poses are held to, as scene waypoints are
  SchedulerSettings settings_;
  std::vector<HostDevice> devices_;
  std::vector<Device*> device_ptrs_;
  std::optional<scene::SceneLoads> loads_;  ///< set_loads' (else the scene's)
  TickReport last_;
  std::optional<Fields> fields_;
  std::string failure_;
  /// Per tool: a blade's stroke (its button down). Its crack lies on one
  /// plane of the reference configuration, set by its first cut, and grows
  /// there by the work the blade does past the cutting resistance (its
  /// front, the edge's two ends, reference positions). Each cut cuts the
  /// stroke's whole crack, from where it began to its front, so that a face
  /// the front has passed opens even where the last cut left its nodes
  /// joined; a cut is made when the front has run a third of an element
  /// since the last.
  struct BladeState {
    bool down = false;
    bool started = false;         ///< the stroke has a front and a plane
    Vec3<double> down_tip = {};   ///< the blade's tip when its button went down
    Vec3<double> last_tip = {};   ///< the blade's tip after the tick before
    Vec3<double> start0 = {};     ///< the edge's first end where the stroke began
    Vec3<double> front0 = {};     ///< the crack's front: the edge's first end
    Vec3<double> edge = {};       ///< the edge in the reference configuration
    Vec3<double> normal = {};     ///< the stroke's plane
    Vec3<double> onward = {};     ///< the way its crack runs on that plane (unit, across the edge)
    double lead = 0;              ///< how far the first cut runs ahead of the edge (m): a thickness and an element
    double cut_at = 0;            ///< the front's distance from the start at the last cut (m)
    bool refusal_noted = false;   ///< a cut of this stroke crossed no element, and the notes say so
  };
  std::vector<BladeState> blades_;
  /// A cut in preparation: the job, the tick at whose end it takes effect,
  /// and for a blade's, the blade and the way it cut.
  struct PendingCut {
    std::future<PreparedCut> job;
    long due = 0;
    int blade = -1;
    Vec3<double> ahead = {};
  };
  std::optional<PendingCut> pending_;
  /// The backend a prepared cut replaced, let go on another thread (its threads joined, its memory freed).
  std::future<void> retiring_;
  bool cores_lent_ = false;  ///< the backend leaves a core to the two above (share_cores)
  double last_cut_seconds_ = 0;
  double last_cut_prepare_seconds_ = 0;
  CommitTimes last_commit_times_;
  long cuts_ = 0;
};

}  // namespace tissue
