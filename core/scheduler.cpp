#include "core/scheduler.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace tissue {

Scheduler::Scheduler(Backend& backend, const TissueModel<double>& model, SchedulerSettings settings)
    : backend_(backend), model_(model), settings_(settings) {
  if (!(settings_.tick > 0)) throw std::invalid_argument("haptic tick must be > 0 s");
  steps_per_tick_ = std::max(1, static_cast<int>(std::lround(settings_.tick / model.dt)));
  depth_ = settings_.depth;
  if (settings_.depth == kDepthAuto) {
    if (settings_.auto_start < 0)
      throw std::invalid_argument(fmt::format("depth auto: start depth {} must be >= 0", settings_.auto_start));
    if (!(settings_.auto_tol > 0) || !std::isfinite(settings_.auto_tol))
      throw std::invalid_argument(fmt::format("depth auto: tolerance {} must be > 0", settings_.auto_tol));
    auto_depth_ = true;
    depth_ = settings_.auto_start;
  }
  // depth N: an empty region (nothing moves) until the first contact seeds it
  region_ = backend_.build_region({}, depth_);
}

bool Scheduler::grow_region(const Reductions& r) {
  if (!auto_depth_ || seeds_.empty() || region_.whole()) return false;
  if (r.front_disp < 0)
    throw SimulationError(fmt::format("depth auto: the {} backend does not report the front ring's displacement "
                                      "(Reductions::front_disp); use a fixed depth",
                                      backend_.name()));
  if (!(r.front_disp > settings_.auto_tol * r.max_disp)) return false;
  ++depth_;
  region_ = backend_.build_region(seeds_, depth_);
  return true;
}

void Scheduler::start_contact(const Hit& hit, const Vec3<double>& tip) {
  contact_tri_ = hit.tri;
  for (int k = 0; k < 3; ++k) {
    nodes_[k] = hit.nodes[k];
    u0_[k] = hit.u[k];
  }
  p0_ = hit.point;
  n0_ = hit.normal;
  if (!region_.whole()) {
    std::vector<index_t> seeds(nodes_, nodes_ + 3);
    std::sort(seeds.begin(), seeds.end());
    if (seeds != seeds_) {
      region_ = backend_.build_region(seeds, depth_);
      seeds_ = std::move(seeds);
    }
  }
  drive(tip);
}

void Scheduler::drive(const Vec3<double>& tip) {
  const Vec3<double> d = tip - p0_;
  double u[9];
  for (int k = 0; k < 3; ++k)
    for (int c = 0; c < 3; ++c) u[3 * k + c] = u0_[k][c] + d[c];
  backend_.set_driven(std::span<const index_t>(nodes_, 3), std::span<const double>(u, 9));
}

TickReport Scheduler::tick(Device& device) {
  const double t_end = (tick_ + 1) * settings_.tick;
  const Vec3<double> tip = device.read_position(t_end);
  if (!has_prev_) {
    prev_ = tip;
    has_prev_ = true;
  }
  // collide -> contact
  if (contact_tri_ < 0) {
    const Hit hit = backend_.collide(prev_, tip);
    // only an entering crossing starts a contact (a segment leaving the
    // tissue, e.g. a tool withdrawing through relaxing tissue, does not)
    if (hit.hit() && dot(tip - prev_, hit.normal) < 0) start_contact(hit, tip);
  } else if (dot(tip - p0_, n0_) > 0) {
    backend_.clear_driven();
    contact_tri_ = -1;
  } else {
    drive(tip);
  }
  // TLED steps over the region, then one reduction
  const long first_step = total_steps_;
  backend_.advance(steps_per_tick_);
  total_steps_ += steps_per_tick_;
  const Reductions r = backend_.reduce();
  if (r.bad_elem >= 0)
    throw SimulationError(fmt::format(
        "tick {} (TLED steps {}..{}): element {} has J = {:.4g} (inverted or degenerate); stopping. "
        "Reduce the indentation or the time step",
        tick_, first_step, total_steps_ - 1, r.bad_elem, r.bad_J));
  if (!r.finite)
    throw SimulationError(fmt::format("tick {} (TLED steps {}..{}): non-finite displacement or force; stopping",
                                      tick_, first_step, total_steps_ - 1));
  TickReport rep;
  rep.tick = tick_;
  rep.time = t_end;
  rep.tool = tip;
  rep.contact_tri = contact_tri_;
  rep.force = contact_tri_ >= 0 ? -1.0 * r.reaction : Vec3<double>{0, 0, 0};
  rep.internal = r.internal;
  rep.region_nodes = region_.nodes();
  rep.region_elems = region_.n_elems;
  const double held = std::sqrt(r.held_force2);
  rep.residual = std::sqrt(r.free_force2) / std::max(held, settings_.force_floor);
  rep.kinetic = r.kinetic;
  rep.strain_energy = r.strain_energy;
  rep.max_disp = r.max_disp;
  rep.front_disp = r.front_disp;
  const double energy_scale = std::max(0.5 * held * r.max_disp, 1e-18);
  rep.kinetic_rel = r.kinetic / energy_scale;
  rep.equilibrium = rep.residual < settings_.residual_tol && rep.kinetic_rel < settings_.kinetic_tol;
  if (grow_region(r)) {  // the next tick runs on the larger region
    rep.equilibrium = false;
    rep.region_nodes = region_.nodes();
    rep.region_elems = region_.n_elems;
  }
  rep.depth = depth_;
  rep.steps = steps_per_tick_;
  device.send_force(rep.force);
  prev_ = tip;
  ++tick_;
  return rep;
}

}  // namespace tissue
