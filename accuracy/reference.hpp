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
  double max_disp = 0;          ///< max |u_a| (m)
  double strain_energy = 0;     ///< J
  double dt = 0;                ///< step used (s)
  RelaxResult relax;            ///< residual reached, steps, wall time, damping
};

/// Relaxes `model` (whole mesh, double, dt = options.dt_safety x dt_crit)
/// under `drive` from u = 0. Throws RelaxError when the relaxation breaks
/// down (NaN, inverted element) and std::runtime_error naming the residual
/// reached when it did not converge within the step or wall limits.
ReferenceSolution reference_solution(const TissueModel<double>& model, const Drive& drive,
                                     const ReferenceOptions& options = {});

/// The tool contact the Scheduler would make on the undeformed tissue along
/// `path`, held where the tool is at time t_hold (s): sampling the path at
/// the haptic tick, the first segment from the previous to the current tip
/// that enters the surface (Backend::collide, nearest hit, an entering
/// crossing) gives the contact triangle and the point P0; its three corners
/// are driven by tip(t_hold) - P0 (core/scheduler.hpp's rule with the
/// undeformed corner displacements u0 = 0). Throws std::runtime_error when
/// the path never touches the surface before t_hold.
struct HeldContact {
  Drive drive;                  ///< the three corners, all components
  index_t tri = -1;             ///< contact triangle
  Vec3<double> point = {};      ///< P0 (m)
  Vec3<double> tip = {};        ///< tip at t_hold (m)
  double t_contact = 0;         ///< time of the tick that made contact (s)
};
/// Time (s) at which a scripted path starts holding the tool still: the
/// start of its longest stationary segment (two consecutive waypoints at the
/// same point), or the path's end when it never stops. Throws
/// std::invalid_argument for an empty path.
double hold_start(const std::vector<Waypoint>& path);

/// `precision` is the collision's: a float run may pick the other triangle
/// of an edge the path crosses exactly, and its reference must drive the
/// triangle it drove.
HeldContact held_contact(const TissueModel<double>& model, const std::vector<Waypoint>& path, double tick,
                         double t_hold, const std::string& backend = "cpu", Precision precision = Precision::Double);

}  // namespace tissue::accuracy
