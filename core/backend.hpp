// The Backend interface: the fixed, small set of operations the Scheduler
// runs on whichever backend is active (docs/design.md). A backend owns its
// store (host arrays or device buffers) in its own scalar type; values cross
// this interface in double. Implementations: cpu/ (TBB + Embree) and cuda/
// (kernels); backends/registry.hpp creates them by name.
//
// The public functions are not virtual: each checks its arguments and the
// backend's state once, here, then calls a protected virtual do_*(), so
// every backend gives the same error for the same mistake (MuJoCo's "check
// once, before any stage runs").
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/body_contact.hpp"
#include "core/contact.hpp"
#include "core/model.hpp"
#include "core/region.hpp"
#include "core/tool.hpp"
#include "core/vec.hpp"

namespace tissue {

/// One tool's share of the per-tick reductions (after the advance's last step).
struct ToolReduction {
  Vec3<double> reaction = {};  ///< sum of core contact_reaction over its contact nodes (N); the force
                               ///< on the tool is minus this
  index_t contact = 0;         ///< nodes in contact (pushed or grasped)
  index_t grasped = 0;         ///< of which grasped
  index_t rigid = 0;           ///< nodes inside the tool that the scene fixes (a rigid support)
  index_t rigid_first = -1;    ///< the lowest of them, -1 none
  index_t outside = 0;         ///< nodes inside the tool that are not inner region nodes (cannot move)
};

/// Reductions over the region after a batch of steps (one call per tick).
struct Reductions {
  Vec3<double> reaction = {};  ///< sum of internal forces on the set_driven components (N)
  Vec3<double> internal = {};  ///< sum of the out-of-balance forces f - R on inner nodes (N): minus the
                               ///< applied loads (set_loads) over the whole mesh, since internal forces sum
                               ///< to zero there, less the halo's support in a limited region; the
                               ///< equilibrium measure is the free-node residual below
  double free_force2 = 0;      ///< sum f_ac^2 over free (integrated) components of inner nodes (N^2); a
                               ///< pushed contact node's tangential part counts as free
  double held_force2 = 0;      ///< sum f_ac^2 over held components of inner nodes: fixed, driven, and
                               ///< the normal part of pushed contact nodes (N^2)
  double kinetic = 0;          ///< 0.5 sum m_a |(u^n - u^{n-1}) / dt|^2 over region nodes (J)
  double max_disp = 0;         ///< max |u_a| over region nodes (m)
  double strain_energy = -1;   ///< sum_e V_e W(Fbar_e) over computed elements at the current u (J; plain
                               ///< tets: W(F_e)). -1 = not computed by this backend
  double front_disp = -1;      ///< max |u_a| over the region's front ring (Region::front; 0 when it is
                               ///< empty), the adaptive region's truncation indicator (m); -1 = not computed
  double visco_power = 0;      ///< W: what the Prony terms dissipate now, over the region's viscoelastic
                               ///< elements (core/material.hpp prony_energy); 0 without Prony terms
  double visco_stored = 0;     ///< J: the energy their Maxwell branches store now
  index_t bad_elem = -1;       ///< lowest element with J <= 0 or non-finite since the last reduce; -1 none
  double bad_J = 1;            ///< its J
  bool finite = true;          ///< every reduced value finite
  ToolReduction tools[kMaxTools];  ///< per tool (set_tools order)
};

/// Host<->device copies the backend made (0 for host backends).
struct TransferCounters {
  std::uint64_t h2d = 0, d2h = 0;
  std::uint64_t h2d_bytes = 0, d2h_bytes = 0;
};

/// Device memory of a backend that has one (bytes; -1 where it has none).
struct DeviceMemory {
  std::int64_t held = -1;   ///< held by this process's backend arrays
  std::int64_t free = -1;   ///< free on the device (all processes)
  std::int64_t total = -1;  ///< the device's
};

/// Whole-store snapshot for output and tests (downloads; not for the tick loop).
/// One std::vector<double> per output array of core/store.hpp
/// (TISSUE_OUTPUT_ARRAYS), at the state's layout: u (3 x n_nodes) m, node_p
/// (n_nodes) Pa, f, the internal nodal force minus the applied load
/// (set_loads) (3 x n_nodes) N, elem_J (n_elems), J's last computed value.
struct Fields {
#define TISSUE_OUTPUT_MEMBER(name, ...) std::vector<double> name;
  TISSUE_OUTPUT_ARRAYS(TISSUE_OUTPUT_MEMBER)
#undef TISSUE_OUTPUT_MEMBER
};

/// A tool's motion over the next advance() (m; axes unit or normalised).
struct ToolMotion {
  ToolPose from, to;
  bool grasp = false;          ///< grasp button held: the nodes in contact when it went down follow the tool
};

/// How contact is computed (the tradeoff's contact dimension; docs/contact.md).
struct ContactOptions {
  bool face = true;            ///< face contact (false: node contact only)
  double max_travel = 0.5;     ///< most travel of a tool between two contact checks, in radii
};

/// One surface node in contact (Backend::contacts: reports, tests, the viewer).
struct ContactNode {
  index_t node = -1;
  int tool = -1;
  std::uint8_t kind = kNoContact;  ///< ContactKind
  Vec3<double> normal = {};        ///< contact normal of a pushed node (unit, out of the tool)
};

/// One surface node touching another body after the last step
/// (Backend::body_contacts: tests, reports).
struct BodyContactNode {
  index_t node = -1;
  index_t tri = -1;   ///< the other body's surface triangle it was inside
  double gap = 0;     ///< how far inside it was before the step's correction (m)
};

/// Scenes of one model that a device backend steps as one: each pass of a
/// tick is one launch over all of them (the cuda backend's scene group,
/// docs/batch.md "One launch per pass"). Made by the registry
/// (make_backend_group); each scene's backend joins it before its upload.
/// A scene's start_tick then only stages its tick; launch() runs every
/// staged tick, and a scene's finish_tick calls it if no one has.
class BackendGroup {
 public:
  virtual ~BackendGroup() = default;
  /// Runs the ticks the group's scenes have started and waits for them.
  virtual void launch() = 0;
  /// Ticks run as one launch per pass since the group was made, and ticks
  /// its scenes ran alone (a scene the group could not take that tick).
  virtual std::int64_t ticks_together() const = 0;
  virtual std::int64_t ticks_alone() const = 0;
};

class Backend {
 public:
  virtual ~Backend() = default;

