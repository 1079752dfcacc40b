// A random but smooth tool motion for soak runs (scripts/soak): an endless
// series of 4-second cycles, each press -> drag -> grasp and move (sideways,
// or pulled back by a pull factor) -> release -> back up, around the scene's
// first press target. Every cycle's key points come from a hash of the seed
// and the cycle number, so the
// motion is reproducible and the device holds no history: memory stays
// constant however long it runs. Between key points the tip moves along a
// cosine ease (zero velocity at each key point, no jumps).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>

#include "core/device.hpp"
#include "core/tool.hpp"

namespace tissue::viewer {

class SoakDevice : public Device {
 public:
  static constexpr double kCycle = 4.0;  ///< s

  /// start: the hover point; dir: unit press direction; approach: distance
  /// from start to the surface along dir (m); radius: the tool's (m).
  /// pull: how far the grasp pulls the tissue back before the release, in
  /// units of the press depth (0: the grasp drags it sideways by one tool
  /// radius instead; docs/reliability.md has what a pull beyond the rest
  /// surface does at the release).
  SoakDevice(Vec3<double> start, Vec3<double> dir, double approach, double radius, std::uint64_t seed = 1,
             double pull = 0)
      : start_(start), dir_(unit_or(dir, Vec3<double>{0, 0, -1})), approach_(approach), radius_(radius), seed_(seed),
        pull_(pull) {
    // two unit vectors across the press direction
    const Vec3<double> helper = std::fabs(dir_.x) < 0.9 ? Vec3<double>{1, 0, 0} : Vec3<double>{0, 1, 0};
    side_ = unit_or(cross(dir_, helper), Vec3<double>{1, 0, 0});
    up_ = cross(dir_, side_);
  }

  /// The motion from `start` seconds into the series (reproducing a late cycle at once).
  void set_start(double start) { start_time_ = start; }

  ToolInput read(double t_session) override {
    const double t = t_session + start_time_;
    const double c = std::floor(t / kCycle);
    const double s = t - c * kCycle;  // seconds into the cycle
    const Keys k = keys(static_cast<std::uint64_t>(c));
    // 0-1 s press, 1-2 s drag, 2-3 s grasp and pull back, 3-3.5 s release (held still), 3.5-4 s up to the hover
    ToolInput in;
    if (s < 1) {
      in.tip = ease(k.hover, k.press, s);
    } else if (s < 2) {
      in.tip = ease(k.press, k.drag, s - 1);
    } else if (s < 3) {
      in.tip = ease(k.drag, k.pull, s - 2);
      in.grasp = true;
    } else if (s < 3.5) {
      in.tip = k.pull;
    } else {
      in.tip = ease(k.pull, keys(static_cast<std::uint64_t>(c) + 1).hover, 2 * (s - 3.5));
    }
    return in;
  }
  void send_force(const Vec3<double>&) override {}

 private:
  struct Keys {
    Vec3<double> hover, press, drag, pull;
  };

  /// Uniform in [0, 1) from (seed, cycle, slot): splitmix64.
  double uniform(std::uint64_t cycle, int slot) const {
    std::uint64_t z = seed_ * 0x9E3779B97F4A7C15ull + cycle * 0xBF58476D1CE4E5B9ull + std::uint64_t(slot) * 0x94D049BB133111EBull;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    z ^= z >> 31;
    return double(z >> 11) * 0x1.0p-53;
  }
  double symmetric(std::uint64_t cycle, int slot) const { return 2 * uniform(cycle, slot) - 1; }

  Keys keys(std::uint64_t c) const {
    // the press lands within 3 tool radii of the first target, 1-3 radii deep (at least 1 mm)
    const double r = std::max(radius_, 1e-3);
    const Vec3<double> lateral = 3 * r * (symmetric(c, 0) * side_ + symmetric(c, 1) * up_);
    const double depth = (1 + 2 * uniform(c, 2)) * r;
    Keys k;
    k.hover = start_ + 0.5 * r * (symmetric(c, 3) * side_ + symmetric(c, 4) * up_);
    k.press = start_ + (approach_ + depth) * dir_ + lateral;
    k.drag = k.press + 2 * r * (symmetric(c, 5) * side_ + symmetric(c, 6) * up_);
    k.pull = pull_ > 0 ? k.drag - pull_ * (0.5 + uniform(c, 7)) * depth * dir_  // back towards the surface and beyond
                       : k.drag + r * (symmetric(c, 7) * side_ + symmetric(c, 8) * up_);  // sideways: shear
    return k;
  }

  static Vec3<double> ease(const Vec3<double>& a, const Vec3<double>& b, double s) {
    const double w = 0.5 * (1 - std::cos(3.14159265358979323846 * std::fmin(std::fmax(s, 0.0), 1.0)));
    return a + w * (b - a);
  }

  Vec3<double> start_, dir_, side_, up_;
  double approach_, radius_;
  std::uint64_t seed_;
  double pull_;
  double start_time_ = 0;
};

}  // namespace tissue::viewer
