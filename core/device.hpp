// Haptic devices: read the tool pose and buttons, receive the force.
// Implementations: ScriptedDevice (tests, benchmarks, demos), the viewer's
// mouse device, and hardware adapters behind the same interface.
#pragma once

#include <string>
#include <vector>

#include "core/tool.hpp"
#include "core/vec.hpp"

namespace tissue {

class Device {
 public:
  virtual ~Device() = default;
  /// Tool pose and buttons at simulated time t (s): the tip (m), the shaft
  /// axis where the device has an orientation (zero otherwise: the scene's
  /// direction is used) and the grasp button.
  virtual ToolInput read(double t) = 0;
  /// Force on the tool (N) to render.
  virtual void send_force(const Vec3<double>& force) = 0;
  /// True once a finite script has ended.
  virtual bool finished(double /*t*/) const { return false; }
};

/// A waypoint of a scripted tool path.
struct Waypoint {
  double t = 0;                   ///< s
  Vec3<double> p = {0, 0, 0};     ///< tool tip (m)
  bool grasp = false;             ///< grasp button held from this waypoint to the next
  Vec3<double> axis = {0, 0, 0};  ///< shaft axis (unit); zero = the scene's direction
};

/// Piecewise-linear tool path through waypoints (ascending t); holds the last
/// point after the end. The tip moves linearly between waypoints, the axis
/// by normalised interpolation where both waypoints give one, and the grasp
/// button holds the state of the last waypoint passed. Keeps the last force
/// it was sent (and every force when asked to record them: tests).
class ScriptedDevice : public Device {
 public:
  /// Throws std::invalid_argument for an empty path, a non-finite value or
  /// times that do not increase, naming the waypoint.
  explicit ScriptedDevice(std::vector<Waypoint> path, bool record_forces = false);
  ToolInput read(double t) override;
  void send_force(const Vec3<double>& force) override;
  bool finished(double t) const override { return t >= path_.back().t; }
  const std::vector<Waypoint>& path() const { return path_; }
  /// Every force sent, in order (empty unless record_forces).
  const std::vector<Vec3<double>>& forces() const { return forces_; }
  const Vec3<double>& last_force() const { return last_force_; }
  long forces_sent() const { return sent_; }
  double duration() const { return path_.back().t; }

 private:
  std::vector<Waypoint> path_;
  bool record_;
  std::vector<Vec3<double>> forces_;
  Vec3<double> last_force_ = {0, 0, 0};
  long sent_ = 0;
};

/// The built-in press-and-release path: from `start`, approach the surface
/// point `target` along `dir` (unit, pointing into the tissue), press `depth`
/// metres past it, hold, retract to start. Times in seconds.
std::vector<Waypoint> press_path(Vec3<double> target, Vec3<double> dir, double depth, double approach_distance,
                                 double t_approach = 0.1, double t_press = 0.2, double t_hold = 0.5,
                                 double t_retract = 0.2);

}  // namespace tissue
