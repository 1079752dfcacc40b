// A scripted tool path for long sessions: played once (then held at its
// last point) or over and over (press, release, press, ...). It drops the
// forces it is sent, so a session of any length runs in constant memory.
#pragma once

#include <cmath>
#include <vector>

#include "core/device.hpp"

namespace tissue::viewer {

class PathDevice : public Device {
 public:
  /// With `repeat`, the path should end where it starts (press_path does)
  /// for a seamless loop.
  PathDevice(std::vector<Waypoint> path, bool repeat) : inner_(std::move(path)), repeat_(repeat) {}
  /// The path's pose and grasp button at t (or at t modulo its duration when repeating).
  ToolInput read(double t) override { return inner_.read(repeat_ ? std::fmod(t, inner_.duration()) : t); }
  /// Forces are dropped: a script renders nothing.
  void send_force(const Vec3<double>&) override {}
  bool finished(double t) const override { return !repeat_ && inner_.finished(t); }
  double duration() const { return inner_.duration(); }  ///< one pass (s)

 private:
  ScriptedDevice inner_;
  bool repeat_;
};

}  // namespace tissue::viewer
