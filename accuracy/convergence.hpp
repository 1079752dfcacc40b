// Mesh convergence of the tool force on the built-in kidney (tissue
// converge, docs/contact.md section 5): the scene's probe held at its 5 mm
// indentation, relaxed to equilibrium (the reference, accuracy/reference.hpp)
// on a family of meshes whose faces under the probe shrink while the rest
// of the organ keeps the default mesh's size (io::SurfaceFocus with
// frequency x focus constant), and the force's limit by Richardson
// extrapolation in the edge length under the tool.
#pragma once

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "accuracy/reference.hpp"
#include "accuracy/remesh.hpp"
#include "scene/scene.hpp"

namespace tissue::accuracy {

/// One mesh of the study.
struct ConvergenceLevel {
  std::string name;
  int target_tets = 0;        ///< 0: the scene's own mesh (then frequency and focus are unused)
  KidneySurfacing surfacing;  ///< frequency and focus of the kidney's surface
};

/// The default family: the scene's own mesh (8 mm faces), then focus 0.75,
/// 0.5, 1/3 and 0.25 at frequency 6 / focus (far faces stay 8 mm, those
/// under the tool 4.5, 2, 0.9 and 0.5 mm), TetGen's target the default's.
std::vector<ConvergenceLevel> default_convergence_levels();

/// A force-depth curve: the tool's force along its press direction (N)
/// against how far it has pressed since it first touched (m), one point a
/// tick.
struct PressCurve {
  std::vector<double> depth, force;
};

/// The largest change of slope along a curve, where the mesh is felt: at
/// each point, the slopes of least-squares lines through the points within
/// `window` before it and within `window` after it, the change as a
/// fraction of the slope before, (k_after - k_before) / k_before. Only
/// where the force before has reached `from` of the curve's last force
/// (the first touch, where the slope rises from 0, is not a kink), and only
/// where both windows are whole. depth NaN: no such point.
struct SlopeJump {
  double jump = 0;     ///< signed: + the curve stiffens, - it softens
  double depth = NAN;  ///< m: where
};
SlopeJump largest_slope_jump(const PressCurve& c, double window, double from = 0.1);

/// The scene's first tool pressed at `speed` (m/s) from where its path
/// first touches to its held pose (held_tool), with the scene's own solver
/// settings, the force read every tick. `model`: the scene's, when the
/// caller has built it (null: built here). Throws std::runtime_error when a
/// tick stops (naming it) or `speed` is not > 0.
PressCurve slow_press(const scene::Scene& s, const HeldTool& held, double speed,
                      std::shared_ptr<const TissueModel<double>> model = nullptr);

/// The press curve's window and speed in `tissue converge`: slopes over
/// 0.25 mm either side, the probe at 2 mm/s (quasi-static on the kidney:
/// its lowest mode is about 10 Hz).
inline constexpr double kCurveWindow = 2.5e-4, kCurveSpeed = 2e-3;

/// What one mesh gave.
struct ConvergenceRow {
  std::string name;
  index_t nodes = 0, tets = 0;
  double edge_under_tool = 0;  ///< mean undeformed surface edge near the tool's axis (m)
  Vec3<double> force = {};     ///< on the held tool (N)
  double residual = 0;         ///< relative residual reached
  bool at_contact_floor = false;
  long steps = 0;
  double wall = 0;             ///< s
  double rel_err = 0;          ///< |F| / F_extrapolated - 1
  std::string failed;          ///< why no result (then force is zero)
  SlopeJump slope_jump;        ///< of the slow press's curve (no curve: depth NaN)
  std::string curve_failed;    ///< why no curve ("" = one, or none asked)
};

/// Richardson extrapolation of values f_i at sizes h_i (descending h) with
/// F(h) = F* + C h^p, from the last three: the order p solves
/// (f1 - f2) / (f2 - f3) = (h1^p - h2^p) / (h2^p - h3^p) (bisection on
/// [0.25, 6]). `monotone` is false, and F* the last value, when the two
/// differences change sign or no order in that range fits.
struct Extrapolation {
  double value = 0, order = 0;
  bool monotone = false;
};
Extrapolation richardson(const std::vector<double>& h, const std::vector<double>& f);

struct ConvergenceResult {
  std::vector<ConvergenceRow> rows;
  Extrapolation limit;  ///< of |F| over the rows that succeeded
};

/// Runs the study on `scene` (the built-in kidney: remesh_scene with each
/// level's surfacing); ReferenceOptions choose backend and tolerance.
/// curve_speed > 0 also presses each mesh at that speed (slow_press) for
/// the curve's largest slope jump. `progress` (may be null) is called
/// after each row.
ConvergenceResult kidney_convergence(const scene::Scene& scene, const std::vector<ConvergenceLevel>& levels,
                                     const ReferenceOptions& options,
                                     void (*progress)(const ConvergenceRow&) = nullptr, double curve_speed = 0);

}  // namespace tissue::accuracy
