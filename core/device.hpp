// Haptic devices: read the tool pose, receive the force. Implementations:
// ScriptedDevice (tests, benchmarks, demos), the viewer's mouse device, and
// hardware adapters behind the same interface.
#pragma once

#include <string>
#include <vector>

#include "core/vec.hpp"

namespace tissue {

class Device {
 public:
  virtual ~Device() = default;
  /// Tool tip position (m) at simulated time t (s).
  virtual Vec3<double> read_position(double t) = 0;
  /// Force on the tool (N) to render.
  virtual void send_force(const Vec3<double>& force) = 0;
  /// True once a finite script has ended.
  virtual bool finished(double /*t*/) const { return false; }
};

/// A waypoint of a scripted tool path.
struct Waypoint {
  double t;           ///< s
  Vec3<double> p;     ///< m
};

/// Piecewise-linear tool path through waypoints (ascending t); holds the last
/// point after the end. Records every force it was sent.
class ScriptedDevice : public Device {
 public:
  explicit ScriptedDevice(std::vector<Waypoint> path);
  Vec3<double> read_position(double t) override;
  void send_force(const Vec3<double>& force) override { forces_.push_back(force); }
  bool finished(double t) const override { return t >= path_.back().t; }
  const std::vector<Waypoint>& path() const { return path_; }
  const std::vector<Vec3<double>>& forces() const { return forces_; }
  double duration() const { return path_.back().t; }

 private:
  std::vector<Waypoint> path_;
  std::vector<Vec3<double>> forces_;
};

/// The built-in press-and-release path: from `start`, approach the surface
/// point `target` along `dir` (unit, pointing into the tissue), press `depth`
/// metres past it, hold, retract to start. Times in seconds.
std::vector<Waypoint> press_path(Vec3<double> target, Vec3<double> dir, double depth, double approach_distance,
                                 double t_approach = 0.1, double t_press = 0.2, double t_hold = 0.5,
                                 double t_retract = 0.2);

}  // namespace tissue
