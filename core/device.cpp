#include "core/device.hpp"

#include <fmt/format.h>

#include <cmath>
#include <stdexcept>

namespace tissue {
namespace {

bool finite3(const Vec3<double>& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

}  // namespace

ScriptedDevice::ScriptedDevice(std::vector<Waypoint> path, bool record_forces)
    : path_(std::move(path)), record_(record_forces) {
  if (path_.empty()) throw std::invalid_argument("scripted tool path has no waypoints");
  for (size_t k = 0; k < path_.size(); ++k) {
    const Waypoint& w = path_[k];
    if (!std::isfinite(w.t))
      throw std::invalid_argument(fmt::format("scripted tool path: waypoint {}: time {} is not finite", k, w.t));
    if (!finite3(w.p) || !finite3(w.axis))
      throw std::invalid_argument(fmt::format("scripted tool path: waypoint {}: position or axis is not finite", k));
    if (k > 0 && !(w.t > path_[k - 1].t))
      throw std::invalid_argument(fmt::format(
          "scripted tool path: waypoint {} has time {} s, not after the previous one ({} s)", k, w.t, path_[k - 1].t));
  }
}

ToolInput ScriptedDevice::read(double t) {
  if (t <= path_.front().t) return {path_.front().p, path_.front().axis, path_.front().grasp};
  for (size_t k = 1; k < path_.size(); ++k)
    if (t < path_[k].t) {
      const Waypoint &a = path_[k - 1], &b = path_[k];
      const double s = (t - a.t) / (b.t - a.t);
      ToolInput in{a.p + s * (b.p - a.p), a.axis, a.grasp};
      if (norm(a.axis) > 0 && norm(b.axis) > 0) in.axis = unit_or(a.axis + s * (b.axis - a.axis), a.axis);
      return in;
    }
  return {path_.back().p, path_.back().axis, path_.back().grasp};
}

void ScriptedDevice::send_force(const Vec3<double>& force) {
  last_force_ = force;
  ++sent_;
  if (record_) forces_.push_back(force);
}

std::vector<Waypoint> press_path(Vec3<double> target, Vec3<double> dir, double depth, double approach_distance,
                                 double t_approach, double t_press, double t_hold, double t_retract) {
  const Vec3<double> start = target - approach_distance * dir;
  const Vec3<double> deep = target + depth * dir;
  // approach, press through the surface to `depth`, hold, retract
  double t = 0;
  std::vector<Waypoint> w{{t, start}};
  w.push_back({t += t_approach, target});
  w.push_back({t += t_press, deep});
  w.push_back({t += t_hold, deep});
  w.push_back({t += t_retract, start});
  return w;
}

}  // namespace tissue
