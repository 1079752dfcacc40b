#include "accuracy/reference.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <stdexcept>

#include "backends/registry.hpp"

namespace tissue::accuracy {

ReferenceSolution reference_solution(const TissueModel<double>& model, const Drive& drive,
                                     const ReferenceOptions& o, const HeldTool* tool) {
  if (!(o.dt_safety > 0 && o.dt_safety <= 1))
    throw std::invalid_argument(fmt::format("reference: dt safety factor {} must be in (0, 1]", o.dt_safety));
  TissueModel<double> m = model;
  set_time_step(m, o.dt_safety * m.dt_crit, m.damping);
  auto backend = create_backend(o.backend, Precision::Double);
  ReferenceSolution ref;
  ref.dt = m.dt;
  ref.relax = relax(*backend, m, drive, o.relax, {}, tool);
  if (!ref.relax.converged && !ref.relax.interrupted)
    throw std::runtime_error(fmt::format(
        "reference: dynamic relaxation stopped after {} steps ({:.1f} s) at relative residual {:.3g} "
        "(wanted {:.3g}) and relative kinetic energy {:.3g} (wanted {:.3g}): it {}",
        ref.relax.steps, ref.relax.wall, ref.relax.residual, o.relax.residual_tol, ref.relax.kinetic,
        o.relax.kinetic_tol, ref.relax.why));
  ref.fields = backend->download();
  ref.reaction = ref.relax.last.reaction;
  ref.tool_force = -1.0 * ref.relax.last.tools[0].reaction;
  ref.contact_nodes = ref.relax.last.tools[0].contact;
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

namespace {

/// A pose the relaxation's ramp can start from: `start` itself when it does
/// not touch the undeformed surface, else `start` moved back, a radius at a
/// time, along the motion from `held` to it (the tool's axis for a tool that
/// does not move) until it no longer touches. A path that begins inside the
/// tissue would otherwise have its contact push the surface nodes a press
/// deep in one step, inverting the elements under the tool.
ToolPose retracted(const TissueModel<double>& model, const ToolShape& shape, ToolPose start, const ToolPose& held) {
  const Vec3<double> away = start.tip - held.tip;
  const Vec3<double> dir = norm(away) > 1e-9 * shape.radius ? (1 / norm(away)) * away : unit_or(held.axis, {0, 0, 1});
  if (const std::optional<ToolPose> out = retracted_from_reference_surface(model, shape, start, dir, shape.radius))
    return *out;
  throw std::runtime_error(fmt::format(
      "held_tool: tool '{}' starts in contact with the tissue and still touches it {} radii back along ({:.3g}, "
      "{:.3g}, {:.3g}); start its path outside the body",
      shape.name, kMaxRetractSteps, dir.x, dir.y, dir.z));
}

}  // namespace

HeldTool held_tool(const TissueModel<double>& model, const ToolSetting& tool, const std::vector<Waypoint>& path,
                   double tick, double t_hold, const ContactOptions& contact) {
  if (!(tick > 0)) throw std::invalid_argument("held_tool: tick must be > 0 s");
  ScriptedDevice device(path);
  const auto pose_at = [&](double t) {
    const ToolInput in = device.read(t);
    return ToolPose{in.tip, unit_or(in.axis, unit_or(tool.axis, Vec3<double>{0, 0, 1}))};
  };
  HeldTool h;
  h.shape = tool.shape;
  h.contact = contact;
  h.held = pose_at(t_hold);
  ToolPose prev = pose_at(tick);  // the Scheduler's first tick reads t = tick
  for (long k = 0;; ++k) {
    const double t = (k + 1) * tick;
    if (t > t_hold + 1e-12)
      throw std::runtime_error(
          fmt::format("held_tool: tool '{}' does not touch the surface before t = {} s", tool.shape.name, t_hold));
    const ToolPose p = pose_at(t);
    if (touches_reference_surface(model, tool.shape, p)) {
      h.start = retracted(model, tool.shape, prev, h.held);
      h.t_touch = t;
      return h;
    }
    prev = p;
  }
}

}  // namespace tissue::accuracy
