// The speed-accuracy sweep behind `tissue tradeoff`: with the scene's tool
// pressed to its held indentation, each setting (region depth, adaptive
// depth, precision, dt safety factor, mesh size, equilibrium tolerance) is
// run through the Scheduler exactly as `tissue run` would, and measured
// against the reference solution (accuracy/reference.hpp).
//
// Protocol of one run: the scripted path up to the start of its hold, then
// the tool held there, tick after tick, until the Scheduler's equilibrium
// test passes at the setting's tolerance or max_hold simulated seconds have
// passed. Measured:
//   cost   wall time per haptic tick and TLED steps/s, averaged over the
//          ticks in contact (the press and the hold); ticks and wall time
//          from the start of the hold until equilibrium;
//   error  at that tick, max_a |u_a - u_ref_a| / max_a |u_ref_a| and
//          |F - F_ref| / |F_ref| for the force on the tool, against the
//          reference of the same mesh (the setting's own error: truncation,
//          rounding, unfinished relaxation), and against the finest mesh's
//          reference sampled at this mesh's nodes (adding the discretisation).
// One run serves every equilibrium tolerance at once: the state is captured
// at the first tick each tolerance passes (the Scheduler's test is the same
// at every tolerance: relative residual < tol and relative kinetic energy <
// the scene's kinetic tolerance), so the tolerance rows share the baseline
// run's trajectory.
#pragma once

#include <functional>

#include <string>
#include <vector>

#include "core/hd.hpp"
#include "core/region.hpp"
#include "core/vec.hpp"
#include "scene/scene.hpp"

