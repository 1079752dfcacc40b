#include "core/device.hpp"

#include <stdexcept>

namespace tissue {

ScriptedDevice::ScriptedDevice(std::vector<Waypoint> path) : path_(std::move(path)) {
  if (path_.empty()) throw std::invalid_argument("scripted tool path has no waypoints");
  for (size_t k = 1; k < path_.size(); ++k)
    if (!(path_[k].t > path_[k - 1].t))
      throw std::invalid_argument("scripted tool path: waypoint " + std::to_string(k) +
                                  " has a time not after the previous one");
}

Vec3<double> ScriptedDevice::read_position(double t) {
  if (t <= path_.front().t) return path_.front().p;
  for (size_t k = 1; k < path_.size(); ++k)
    if (t <= path_[k].t) {
      const double s = (t - path_[k - 1].t) / (path_[k].t - path_[k - 1].t);
      return path_[k - 1].p + s * (path_[k].p - path_[k - 1].p);
    }
  return path_.back().p;
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
