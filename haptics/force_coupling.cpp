#include "haptics/force_coupling.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace tissue {
namespace {

void require(bool ok, const char* name, double value, const char* rule) {
  if (!ok) throw std::invalid_argument(fmt::format("virtual coupling: {} = {} must be {}", name, value, rule));
}

double effective_mass(const CouplingParams& p) {
  return p.proxy_mass + p.period * p.damping + p.period * p.period * p.stiffness;
}

}  // namespace

void validate(const CouplingParams& p) {
  require(std::isfinite(p.stiffness) && p.stiffness > 0, "stiffness (N/m)", p.stiffness, "finite and > 0");
  require(std::isfinite(p.damping) && p.damping >= 0, "damping (N s/m)", p.damping, "finite and >= 0");
  require(std::isfinite(p.proxy_mass) && p.proxy_mass > 0, "proxy mass (kg)", p.proxy_mass, "finite and > 0");
  require(std::isfinite(p.max_force) && p.max_force > 0, "maximum force (N)", p.max_force, "finite and > 0");
  require(std::isfinite(p.period) && p.period > 0, "period (s)", p.period, "finite and > 0");
}

double coupling_jump_gain(const CouplingParams& p) {
  CouplingParams unclamped = p;
  unclamped.max_force = 1e300;
  CouplingState s;
  coupling_step(unclamped, s, {0, 0, 0});
  s.env_force = {1, 0, 0};
  // the response settles within a few 1 / (zeta w_n); run 4 s of it
  double prev = 0, gain = 0;
  const long n = std::lround(4.0 / p.period);
  for (long k = 0; k < n; ++k) {
    coupling_step(unclamped, s, {0, 0, 0});
    gain = std::max(gain, std::abs(s.rendered.x - prev));
    prev = s.rendered.x;
  }
  return gain;
}

Vec3<double> clamp_force(Vec3<double> f, double max_force) {
  const double n = norm(f);
  return n > max_force ? (max_force / n) * f : f;
}

Vec3<double> coupling_step(const CouplingParams& p, CouplingState& s, Vec3<double> device_pos) {
  const double h = p.period;
  if (!s.started) {
    s = CouplingState{};
    s.started = true;
    s.proxy = device_pos;
    s.device = device_pos;
    return s.proxy;
  }
  s.device_vel = (1.0 / h) * (device_pos - s.device);
  s.device = device_pos;
  const Vec3<double> impulse =
      h * (p.stiffness * (s.device - s.proxy) + p.damping * s.device_vel + s.env_force);
  s.proxy_vel = (1.0 / effective_mass(p)) * (p.proxy_mass * s.proxy_vel + impulse);
  s.proxy = s.proxy + h * s.proxy_vel;
  s.coupling = p.stiffness * (s.proxy - s.device);
  s.rendered = clamp_force(s.coupling, p.max_force);
  s.clamped = norm(s.coupling) > p.max_force;
  return s.proxy;
}

CoupledDevice::CoupledDevice(Device& inner, CouplingParams params) : inner_(inner), params_(params) {
  validate(params_);
}

ToolInput CoupledDevice::read(double t) {
  ToolInput in = inner_.read(t);
  in.tip = coupling_step(params_, state_, in.tip);
  return in;
}

void CoupledDevice::send_force(const Vec3<double>& force) {
  state_.env_force = force;
  inner_.send_force(state_.rendered);
}

}  // namespace tissue