  virtual std::string name() const = 0;         ///< "cpu", "cuda"
  virtual Precision precision() const = 0;
  virtual std::string device_name() const = 0;  ///< processor or GPU, for reports
  /// True when write_positions() writes device memory (the viewer maps a
  /// GL buffer for it); false when it writes host memory.
  virtual bool positions_on_device() const { return false; }

  /// Loads the model (once per scene; allocates everything the loop needs)
  /// and resets the state to u = 0 with the whole mesh as region, no
  /// driven nodes and no tools.
  void upload(const TissueModel<double>& model);

  /// Replaces every displacement (u^n = u^{n-1} = given; 3 x n_nodes, m).
  /// Halo nodes are held at the new u (they are held "at their current
  /// displacement"); fixed and driven nodes keep their targets.
  void set_displacements(std::span<const double> u);
  /// Replaces the motion: u^n = u and u^{n-1} = u_prev (3 x n_nodes each,
  /// m), so the velocity (u - u_prev) / dt carries over; otherwise as
  /// set_displacements (which is set_motion(u, u)). A remesh (a cut) carries
  /// the state over through it. Throws std::invalid_argument naming the node
  /// for a size that is not 3 x n_nodes or a value that is not finite.
  void set_motion(std::span<const double> u, std::span<const double> u_prev);
  /// u^{n-1} (3 x n_nodes, m), with download()'s u the motion set_motion takes.
  std::vector<double> previous_displacements();
  /// Builds now what the first step after an upload or set_motion would
  /// build on its way (the cpu backend's surface BVH at the current u;
  /// nothing on cuda), so that a backend prepared on another thread (a
  /// cut, Session::begin_cut) steps at once when it takes over.
  void warm_up();
  /// New nodal masses (n_nodes, kg) for the model uploaded, whose dt and
  /// damping (s, 1/s) are given: the central difference's constants are
  /// computed from them as set_time_step computes them, and taken with the
  /// masses in place; the state and the region are kept (the step guard's
  /// added mass, core/step_guard.hpp). Throws std::invalid_argument for a
  /// size that is not n_nodes, or a mass that is not finite and > 0 (naming
  /// the node).
  void set_masses(std::span<const double> mass, double dt, double damping);
  /// The smallest altitude of each listed element on its deformed shape
  /// (m; 0 where it is inverted or flat), the step guard's measure. Throws
  /// std::out_of_range naming an element that is not the model's.
  std::vector<double> deformed_altitudes(const TissueModel<double>& model, std::span<const index_t> elems);

