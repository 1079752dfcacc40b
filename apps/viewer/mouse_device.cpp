#include "apps/viewer/mouse_device.hpp"

#include <fmt/format.h>

#include <cmath>
#include <stdexcept>

namespace tissue::viewer {

MouseDevice::MouseDevice(Vec3<double> start, double max_speed) : target_(start), tip_(start), max_speed_(max_speed) {
  if (!(std::isfinite(max_speed) && max_speed > 0))
    throw std::invalid_argument(fmt::format("mouse device: maximum speed {} m/s must be finite and > 0", max_speed));
}

void MouseDevice::set_target(Vec3<double> p) {
  if (!(std::isfinite(p.x) && std::isfinite(p.y) && std::isfinite(p.z))) return;  // a degenerate unprojection
  std::lock_guard lk(mutex_);
  target_ = p;
}

Vec3<double> MouseDevice::target() const {
  std::lock_guard lk(mutex_);
  return target_;
}

void MouseDevice::set_grasp(bool down) {
  std::lock_guard lk(mutex_);
  grasp_ = down;
}

bool MouseDevice::grasp() const {
  std::lock_guard lk(mutex_);
  return grasp_;
}

ToolInput MouseDevice::read(double t) {
  std::lock_guard lk(mutex_);
  const double dt = started_ ? std::max(0.0, t - t_last_) : 0.0;
  started_ = true;
  t_last_ = t;
  const Vec3<double> d = target_ - tip_;
  const double dist = norm(d), step = max_speed_ * dt;
  tip_ = dist <= step ? target_ : tip_ + (step / dist) * d;
  return {tip_, {0, 0, 0}, grasp_};
}

void MouseDevice::send_force(const Vec3<double>& force) {
  std::lock_guard lk(mutex_);
  force_ = force;
}

Vec3<double> MouseDevice::last_force() const {
  std::lock_guard lk(mutex_);
  return force_;
}

}  // namespace tissue::viewer
