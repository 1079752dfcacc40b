// The reference solution a setting's answer is measured against: the whole
// mesh, double precision, the tool held at its indentation, relaxed by
// dynamic relaxation (accuracy/relaxation.hpp) until the relative residual
// is <= 1e-9. It reports the residual it actually reached.
#pragma once

#include <string>
#include <vector>

#include "accuracy/relaxation.hpp"
#include "core/device.hpp"
#include "core/model.hpp"
#include "core/scheduler.hpp"

namespace tissue::accuracy {

/// Reference settings.
struct ReferenceOptions {
  std::string backend = "cpu";  ///< backend that relaxes (always in double)
  double dt_safety = 0.9;       ///< dt = dt_safety x dt_crit (IANP is stable up to 1; plain tets need < 0.85)
  RelaxOptions relax;           ///< residual_tol 1e-9 by default; with relax.stop, an interrupted
                                ///< relaxation returns its state (relax.interrupted) instead of throwing
};

/// A relaxed reference state.
struct ReferenceSolution {
  Fields fields;                ///< relaxed u (3 x n_nodes, m), f (N), nodal pressure, J
  Vec3<double> reaction = {};   ///< sum of internal forces on the driven components (N)
  Vec3<double> tool_force = {}; ///< force on the held tool, if any: minus its contact reaction (N)
  index_t contact_nodes = 0;    ///< the tool's contact nodes at the end
  double max_disp = 0;          ///< max |u_a| (m)
  double strain_energy = 0;     ///< J
  double dt = 0;                ///< step used (s)
  RelaxResult relax;            ///< residual reached, steps, wall time, damping
};

/// Relaxes `model` (whole mesh, double, dt = options.dt_safety x dt_crit)
/// under `drive` (and `tool`, if given) from u = 0. Throws RelaxError when
/// the relaxation breaks down (NaN, inverted element) and
/// std::runtime_error naming the residual reached when it did not converge
/// within the step or wall limits.
ReferenceSolution reference_solution(const TissueModel<double>& model, const Drive& drive,
                                     const ReferenceOptions& options = {}, const HeldTool* tool = nullptr);

/// Time (s) at which a scripted path starts holding the tool still: the
/// start of its longest stationary segment (two consecutive waypoints at the
/// same point), or the path's end when it never stops. Throws
/// std::invalid_argument for an empty path.
double hold_start(const std::vector<Waypoint>& path);

/// The scene's tool held where its path is at t_hold (s), for the
/// reference: sampling the path at the haptic tick, the ramp starts at the
/// last pose before the tool first comes within its radius of the
/// undeformed surface. A path that starts there (in contact, or inside the
/// body) has its first pose moved back, a radius at a time, along the
/// motion from the held pose to it (the axis for a tool that does not
/// move) until it no longer touches, so that the ramp presses in from
/// outside. The axis is the path's where it gives one, else the tool's
/// direction. Throws std::runtime_error when the path never touches the
/// surface before t_hold, or when 1000 radii back it still touches.
HeldTool held_tool(const TissueModel<double>& model, const ToolSetting& tool, const std::vector<Waypoint>& path,
                   double tick, double t_hold, const ContactOptions& contact = {});


}  // namespace tissue::accuracy