  /// Flood-fills the region from seeds for depth rings (kDepthAll = whole
  /// mesh), holds the new halo at its current displacement, freezes nodes
  /// leaving the region and recomputes pass 1 over all elements. Returns
  /// the region's sizes only (a device backend keeps the lists on the
  /// device: nothing but these four counts comes back).
  RegionSizes build_region(std::span<const index_t> seeds, int depth);

  /// The current region's full lists (downloads; for output and tests).
  Region region();

  /// Prescribes the displacement (3 per node, m) of nodes (a boundary
  /// drive: references, patch tests); they stay held until clear_driven().
  /// Replaces the previous driven set. set_driven_axes gives a component
  /// mask per node (a roller): bit c of axes[k] (1..7) set = component c of
  /// nodes[k] is prescribed to u[3k + c]; the other components are
  /// integrated. Reductions::reaction sums the driven components. A node
  /// given twice is driven in the union of its masks, each component at its
  /// last target.
  void set_driven(std::span<const index_t> nodes, std::span<const double> u);
  void set_driven_axes(std::span<const index_t> nodes, std::span<const double> u, std::span<const std::uint8_t> axes);
  void clear_driven();

  /// Applies constant external forces (dead loads, N; 3 per node, xyz) to
  /// nodes: the R of the central difference (docs/design.md section 2),
  /// which was 0 before. Replaces the previous loads; a node given twice
  /// gets the sum; empty lists remove every load. A load moves the
  /// components a node integrates; a held component's support takes it
  /// (Reductions::reaction and Fields::f are the internal force minus the
  /// load, the out-of-balance force). Only region nodes integrate: the
  /// Scheduler seeds its region with the loaded nodes (Scheduler::set_loads).
  void set_loads(std::span<const index_t> nodes, std::span<const double> force);
  /// The nodes set_loads gave (ascending, each once).
  const std::vector<index_t>& loaded_nodes() const { return loaded_; }

  /// The scene's tools (at most kMaxTools; radius > 0, shaft >= 0) and how
  /// contact is computed. Releases every grasp; the tools rest at the
  /// origin until move_tools().
  void set_tools(std::span<const ToolShape> tools, const ContactOptions& options = {});
  int n_tools() const { return static_cast<int>(shapes_.size()); }
  const std::vector<ToolShape>& tools() const { return shapes_; }
  /// Tool `tool`'s Coulomb coefficient from the next advance() on (finite,
  /// >= 0; 0 = frictionless), keeping its contacts and grasp.
  void set_tool_friction(int tool, double friction);

  /// The tools' motion over the next advance() (one per tool): the pose is
  /// interpolated linearly across its steps (core interpolate_pose), and
  /// contact is checked contact_substeps() times per step. A grasp flag
  /// that turns on grasps the nodes in contact with that tool now; one that
  /// turns off releases them. After the advance the tools rest at `to`.
  void move_tools(std::span<const ToolMotion> motion);

  /// Contact between the bodies of the mesh (core/body_contact.hpp) from the
  /// next advance on: every pair of spec.pairs, each TLED step, before the
  /// tools' contact. An empty spec turns it off. std::invalid_argument for a
  /// bad spec; a backend that cannot run it with its settings says why.
  void set_body_contact(const BodyContactSpec& spec);
  const BodyContactSpec& body_contact() const { return body_spec_; }
  /// The surface nodes inside another body after the last step, before its
  /// correction (ascending node id).
  std::vector<BodyContactNode> body_contacts();
  /// How many times the candidate lists were built (tests, reports).
  virtual long body_list_builds() const { return 0; }
  /// How many step graphs were captured so far (cuda; 0 where none are),
  /// and how many of those updated a graph kept from before in place
  /// rather than instantiating a new one: reports.
  virtual long graph_captures() const { return 0; }
  virtual long graph_updates() const { return 0; }
  /// Takes `from`'s step graphs, so that this backend's first captures
  /// update them in place rather than instantiate new ones (cuda of the same
  /// precision; nothing elsewhere; a graph that cannot be updated, another
  /// device's, is instantiated anew): a cut's new backend taking over from
  /// the old one, between ticks.
  virtual void adopt_graphs(Backend& from) { (void)from; }

  /// The pending tool motion as the steps of an advance of `steps` steps
  /// see it (core/contact.hpp ContactTools: poses, substeps, grasps): what
  /// the backends' contact stages get.
  ContactTools<double> contact_tools(int steps) const;

