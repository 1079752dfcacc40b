// The mouse as a haptic device (docs/design.md section 3): the display thread
// sets where the tool tip should go; the haptic thread reads the tip, which
// moves towards that target at a bounded speed, so that the 60 Hz steps of
// the mouse reach the 1 kHz loop as a smooth path (no jumps into the
// tissue, no velocity spikes in the coupling). The right button is the
// grasp button. The mouse renders no force; the last one sent is kept for
// display. Thread-safe.
#pragma once

#include <mutex>

#include "core/device.hpp"

namespace tissue::viewer {

class MouseDevice : public Device {
 public:
  /// Tip starts (and rests) at `start` (m); moves at most `max_speed` (m/s).
  MouseDevice(Vec3<double> start, double max_speed);

  /// Display thread: where the tip should go (m).
  void set_target(Vec3<double> p);
  Vec3<double> target() const;
  /// Display thread: the grasp button (the right mouse button).
  void set_grasp(bool down);
  bool grasp() const;

  /// Haptic thread: the tip at simulated time t (s), moved towards the
  /// target by at most max_speed x (t - t_last); no orientation (the
  /// scene's direction); the grasp button.
  ToolInput read(double t) override;
  void send_force(const Vec3<double>& force) override;
  Vec3<double> last_force() const;

 private:
  mutable std::mutex mutex_;
  Vec3<double> target_;
  Vec3<double> tip_;
  Vec3<double> force_ = {0, 0, 0};
  bool grasp_ = false;
  double max_speed_;
  double t_last_ = 0;
  bool started_ = false;
};

}  // namespace tissue::viewer
