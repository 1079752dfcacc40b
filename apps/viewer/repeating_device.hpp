// A scripted tool path played over and over (press, release, press, ...),
// for sessions that measure the haptic loop for longer than one path.
#pragma once

#include <cmath>
#include <vector>

#include "core/device.hpp"

namespace tissue::viewer {

class RepeatingDevice : public Device {
 public:
  /// The path must end where it starts (press_path does) for a seamless loop.
  explicit RepeatingDevice(std::vector<Waypoint> path) : inner_(std::move(path)) {}
  /// The path's position at t modulo its duration (m).
  Vec3<double> read_position(double t) override { return inner_.read_position(std::fmod(t, inner_.duration())); }
  /// Forces are dropped: a script renders nothing, and the session must not grow.
  void send_force(const Vec3<double>&) override {}

 private:
  ScriptedDevice inner_;
};

}  // namespace tissue::viewer