  /// Surface nodes that are not inner region nodes and that the pending
  /// tool motion comes within a radius of (ascending): the Scheduler seeds
  /// the region with them before the advance. Empty when there are no tools.
  std::vector<index_t> contact_candidates();

  /// Every surface node in contact after the last step (ascending node id).
  std::vector<ContactNode> contacts();

  /// The four IANP passes of docs/design.md section 2 over the region (tests run
  /// them one by one; node_update has no contact stage).
  void element_pressure();  ///< pass 1: J_e, (J_e - 1) V_e
  void nodal_pressure();    ///< pass 2: p_a
  void element_forces();    ///< pass 3: Fbar, S, f_a^e
  /// Pass 4: gather f_a, central difference, rotate u. It needs the forces
  /// of a pass 3 called since the last pass 4, upload or step (a backend's
  /// steps need not leave their forces where pass 4 reads them: the cuda
  /// backend's fused passes keep them on chip); std::logic_error otherwise.
  void node_update();

  /// n TLED steps, each the four passes then the contact stage of the
  /// tools' motion (core/contact.hpp). Backends may fuse passes or replay a
  /// captured graph; results are the same.
  void advance(int steps);

  /// Reaction, total internal force, residual parts, kinetic energy, max
  /// displacement, per-tool contact results and the bad-element flag
  /// (which it clears).
  Reductions reduce();

  /// advance(steps) then reduce(), as one unit of work: the haptic tick's.
  /// Results are those of the two calls; a backend may run both without
  /// returning to the host in between (the cuda backend replays one graph:
  /// the tools' upload, the steps, the reductions and their download).
  Reductions advance_reduce(int steps);

  /// advance_reduce(steps), unless the pending tool motion reaches surface
  /// nodes that are not inner region nodes (contact_candidates() is not
  /// empty): then nothing runs, the tools stay where they were, and the
  /// result is empty; the caller grows the region (Scheduler) and calls
  /// advance_reduce. The cuda backend makes that check on the device, in
  /// the tick's graph, so that a tick whose region holds needs no host
  /// round trip before its steps.
  std::optional<Reductions> advance_reduce_in_region(int steps);

  /// The haptic tick's work in two halves, so that many backends' ticks run
  /// at once (a batch of scenes): start_tick(steps, in_region) begins what
  /// advance_reduce_in_region(steps) (in_region) or advance_reduce(steps)
  /// would do and may return before it ends; finish_tick() waits for it and
  /// returns that call's result. A device backend enqueues the tick on its
  /// own stream; a host backend does the work in start_tick. Between the
  /// two, every other call throws std::logic_error.
  void start_tick(int steps, bool in_region);
  std::optional<Reductions> finish_tick();
  bool tick_pending() const { return tick_pending_; }
  /// True when start_tick returns before the tick's work ends (a device
  /// backend): a batch then starts every scene's tick from one thread
  /// before it waits for any. False: start_tick does the work, and a batch
  /// runs its scenes on threads of their own.
  virtual bool asynchronous_ticks() const { return false; }

  /// How many threads this backend's own steps may use (0: its default). A
  /// batch of scenes on the cpu runs one scene per thread and sets 1; a
  /// device backend has no host threads to set and ignores it.
  virtual void set_worker_threads(int /*threads*/) {}
  /// Leaves `cores` of the cores its steps run on to other work of the
  /// process for now (a cut prepared on another thread), 0 to take them
  /// back: the cpu backend's steps then keep at most its team's size less
  /// `cores` threads busy (at least one), with the same bits; a device
  /// backend has no host threads to spare and ignores it.
  virtual void lend_cores(int /*cores*/) {}

  /// Copies the store's fields to the host (output, tests).
  Fields download();

  /// Writes deformed positions X + u of all nodes as float xyz triples
  /// (n_nodes x 3) to dst: host memory when !positions_on_device(), device
  /// memory otherwise (the viewer's mapped vertex buffer).
  void write_positions(float* dst);

  virtual TransferCounters transfers() const { return {}; }
  /// The device memory now (soak runs, out-of-memory reports); host backends: all -1.
  virtual DeviceMemory device_memory() const { return {}; }

  index_t n_nodes() const { return n_nodes_; }
  bool uploaded() const { return uploaded_; }

