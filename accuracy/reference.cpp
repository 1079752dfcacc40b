#include "accuracy/reference.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "backends/registry.hpp"

namespace tissue::accuracy {

ReferenceSolution reference_solution(const TissueModel<double>& model, const Drive& drive,
                                     const ReferenceOptions& o) {
  if (!(o.dt_safety > 0 && o.dt_safety <= 1))
    throw std::invalid_argument(fmt::format("reference: dt safety factor {} must be in (0, 1]", o.dt_safety));
  TissueModel<double> m = model;
  set_time_step(m, o.dt_safety * m.dt_crit, m.damping);
  auto backend = create_backend(o.backend, Precision::Double);
  ReferenceSolution ref;
  ref.dt = m.dt;
  ref.relax = relax(*backend, m, drive, o.relax);
  if (!ref.relax.converged && !ref.relax.interrupted)
    throw std::runtime_error(fmt::format(
        "reference: dynamic relaxation stopped after {} steps ({:.1f} s) at relative residual {:.3g} "
        "(wanted {:.3g}) and relative kinetic energy {:.3g} (wanted {:.3g})",
        ref.relax.steps, ref.relax.wall, ref.relax.residual, o.relax.residual_tol, ref.relax.kinetic,
        o.relax.kinetic_tol));
  ref.fields = backend->download();
  ref.reaction = ref.relax.last.reaction;
  ref.max_disp = ref.relax.last.max_disp;
  ref.strain_energy = ref.relax.last.strain_energy;
  return ref;
}

double hold_start(const std::vector<Waypoint>& path) {
  if (path.empty()) throw std::invalid_argument("hold_start: the tool path has no waypoints");
  double best_len = 0, start = path.back().t;
  for (std::size_t k = 0; k + 1 < path.size(); ++k) {
    const double len = path[k + 1].t - path[k].t;
    if (norm(path[k + 1].p - path[k].p) == 0 && len > best_len) {
      best_len = len;
      start = path[k].t;
    }
  }
  return start;
}

HeldContact held_contact(const TissueModel<double>& model, const std::vector<Waypoint>& path, double tick,
                         double t_hold, const std::string& backend_name, Precision precision) {
  if (!(tick > 0)) throw std::invalid_argument("held_contact: tick must be > 0 s");
  ScriptedDevice device(path);
  auto backend = create_backend(backend_name, precision);
  backend->upload(model);
  HeldContact c;
  Vec3<double> prev = device.read_position(tick);  // the Scheduler's first tick reads t = tick
  for (long k = 0;; ++k) {
    const double t = (k + 1) * tick;
    if (t > t_hold + 1e-12)
      throw std::runtime_error(fmt::format("held_contact: the tool path does not touch the surface before t = {} s",
                                           t_hold));
    const Vec3<double> tip = device.read_position(t);
    const Hit hit = backend->collide(prev, tip);
    if (hit.hit() && dot(tip - prev, hit.normal) < 0) {
      c.tri = hit.tri;
      c.point = hit.point;
      c.t_contact = t;
      c.drive.nodes.assign(hit.nodes, hit.nodes + 3);
      break;
    }
    prev = tip;
  }
  c.tip = device.read_position(t_hold);
  const Vec3<double> d = c.tip - c.point;
  for (int k = 0; k < 3; ++k)
    for (int j = 0; j < 3; ++j) c.drive.u.push_back(d[j]);
  return c;
}

}  // namespace tissue::accuracy