namespace tissue::accuracy {

/// One point of the sweep.
struct TradeoffSetting {
  std::string group;              ///< "baseline", "anchor", "depth", "auto", "precision", "safety", "mass",
                                  ///< "mesh", "contact", "tolerance", "compare"
  std::string label;              ///< e.g. "depth 3", "auto 0.02", "double", "safety 0.9"
  int depth = 5;                  ///< rings; kDepthAll; kDepthAuto
  double auto_tol = 0.02;         ///< depth auto's front tolerance
  Precision precision = Precision::Float;
  double dt_safety = 0.5;         ///< dt = safety x dt_crit (then shortened to whole steps per tick)
  int mesh = 1;                   ///< index into TradeoffOptions::mesh_targets
  double residual_tol = 1e-3;     ///< equilibrium tolerance (relative free-node residual)
  double mass_scaling = 0;        ///< selective mass scaling budget (fraction of the total mass; 0 = off)
  bool face_contact = true;       ///< contact: face contact on (off: node contact only)
  double max_travel = 0.5;        ///< contact: most tool travel between two contact checks, in radii
};

/// What one setting measured.
struct TradeoffRow {
  TradeoffSetting setting;
  index_t mesh_nodes = 0, mesh_elems = 0;
  double dt = 0;                  ///< s
  int steps_per_tick = 0;
  double wall_per_tick = 0;       ///< s, median over ticks in contact (robust to other processes' bursts)
  double cpu_per_tick = 0;        ///< s of process CPU time (all threads), mean over ticks in contact
  double steps_per_s = 0;         ///< TLED steps per wall second over ticks in contact
  index_t region_nodes = 0, region_elems = 0;
  int depth_reached = 0;          ///< rings at the measured tick (kDepthAll = whole)
  bool equilibrium = false;       ///< the tolerance passed before max_hold ran out
  long hold_ticks = 0;            ///< ticks from the start of the hold to the measured tick
  double hold_wall = 0;           ///< s of wall time for those ticks
  double residual = 0;            ///< relative residual at the measured tick
  Vec3<double> force = {};        ///< force on the tool (N)
  double max_disp = 0;            ///< m
  double disp_err = 0;            ///< vs the same mesh's reference (relative)
  double force_err = 0;
  double disp_err_fine = 0;       ///< vs the finest mesh's reference (relative)
  double disp_err_fine_far = 0;   ///< the same over nodes farther than far_radius from the held tool tip:
                                  ///< the discretisation error away from the contact patch
  double force_err_fine = 0;
  double added_mass = 0;          ///< mass scaling's added mass / total mass
  double press_force_err = 0;     ///< the transient: max over the press's ticks of |F(t) - F_dyn(t)| / max |F_dyn|,
                                  ///< F_dyn from the same mesh run whole, double, safety 0.5, no mass scaling
                                  ///< (the most faithful dynamics); what the hand feels during the motion
  bool pareto = false;            ///< on the front of (wall_per_tick, disp_err)
  std::string failed;             ///< why the run or its reference stopped (the rest is then unset); empty = ran
};

/// A mesh's reference, for the report.
struct TradeoffReference {
  std::string mesh;               ///< "coarse", "default", "fine"
  index_t nodes = 0, elems = 0;
  long steps = 0;
  double wall = 0;                ///< s
  double residual = 0;            ///< relative residual reached
  Vec3<double> force = {};        ///< force on the tool (N)
  double max_disp = 0;            ///< m
  index_t contact_nodes = 0;      ///< the tool's contact nodes at equilibrium
  std::string failed;             ///< why the relaxation stopped (e.g. an element inverted under the contact)
};

/// The defaults the built-in scenes had before the sweep chose today's
/// (docs/accuracy.md): depth 5, float, dt = 0.5 dt_crit, no mass scaling,
/// residual tolerance 1e-3. Kept as a comparison row.
inline TradeoffSetting previous_defaults() {
  TradeoffSetting s;
  s.label = "previous defaults: depth 5, float, safety 0.5";
  s.depth = 5;
  s.precision = Precision::Float;
  s.dt_safety = 0.5;
  s.mass_scaling = 0;
  s.residual_tol = 1e-3;
  return s;
}

/// A contact-dimension setting (label, face contact, check spacing in radii).
inline TradeoffSetting contact_setting(std::string label, bool face, double max_travel) {
  TradeoffSetting s;
  s.label = "anchor, " + std::move(label);
  s.face_contact = face;
  s.max_travel = max_travel;
  return s;
}

struct TradeoffOptions {
  std::string backend;                          ///< empty = the scene's
  std::vector<int> mesh_targets = {3000, 0, 20000, 25000};  ///< tet targets (0 = the scene's own mesh), ascending:
                                                ///< the finest usable one is the discretisation reference
  std::vector<std::string> mesh_names = {"coarse", "default", "fine", "finer"};
  std::vector<int> depths = {1, 2, 3, 5, 8, kDepthAll};
  std::vector<double> auto_tols = {0.05, 0.02, 0.005};
  std::vector<Precision> precisions = {Precision::Float, Precision::Double};
  std::vector<double> safeties = {0.3, 0.6, 0.9};
  std::vector<double> mass_scalings = {0, 0.002, 0.01, 0.025, 0.05};
  std::vector<double> residual_tols = {1e-2, 1e-3, 1e-4};
  std::vector<TradeoffSetting> contact = {contact_setting("node contact only", false, 0.5),
                                          contact_setting("contact checks every radius of travel", true, 1.0)};
  int anchor_depth = kDepthAll;                 ///< the anchor's depth: see tradeoff_settings
  Precision anchor_precision = Precision::Double;
  std::vector<TradeoffSetting> compare = {previous_defaults()};  ///< extra rows, on the scene's mesh
  double max_hold = 0.6;                        ///< s of hold before giving up on equilibrium
  double reference_tol = 1e-9;                  ///< the references' relative residual
  double far_radius = 0.01;                     ///< m: "far" nodes for disp_err_fine_far
  bool verbose = true;                          ///< progress lines on stderr
  std::function<bool()> stop;                   ///< asked before each mesh and each setting: true ends the
                                                ///< sweep with the rows done (TradeoffResult::interrupted)
};

struct TradeoffResult {
  std::string scene;
  std::string device;                           ///< processor / GPU of the backend
  std::vector<TradeoffReference> references;    ///< per mesh
  std::vector<TradeoffRow> rows;
  double wall = 0;                              ///< s for the whole sweep
  bool interrupted = false;                     ///< TradeoffOptions::stop ended the sweep early
};

/// The settings swept, one dimension at a time:
///   baseline   the scene's solver settings on the scene's mesh;
///   anchor     the baseline on the whole mesh in double (anchor_depth,
///              anchor_precision): no truncation, no float floor;
///   depth, auto, precision   vary the baseline's depth and precision (the
///              region is what they trade);
///   safety, mass, mesh, contact, tolerance  vary the anchor (around the baseline,
///              the region's truncation error would hide their effect);
///   compare    the `compare` settings, on the scene's mesh.
std::vector<TradeoffSetting> tradeoff_settings(const scene::Scene& scene, const TradeoffOptions& options);

/// Runs the sweep on the scene (references first, then every setting). A
/// mesh whose reference cannot be computed (an element inverts under the
/// tool's contact triangle, ...) and a run that stops (SimulationError) are
/// reported as failed rows with their message; the sweep goes on. The finest
/// usable mesh is the discretisation reference.
TradeoffResult run_tradeoff(const scene::Scene& scene, const TradeoffOptions& options);

/// Marks the Pareto front of (wall_per_tick, disp_err): rows no other row
/// beats in both (one strictly). Failed rows are never on it.
void mark_pareto(std::vector<TradeoffRow>& rows);

/// The result as a fixed-width text table.
std::string tradeoff_table(const TradeoffResult& result);

/// The result as JSON (one object: scene, device, references, rows).
std::string tradeoff_json(const TradeoffResult& result);

}  // namespace tissue::accuracy