 protected:
  virtual void do_upload(const TissueModel<double>& model) = 0;
  virtual void do_set_motion(std::span<const double> u, std::span<const double> u_prev) = 0;
  virtual void do_warm_up() {}
  /// mass, cd_A, cd_B, cd_C: n_nodes each (checked).
  struct NodeMasses {
    std::vector<double> mass, cd_A, cd_B, cd_C;
  };
  virtual void do_set_masses(const NodeMasses& masses) = 0;
  /// The base class's: from download()'s displacements.
  virtual std::vector<double> do_deformed_altitudes(const TissueModel<double>& model, std::span<const index_t> elems);
  virtual std::vector<double> do_previous_displacements() = 0;
  virtual RegionSizes do_build_region(std::span<const index_t> seeds, int depth) = 0;
  virtual Region do_region() = 0;
  /// Region roles (NodeRole) of the given nodes (the driven-node check).
  virtual std::vector<std::uint8_t> do_roles(std::span<const index_t> nodes) = 0;
  /// nodes unique, masks 1..7, targets finite (checked).
  virtual void do_set_driven(std::span<const index_t> nodes, std::span<const double> u,
                             std::span<const std::uint8_t> axes) = 0;
  virtual void do_clear_driven() = 0;
  /// load: the applied force per node (3 x n_nodes, component-major, N;
  /// finite), or empty for none.
  virtual void do_set_loads(std::span<const double> load) = 0;
  /// Tool `tool` at `pose` starts grasping: its pushed contact nodes become grasped.
  virtual void do_begin_grasp(int tool, const ToolPose& pose) = 0;
  /// Releases the nodes tool `tool` grasps.
  virtual void do_end_grasp(int tool) = 0;
  /// The tools changed (set_tools): forget every contact and grasp.
  virtual void do_reset_contacts() = 0;
  virtual void do_element_pressure() = 0;
  virtual void do_nodal_pressure() = 0;
  virtual void do_element_forces() = 0;
  virtual void do_node_update() = 0;
  virtual void do_advance(int steps, const ContactTools<double>& tools) = 0;
  /// `sweep` holds the pending motion as one step (steps = 1).
  virtual std::vector<index_t> do_contact_candidates(const ContactTools<double>& sweep) = 0;
  virtual std::vector<ContactNode> do_contacts() = 0;
  virtual Reductions do_reduce() = 0;
  /// Default: do_advance, then do_reduce.
  virtual Reductions do_advance_reduce(int steps, const ContactTools<double>& tools);
  /// Default: do_contact_candidates over the whole motion, then do_advance_reduce if it is empty.
  virtual std::optional<Reductions> do_advance_reduce_in_region(int steps, const ContactTools<double>& tools);
  /// start_tick's work (steps > 0; in_region only with tools). Default: runs
  /// do_advance_reduce_in_region or do_advance_reduce now and keeps the
  /// result for do_finish_tick.
  virtual void do_start_tick(int steps, const ContactTools<double>& tools, bool in_region);
  /// Waits for the started tick and returns its result. Default: the kept one.
  virtual std::optional<Reductions> do_finish_tick();
  virtual Fields do_download() = 0;
  virtual void do_write_positions(float* dst) = 0;
  /// spec checked against the mesh (check_body_contact). Default: refuses a non-empty spec.
  virtual void do_set_body_contact(const BodyContactSpec& spec);
  virtual std::vector<BodyContactNode> do_body_contacts() { return {}; }

 private:
  void require_upload(const char* what) const;
  /// require_upload, and steps >= 0 (invalid_argument naming `what`).
  void check_steps(const char* what, int steps) const;
  /// After an advance that took steps: the tools rest where their motion
  /// ended, and no pass 3's forces remain for a pass 4.
  void steps_taken();

  bool uploaded_ = false;
  bool pass3_forces_ = false;  ///< element_forces() ran since the last node_update(), upload or step taken
  index_t n_nodes_ = 0, n_elems_ = 0;
  std::vector<ToolShape> shapes_;
  ContactOptions contact_options_;
  std::vector<ToolMotion> motion_;      ///< pending motion per tool
  std::vector<ToolPose> grasp_pose_;    ///< pose when each tool's grasp started
  std::vector<std::uint8_t> grasping_;  ///< per tool
  std::vector<index_t> loaded_;         ///< set_loads' nodes
  BodyContactSpec body_spec_;           ///< set_body_contact's
  bool tick_pending_ = false;           ///< start_tick called, finish_tick not yet
  bool pending_steps_ = false;          ///< the pending tick takes steps (else it is a reduction alone)
  std::optional<Reductions> pending_;   ///< the default do_start_tick's result
};

}  // namespace tissue
