#include "accuracy/relaxation.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>

namespace tissue::accuracy {
namespace {

using Clock = std::chrono::steady_clock;
constexpr int kContactOmegaSpan = 50;  ///< steps a lowest-mode estimate spans with contact (measured_omega)

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

void check_drive(const TissueModel<double>& m, const Drive& d) {
  if (d.u.size() != 3 * d.nodes.size())
    throw std::invalid_argument(
        fmt::format("relax: {} target values for {} driven nodes (need 3 per node)", d.u.size(), d.nodes.size()));
  if (!d.axes.empty() && d.axes.size() != d.nodes.size())
    throw std::invalid_argument(
        fmt::format("relax: {} axis masks for {} driven nodes (need one per node)", d.axes.size(), d.nodes.size()));
  for (index_t a : d.nodes)
    if (a < 0 || a >= m.n_nodes)
      throw std::invalid_argument(fmt::format("relax: driven node {} out of range (0..{})", a, m.n_nodes - 1));
}

/// Components each node integrates (bit c = free): not fixed by the model, not driven.
std::vector<std::uint8_t> free_components(const TissueModel<double>& m, const Drive& d) {
  std::vector<std::uint8_t> held(m.n_nodes);
  for (index_t a = 0; a < m.n_nodes; ++a) held[a] = fixed_axes(m.node_flags[a]);
  for (std::size_t k = 0; k < d.nodes.size(); ++k) held[d.nodes[k]] |= d.axes.empty() ? kAllAxes : d.axes[k];
  for (auto& h : held) h = std::uint8_t(~h & kAllAxes);
  return held;
}

/// The tool's pose a fraction `frac` of the way from its start to its held pose.
ToolPose tool_pose(const HeldTool& t, double frac) {
  ToolPose p;
  interpolate_pose(t.start.tip, t.start.axis, t.held.tip, t.held.axis, frac, p.tip, p.axis);
  return p;
}

/// Drives the nodes at start + frac (target - start) and moves the tool
/// (if any) from where it was to its pose at frac over the next advance.
void drive_at(Backend& b, const Drive& d, const std::vector<double>& start, double frac, const HeldTool* tool = nullptr,
              double frac_before = -1) {
  if (tool) {
    const ToolMotion m{tool_pose(*tool, frac_before < 0 ? frac : frac_before), tool_pose(*tool, frac)};
    b.move_tools(std::span<const ToolMotion>(&m, 1));
  }
  if (d.nodes.empty()) return;
  std::vector<double> u(d.u.size());
  for (std::size_t k = 0; k < u.size(); ++k) u[k] = start[k] + frac * (d.u[k] - start[k]);
  if (d.axes.empty())
    b.set_driven(d.nodes, u);
  else
    b.set_driven_axes(d.nodes, u, d.axes);
}

/// The driven nodes' start values (3 per node) from u0 (3 x n_nodes, or empty = 0).
std::vector<double> drive_start(const TissueModel<double>& m, const Drive& d, std::span<const double> u0) {
  std::vector<double> s(d.u.size(), 0.0);
  if (u0.empty()) return s;
  for (std::size_t k = 0; k < d.nodes.size(); ++k)
    for (int c = 0; c < 3; ++c) s[3 * k + c] = u0[c * m.n_nodes + d.nodes[k]];
  return s;
}

/// Throws RelaxError when the reduction saw NaN/Inf or an inverted element;
/// `frac` is how far the drive's ramp had got (1 = full targets).
void check_health(const Reductions& r, long first, long last, double frac) {
  const std::string when =
      frac < 1 ? fmt::format(" (ramp at {:.0f}% of the drive's targets)", 100 * frac) : std::string(" (targets held)");
  if (r.bad_elem >= 0)
    throw RelaxError(fmt::format("relaxation steps {}..{}{}: element {} has J = {:.4g} (inverted or degenerate)", first,
                                 last, when, r.bad_elem, r.bad_J));
  if (!r.finite)
    throw RelaxError(fmt::format("relaxation steps {}..{}{}: non-finite displacement or force", first, last, when));
}

}  // namespace

std::vector<double> relaxation_masses(const TissueModel<double>& m, double dt, double safety) {
  if (!(dt > 0) || !(safety > 0 && safety <= 1))
    throw std::invalid_argument(fmt::format("relaxation_masses: dt {} must be > 0 and safety {} in (0, 1]", dt, safety));
  const index_t ne = m.n_elems;
  std::vector<double> g(m.n_nodes, 0.0);
  // IANP: an element's pressure uses its corners' nodal K_a (core node_bulk_moduli)
  const std::vector<double> node_K = m.ianp ? node_bulk_moduli(m) : std::vector<double>{};
  for (index_t e = 0; e < ne; ++e) {
    double len[4], sum = 0;
    for (int a = 0; a < 4; ++a) {
      const double gx = m.dndx[(3 * a) * ne + e], gy = m.dndx[(3 * a + 1) * ne + e], gz = m.dndx[(3 * a + 2) * ne + e];
      len[a] = std::sqrt(gx * gx + gy * gy + gz * gz);
      sum += len[a];
    }
    double K = m.K[e];
    for (int a = 0; a < 4 && m.ianp; ++a) K = std::max(K, node_K[m.elem_nodes[a * ne + e]]);
    const double stiff = (K + 4.0 * m.mu[e] / 3.0) * m.volume[e];
    for (int a = 0; a < 4; ++a) g[m.elem_nodes[a * ne + e]] += stiff * len[a] * sum;
  }
  for (double& x : g) x *= dt * dt / (4 * safety);
  return g;
}

double rayleigh_omega2(std::span<const double> u0, std::span<const double> u1, std::span<const double> f0,
                       std::span<const double> f1, std::span<const double> mass,
                       std::span<const std::uint8_t> free_mask) {
  const std::size_t n = mass.size();
  double num = 0, den = 0;
  for (int c = 0; c < 3; ++c)
    for (std::size_t a = 0; a < n; ++a) {
      if (!(free_mask[a] >> c & 1)) continue;
      const std::size_t k = c * n + a;
      const double du = u1[k] - u0[k];
      num += du * (f1[k] - f0[k]);
      den += mass[a] * du * du;
    }
  return den > 0 ? std::max(num, 0.0) / den : 0.0;
}

namespace {

/// relax's first phase: the drive ramped from its start to its end over ramp_steps, health checked every
/// check_every steps. Returns false when o.stop asked to stop.
bool ramp_drive(Backend& b, const Drive& drive, const std::vector<double>& start, const HeldTool* tool,
                const RelaxOptions& o, long ramp_steps, long& steps) {
  const int ramp_chunk = static_cast<int>(std::clamp(ramp_steps / 200, 1L, long(o.check_every)));
  long last_check = steps;
  while (steps < ramp_steps) {
    const int k = static_cast<int>(std::min<long>(ramp_chunk, ramp_steps - steps));
    drive_at(b, drive, start, double(steps + k) / double(ramp_steps), tool, double(steps) / double(ramp_steps));
    b.advance(k);
    steps += k;
    if (steps - last_check >= o.check_every || steps == ramp_steps) {
      check_health(b.reduce(), last_check, steps - 1, double(steps) / double(ramp_steps));
      last_check = steps;
      if (o.stop && o.stop()) return false;
    }
  }
  return true;
}

/// The lowest mode's frequency (rad/s) measured from the current state over `span` steps (a Rayleigh
/// quotient of the free components; nodes on a tool are held by it, so theirs are left out). Takes span + 1
/// steps. A download's f is the force at the previous download's u, so u0 pairs with the next f.
double measured_omega(Backend& b, const TissueModel<double>& m, std::vector<std::uint8_t> mask, int span,
                      Fields& last) {
  // A tool's contact nodes, and a body contact's node and its triangle's corners, are left out at every
  // step: a node entering or leaving contact is moved by the contact's projection, not by its stiffness.
  // Over one step du is the velocity, which weighs each mode by its frequency, so a contact's chatter
  // outweighed the creep of the lowest mode (two spheres: 11 times its frequency, and each raised damping
  // raised the next estimate); over `span` steps the creep grows and the chatter does not.
  const auto leave_out_contacts = [&] {
    for (const ContactNode& c : b.contacts()) mask[c.node] = 0;
    for (const BodyContactNode& c : b.body_contacts()) {
      mask[c.node] = 0;
      for (int k = 0; k < 3; ++k) mask[m.tris[k * m.n_tris + c.tri]] = 0;
    }
  };
  leave_out_contacts();
  const Fields d0 = b.download();
  b.advance(1);
  leave_out_contacts();
  const Fields f0 = b.download();
  for (int k = 1; k < span; ++k) {
    b.advance(1);
    leave_out_contacts();
  }
  const Fields d1 = span > 1 ? b.download() : f0;
  b.advance(1);
  leave_out_contacts();
  last = b.download();
  return std::sqrt(rayleigh_omega2(d0.u, d1.u, f0.f, last.f, m.mass, mask));
}

/// With bodies in contact: the free residual squared (N^2) over the free components of the nodes no body
/// contact of the last step touches, plus the squared net force of the nodes it touches (a node inside
/// another body and the corners of the triangle it is inside) along each axis none of them holds (along a
/// held one, a roller's reaction takes a share the internal forces do not show). A tool's contact nodes are
/// held by the tool and left out; one among the touched nodes leaves their net unchecked (the tool carries a
/// share of it).
double body_free_force2(Backend& b, const TissueModel<double>& m, const std::vector<std::uint8_t>& free_mask) {
  const Fields f = b.download();
  const index_t n = m.n_nodes, nt = m.n_tris;
  std::vector<std::uint8_t> touched(n, 0), on_tool(n, 0);
  for (const ContactNode& c : b.contacts()) on_tool[c.node] = 1;
  std::uint8_t held = 0;
  for (const BodyContactNode& c : b.body_contacts())
    for (int k = -1; k < 3; ++k) {
      const index_t a = k < 0 ? c.node : m.tris[k * nt + c.tri];
      touched[a] = 1;
      held |= on_tool[a] ? kAllAxes : std::uint8_t(~free_mask[a] & kAllAxes);
    }
  double rest2 = 0, net2 = 0;
  for (int c = 0; c < 3; ++c) {
    double net = 0;
    for (index_t a = 0; a < n; ++a) {
      if (!(free_mask[a] >> c & 1) || on_tool[a]) continue;
      const double v = f.f[c * std::size_t(n) + a];
      if (touched[a])
        net += v;
      else
        rest2 += v * v;
    }
    if (!(held >> c & 1)) net2 += net * net;
  }
  return rest2 + net2;
}

}  // namespace

RelaxResult relax(Backend& b, const TissueModel<double>& model, const Drive& drive, const RelaxOptions& o,
                  std::span<const double> u0, const HeldTool* tool) {
  check_drive(model, drive);
  if (!u0.empty() && u0.size() != 3 * std::size_t(model.n_nodes))
    throw std::invalid_argument(
        fmt::format("relax: start state has {} values for {} nodes (need 3 x n_nodes)", u0.size(), model.n_nodes));
  if (!(o.residual_tol > 0) || !(o.kinetic_tol > 0) || o.check_every < 1 || o.adapt_every < 1)
    throw std::invalid_argument("relax: tolerances must be > 0 and check/adapt intervals >= 1");
  const auto t0 = Clock::now();
  TissueModel<double> m = model;
  const bool contact = tool != nullptr || !o.bodies.empty();  // a tool's or the bodies'
  if (o.mass_scaling) {
    m.mass = relaxation_masses(m, m.dt, contact ? std::min(o.mass_safety, o.contact_mass_safety) : o.mass_safety);
    m.total_mass = 0;
    for (double x : m.mass) m.total_mass += x;
  }
  const double omega0 = lowest_mode_estimate(m);
  double alpha = o.damping >= 0 ? o.damping : 2.0 * omega0;
  set_time_step(m, m.dt, alpha);
  const auto load = [&](std::span<const double> u) {
    b.upload(m);
    if (tool) b.set_tools(std::span<const ToolShape>(&tool->shape, 1), tool->contact);
    if (!u.empty()) b.set_displacements(u);
    if (!o.bodies.empty()) b.set_body_contact(o.bodies);  // its lists built where the bodies are
  };
  load(u0);
  const std::vector<double> start = drive_start(m, drive, u0);
  const std::vector<std::uint8_t> free_mask = free_components(m, drive);

  RelaxResult out;
  const double ramp_time = o.ramp_time >= 0 ? o.ramp_time : 2 * M_PI / omega0;
  long steps = 0;
  out.interrupted = !ramp_drive(b, drive, start, tool, o, std::max(1L, std::lround(ramp_time / m.dt)), steps);
  if (out.interrupted) out.why = fmt::format("was interrupted by a stop request during the ramp, after {} steps", steps);
  const auto tolerances = [&] {
    return fmt::format("relative residual {:.3g} (tolerance {:.3g}), relative kinetic energy {:.3g} (tolerance {:.3g})",
                       out.residual, o.residual_tol, out.kinetic, o.kinetic_tol);
  };

  long last_adapt = steps;
  double best = INFINITY;  // best residual seen, and the step at which it last halved
  long best_step = steps;
  while (!out.interrupted) {
    b.advance(o.check_every);
    steps += o.check_every;
    const Reductions r = b.reduce();
    check_health(r, steps - o.check_every, steps - 1, 1.0);
    const double held = std::max(std::sqrt(r.held_force2), o.force_floor);
    out.residual = std::sqrt(o.bodies.empty() ? r.free_force2 : body_free_force2(b, m, free_mask)) / held;
    out.kinetic = r.kinetic / std::max(0.5 * held * r.max_disp, 1e-300);
    out.last = r;
    out.history.push_back(out.residual);
    if (out.residual <= o.residual_tol && out.kinetic <= o.kinetic_tol) {
      out.converged = true;
      out.why = fmt::format("converged to the tolerances after {} steps: {}", steps, tolerances());
      break;
    }
    if (out.residual < 0.5 * best) {
      best = out.residual;
      best_step = steps;
    }
    const double period = 2 * M_PI / (0.5 * alpha);  // alpha = 2 omega_1 once adapted
    const long stall = std::max(10L * o.check_every, std::lround(o.stall_periods * period / m.dt));
    if (steps - best_step > stall) {
      out.stalled = true;
      if (contact && out.residual <= o.contact_floor * o.residual_tol && out.kinetic <= o.kinetic_tol)
        out.converged = out.at_contact_floor = true;
      out.why = out.converged
                    ? fmt::format("converged at the contact's floor after {} steps: the residual stalled within {:g} x "
                                  "its tolerance (a contact node of zero force going in and out of contact); {}",
                                  steps, o.contact_floor, tolerances())
                    : fmt::format("stalled after {} steps: the best residual, {:.3g}, did not halve in the last {} "
                                  "steps ({:g} periods of the lowest mode): the precision's rounding floor lies above "
                                  "the tolerance; {}",
                                  steps, best, steps - best_step, o.stall_periods, tolerances());
      break;
    }
    if (steps >= o.max_steps) {
      out.why = fmt::format("hit the step limit of {} steps before converging; {}", o.max_steps, tolerances());
      break;
    }
    if (seconds_since(t0) > o.max_wall) {
      out.why = fmt::format("hit the wall-time limit of {:g} s after {} steps before converging; {}", o.max_wall, steps,
                            tolerances());
      break;
    }
    if (o.stop && o.stop()) {
      out.interrupted = true;
      out.why = fmt::format("was interrupted by a stop request after {} steps; {}", steps, tolerances());
      break;
    }
    if (o.adapt_damping && out.residual > o.adapt_above && steps - last_adapt >= o.adapt_every) {
      last_adapt = steps;
      Fields now;
      const int span = contact ? kContactOmegaSpan : 1;
      const double omega = measured_omega(b, m, free_mask, span, now);
      steps += span + 1;
      if (omega > 0 && std::fabs(2 * omega - alpha) > 0.1 * alpha) {  // restart there with alpha = 2 omega
        alpha = 2 * omega;
        set_time_step(m, m.dt, alpha);
        load(now.u);
        drive_at(b, drive, start, 1.0, tool);
        ++out.restarts;
      }
    }
  }
  out.steps = steps;
  out.damping = alpha;
  out.wall = seconds_since(t0);
  return out;
}

}  // namespace tissue::accuracy
