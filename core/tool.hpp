// Rigid tools (docs/contact.md): a capsule -- a tip sphere of radius r at the
// tip p and a shaft of length l from p along the unit axis d (d points from
// the tip up the shaft, toward the handle; l = 0 is a sphere). The radius is
// physical: it is the loaded patch. What a device reports each haptic tick
// (ToolInput), how a pose moves across the TLED steps of a tick
// (interpolate_pose) and how often contact is checked inside one step
// (contact_substeps) are defined here once, for the Scheduler and every
// backend.
#pragma once

#include <algorithm>
#include <cmath>
#include <string>

#include "core/vec.hpp"

namespace tissue {

/// Most tools one scene may hold (two hands and two assistants). The
/// backends keep per-tool data in fixed arrays of this size.
inline constexpr int kMaxTools = 4;

/// Most contact checks inside one TLED step (contact_substeps caps here).
inline constexpr int kMaxSubsteps = 256;

/// A tool's shape (SI).
struct ToolShape {
  std::string name = "probe";  ///< for messages
  double radius = 2e-3;        ///< r: tip sphere and shaft radius (m), > 0
  double shaft = 0;            ///< l: shaft length (m), >= 0; 0 = a sphere
  double friction = 0;         ///< mu: Coulomb coefficient of its pushed contacts, >= 0; 0 = frictionless
};

/// The rule a tool's shape keeps, as the message of the first part it breaks
/// ("" when it keeps it): the radius finite and > 0 and at most half the
/// body's largest extent body_extent (m; 0 = not checked), the shaft
/// length finite and >= 0, the friction coefficient finite and >= 0. The scene's checks, the Scheduler and
/// Backend::set_tools all report this one message, each with its context.
std::string tool_shape_error(const ToolShape& t, double body_extent = 0);

/// The friction coefficient's part of that rule ("" when `friction` keeps
/// it), for a live change of one tool's coefficient.
std::string tool_friction_error(const std::string& name, double friction);

/// A tool's pose: tip position and the unit shaft axis (tip -> handle).
struct ToolPose {
  Vec3<double> tip = {0, 0, 0};   ///< m
  Vec3<double> axis = {0, 0, 1};  ///< unit
};

/// One sample of a device: the tool pose and the grasp button.
struct ToolInput {
  Vec3<double> tip = {0, 0, 0};   ///< m
  Vec3<double> axis = {0, 0, 0};  ///< unit shaft axis; zero = the device has no orientation
                                  ///< (the scene's direction is used)
  bool grasp = false;             ///< grasp button held
};

/// Unit vector of v, or `fallback` when |v| is zero or not finite.
template <class T>
TISSUE_HD Vec3<T> unit_or(Vec3<T> v, Vec3<T> fallback) {
  const T n = norm(v);
  return n > T(0) && n < T(INFINITY) ? (T(1) / n) * v : fallback;
}

/// The pose a fraction s in [0, 1] of the way from a to b: the tip moves
/// linearly, the axis by normalised linear interpolation (it keeps a's axis
/// when the two are opposite).
template <class T>
TISSUE_HD void interpolate_pose(Vec3<T> tip0, Vec3<T> axis0, Vec3<T> tip1, Vec3<T> axis1, T s, Vec3<T>& tip,
                                Vec3<T>& axis) {
  tip = tip0 + s * (tip1 - tip0);
  axis = unit_or(axis0 + s * (axis1 - axis0), axis0);
}

/// Contact checks per TLED step for a tool moving from pose 0 to pose 1
/// over `steps` steps: the tip and the shaft's end each move at most
/// max_travel x r between two checks (DESIGN: r / 2, max_travel = 0.5), at
/// least 1, at most kMaxSubsteps.
inline int contact_substeps(const ToolPose& from, const ToolPose& to, double radius, double shaft, int steps,
                            double max_travel = 0.5) {
  const Vec3<double> end0 = from.tip + shaft * from.axis, end1 = to.tip + shaft * to.axis;
  const double move = std::max(norm(to.tip - from.tip), norm(end1 - end0)) / std::max(steps, 1);
  const double per_check = max_travel * radius;
  if (!(move > 0) || !(per_check > 0)) return 1;
  return static_cast<int>(std::clamp(std::ceil(move / per_check), 1.0, double(kMaxSubsteps)));
}

}  // namespace tissue
