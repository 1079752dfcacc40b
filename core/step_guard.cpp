#include "core/step_guard.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include <fmt/format.h>

#include "core/contact.hpp"
#include "core/tet.hpp"

namespace tissue {
namespace {

Vec3<double> corner(const TissueModel<double>& m, index_t e, int a) {
  return reference_position(m, m.elem_nodes[std::size_t(a) * m.n_elems + e]);
}

/// Distance (m) from x to the capsule of `shape` at `pose` (negative inside).
double capsule_distance(const ToolShape& shape, const ToolPose& pose, const Vec3<double>& x) {
  const Vec3<double> a = pose.tip, b = pose.tip + shape.shaft * pose.axis;
  return norm(x - (a + closest_on_segment(a, b, x) * (b - a))) - shape.radius;
}

}  // namespace

StepGuard::StepGuard(const TissueModel<double>& m, const StepGuardSettings& settings) : settings_(settings) {
  if (settings.interval < 1)
    throw std::invalid_argument(fmt::format("step guard: interval {} must be >= 1 tick", settings.interval));
  if (!(settings.trigger > 0) || !(settings.target > settings.trigger) || !std::isfinite(settings.target))
    throw std::invalid_argument(fmt::format("step guard: trigger {} and target {} must satisfy 0 < trigger < target",
                                            settings.trigger, settings.target));
  if (!(settings.watch >= settings.target) || !std::isfinite(settings.watch))
    throw std::invalid_argument(
        fmt::format("step guard: watch {} must be finite and >= target {}", settings.watch, settings.target));
  if (!(settings.budget >= 0) || !(settings.budget < 1))
    throw std::invalid_argument(fmt::format("step guard: budget {} must be in [0, 1)", settings.budget));
  left_ = settings.budget * m.total_mass - m.added_mass;
  if (!settings.on || !(left_ > 0) || m.scaled_elems == 0 || !(m.dt > 0)) return;
  if (m.elem_step.size() != std::size_t(m.n_elems) || m.elem_mass.size() != std::size_t(m.n_elems))
    throw std::invalid_argument(fmt::format("step guard: the model's element steps ({}) and masses ({}) are not one "
                                            "per element ({}): a model not made by build_model",
                                            m.elem_step.size(), m.elem_mass.size(), m.n_elems));
  step_ = m.elem_step;
  mass_ = m.elem_mass;
  rest_alt_.assign(m.n_elems, 0);
  for (index_t e = 0; e < m.n_elems; ++e) {
    if (!(step_[e] < settings.watch * m.dt)) continue;
    const Vec3<double> X[4] = {corner(m, e, 0), corner(m, e, 1), corner(m, e, 2), corner(m, e, 3)};
    rest_alt_[e] = tet_min_altitude(X, m.volume[e]);
    elems_.push_back(e);
    const Vec3<double> c = 0.25 * (X[0] + X[1] + X[2] + X[3]);
    double r = 0;
    for (const Vec3<double>& x : X) r = std::max(r, norm(x - c));
    centre_.push_back(c);
    bound_.push_back(r);
  }
}

std::vector<index_t> StepGuard::near(std::span<const ToolShape> shapes,
                                     std::span<const ToolPose> poses, double reach) const {
  std::vector<index_t> out;
  const std::size_t n_tools = std::min(shapes.size(), poses.size());
  for (std::size_t k = 0; k < elems_.size(); ++k) {
    bool hit = false;
    for (std::size_t t = 0; t < n_tools && !hit; ++t)
      hit = capsule_distance(shapes[t], poses[t], centre_[k]) <= reach + bound_[k];
    if (hit) out.push_back(elems_[k]);
  }
  return out;
}

StepGuardLift StepGuard::lift(const TissueModel<double>& m, std::span<double> mass, std::span<const index_t> elems,
                              std::span<const double> altitude) {
  StepGuardLift out;
  if (elems.size() != altitude.size() || mass.size() != std::size_t(m.n_nodes))
    throw std::invalid_argument(fmt::format("step guard: {} altitudes for {} elements, {} masses for {} nodes",
                                            altitude.size(), elems.size(), mass.size(), m.n_nodes));
  const index_t ne = m.n_elems;
  for (std::size_t k = 0; k < elems.size(); ++k) {
    const index_t e = elems[k];
    if (e < 0 || e >= ne || std::size_t(e) >= rest_alt_.size() || !(rest_alt_[e] > 0))
      throw std::invalid_argument(fmt::format("step guard: element {} is not watched", e));
    if (!(altitude[k] > 0) || !std::isfinite(altitude[k])) continue;
    const double step = step_[e] * altitude[k] / rest_alt_[e];  // the step on its deformed shape (s)
    if (out.worst_elem < 0 || step < out.worst * m.dt) {
      out.worst = step / m.dt;
      out.worst_elem = e;
    }
    if (!(step < settings_.trigger * m.dt)) continue;
    const double r = settings_.target * m.dt / step, g = r * r;  // the step goes as 1 / sqrt(density)
    const double extra = (g - 1) * mass_[e];
    if (extra > left_) {
      ++out.refused;
      continue;
    }
    left_ -= extra;
    for (int a = 0; a < 4; ++a) mass[m.elem_nodes[std::size_t(a) * ne + e]] += extra / 4;
    mass_[e] *= g;
    step_[e] *= r;
    ++out.elements;
    out.added_mass += extra;
  }
  added_ += out.added_mass;
  return out;
}

}  // namespace tissue
