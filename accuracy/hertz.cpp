#include "accuracy/hertz.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

#include "accuracy/relaxation.hpp"
#include "backends/registry.hpp"
#include "core/box_mesh.hpp"

namespace tissue::accuracy {
namespace {

using Clock = std::chrono::steady_clock;

constexpr double kUpperCore = 0.85;    ///< the upper block's core edge over the lower's (hertz_pair)
constexpr int kCycleSteps = 600;       ///< steps a cycling force is averaged over
constexpr double kCycleSpread = 2e-3;  ///< most (max - min) / mean of it that counts as settled

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

/// Mean length of the edges of elements with a corner within `radius` of the origin's top (m).
double edge_near_origin(const ModelInput& in, double radius) {
  double sum = 0;
  long count = 0;
  const auto pos = [&](index_t i) { return Vec3<double>{in.nodes[3 * i], in.nodes[3 * i + 1], in.nodes[3 * i + 2]}; };
  for (std::size_t e = 0; e < in.tets.size() / 4; ++e) {
    bool near = false;
    for (int a = 0; a < 4; ++a) near = near || norm(pos(in.tets[4 * e + a])) < radius;
    if (!near) continue;
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b) {
        sum += norm(pos(in.tets[4 * e + a]) - pos(in.tets[4 * e + b]));
        ++count;
      }
  }
  return count ? sum / double(count) : 0.0;
}

/// Height above its lowest point of a sphere's surface of radius R at distance r from its axis: the cap out
/// to `cap`, then along its tangent cone (0 for a flat one, R infinite).
double cap_height(double R, double r, double cap) {
  if (!std::isfinite(R)) return 0;
  const double rr = std::min(r, cap);
  const double h = R - std::sqrt(R * R - rr * rr);
  return r <= cap ? h : h + (r - cap) * cap / std::sqrt(R * R - cap * cap);
}

/// The radius Hertz's formula takes: the rigid sphere's, or the two spheres' R* (1/R* = 1/R_1 + 1/R_2).
double effective_radius(const HertzOptions& o) { return o.spheres ? 1 / (1 / o.R + 1 / o.upper.R) : o.R; }

/// Sum of the z internal forces over `nodes` (N).
double force_z(const Fields& f, index_t n_nodes, const std::vector<index_t>& nodes) {
  double s = 0;
  for (index_t a : nodes) s += f.f[2 * std::size_t(n_nodes) + a];
  return s;
}

}  // namespace

double hertz_force_pair(double E1, double nu1, double R1, double E2, double nu2, double R2, double delta) {
  // the rigid sphere's formula with E / (1 - nu^2) = E* and R = R*
  return hertz_force(1 / ((1 - nu1 * nu1) / E1 + (1 - nu2 * nu2) / E2), 0.0, 1 / (1 / R1 + 1 / R2), delta);
}

HertzPairMesh hertz_pair(int n, double L, double core, double p, const HertzSphere& lower, const HertzSphere& upper,
                         double cap) {
  if (!(cap > 0 && cap < lower.R && cap < upper.R))
    throw std::invalid_argument(fmt::format(
        "hertz_pair: the cap radius {} must be > 0 and below both spheres' radii ({}, {})", cap, lower.R, upper.R));
  HertzPairMesh out;
  out.in = hertz_block(n, L, core, p, lower.E, lower.nu);
  // the upper block's core cells are kUpperCore of the lower's, so that the two meshes' nodes do not lie
  // node on node across the contact (they meet at the origin only)
  const ModelInput up = hertz_block(n, L, kUpperCore * core, p, upper.E, upper.nu);
  ModelInput& in = out.in;
  const index_t nl = static_cast<index_t>(in.nodes.size() / 3), nu = static_cast<index_t>(up.nodes.size() / 3);
  for (index_t i = 0; i < nl; ++i) {
    double* x = &in.nodes[3 * std::size_t(i)];
    x[2] -= cap_height(lower.R, std::hypot(x[0], x[1]), cap);
  }
  out.first_upper = nl;
  for (index_t i = 0; i < nu; ++i) {
    const double* x = &up.nodes[3 * std::size_t(i)];
    in.nodes.insert(in.nodes.end(), {x[0], x[1], -x[2] + cap_height(upper.R, std::hypot(x[0], x[1]), cap)});
    in.fixed.push_back(0);
    in.fixed_axes.push_back(up.fixed_axes[i]);
    if (up.fixed[i]) out.upper_far.push_back(nl + i);  // the block's base is the upper body's far face
  }
  const std::size_t lower_elems = in.tets.size() / 4;
  for (std::size_t e = 0; e < up.tets.size() / 4; ++e) {  // mirrored in z: two corners swap to keep the orientation
    const index_t* t = &up.tets[4 * e];
    in.tets.insert(in.tets.end(), {t[0] + nl, t[2] + nl, t[1] + nl, t[3] + nl});
  }
  in.materials.push_back(up.materials[0]);
  in.elem_material.assign(lower_elems, 0);
  in.elem_material.resize(in.tets.size() / 4, 1);
  in.source = fmt::format("Hertz pair of graded quarter blocks ({} cells per axis each), spheres R {} and {} m", n,
                          lower.R, upper.R);
  return out;
}

double hertz_force(double E, double nu, double R, double delta) {
  return 4.0 / 3.0 * E / (1 - nu * nu) * std::sqrt(R) * std::pow(delta, 1.5);
}

ModelInput hertz_block(int n, double L, double core, double p, double E, double nu) {
  if (n < 2 || !(L > 0) || !(core > 0 && core < L) || !(p >= 1))
    throw std::invalid_argument(fmt::format(
        "hertz_block: need n = {} >= 2 cells, L = {} > 0, 0 < core = {} < L and grading p = {} >= 1", n, L, core, p));
  // the core's share of the cells: a cube of n_core cells per axis mapped
  // uniformly onto [0, core]^3, the rest graded out to L as a power of the
  // cube's radius with exponent q (q = p when n_core comes out exact)
  const int n_core = std::clamp(static_cast<int>(std::lround(n * std::pow(core / L, 1.0 / p))), 1, n - 1);
  const double rc = double(n_core) / n;
  const double q = std::log(L / core) / std::log(1.0 / rc);
  ModelInput in;
  box_mesh(in, n, n, n, 1.0, 1.0, 1.0);
  const index_t nn = static_cast<index_t>(in.nodes.size() / 3);
  in.fixed.assign(nn, 0);
  in.fixed_axes.assign(nn, 0);
  for (index_t i = 0; i < nn; ++i) {
    double* x = &in.nodes[3 * std::size_t(i)];
    const Vec3<double> xi{x[0], x[1], 1.0 - x[2]};  // xi_z measured down from the top
    const double r = std::max({xi.x, xi.y, xi.z});
    const double s = r <= rc ? core / rc : core * std::pow(r / rc, q) / r;
    x[0] = s * xi.x;
    x[1] = s * xi.y;
    x[2] = -s * xi.z;
    if (xi.z == 1.0) in.fixed[i] = 1;            // the base
    if (xi.x == 0.0) in.fixed_axes[i] |= 1;      // symmetry plane x = 0: roller
    if (xi.y == 0.0) in.fixed_axes[i] |= 2;      // symmetry plane y = 0
  }
  in.materials = {{E / (2 * (1 + nu)), E / (3 * (1 - 2 * nu)), 1000}};
  in.source = fmt::format("Hertz quarter block ({} cells per axis)", n);
  return in;
}

HertzStudy run_hertz(const HertzOptions& o) {
  if (o.ratios.empty() || o.levels.empty()) throw std::invalid_argument("hertz: no indentation or no mesh level");
  for (std::size_t k = 0; k < o.ratios.size(); ++k)
    if (!(o.ratios[k] > 0) || (k > 0 && !(o.ratios[k] > o.ratios[k - 1])))
      throw std::invalid_argument("hertz: indentation ratios must be positive and ascending");
  HertzStudy study;
  study.options = o;
  const double R_eff = effective_radius(o);
  const double a_max = std::sqrt(R_eff * R_eff * o.ratios.back());
  study.L = o.block * a_max;
  study.device = create_backend(o.backend, Precision::Double)->device_name();
  for (int n : o.levels) {
    const auto t0 = Clock::now();
    const HertzPairMesh pair = o.spheres ? hertz_pair(n, study.L, o.core * a_max, o.grading, {o.E, o.nu, o.R},
                                                      o.upper, 2 * a_max)
                                         : HertzPairMesh{hertz_block(n, study.L, o.core * a_max, o.grading, o.E, o.nu), 0, {}};
    const ModelInput& in = pair.in;
    TissueModel<double> m = build_model(in);
    set_time_step(m, 0.9 * m.dt_crit, m.damping);
    HertzLevel level;
    level.cells = n;
    level.nodes = m.n_nodes;
    level.elems = m.n_elems;
    level.h_contact = edge_near_origin(in, a_max);
    auto backend = create_backend(o.backend, Precision::Double);
    HeldTool tool;
    tool.shape = {"sphere", o.R, 0};
    tool.start = {{0, 0, o.R}, {0, 0, 1}};  // touching the top at the corner
    RelaxOptions ro;
    ro.residual_tol = o.residual_tol;
    ro.kinetic_tol = 1e-3 * o.residual_tol;
    ro.max_wall = 3600;  // the finest meshes are large: give them the hour a verification run may take
    Drive drive;
    std::vector<index_t> base;  // the lower block's fixed base
    if (o.spheres) {
      ro.bodies.first_node = {0, pair.first_upper, m.n_nodes};
      ro.bodies.pairs = {{0, 1, 0.0}};
      drive.nodes = pair.upper_far;
      for (index_t a = 0; a < pair.first_upper; ++a)
        if (in.fixed[a]) base.push_back(a);
    }
    std::vector<double> u;
    for (double ratio : o.ratios) {
      const double delta = ratio * R_eff;
      tool.held = {{0, 0, o.R - delta}, {0, 0, 1}};
      drive.u.assign(3 * drive.nodes.size(), 0.0);
      for (std::size_t k = 0; k < drive.nodes.size(); ++k) drive.u[3 * k + 2] = -delta;
      const RelaxResult r = relax(*backend, m, drive, ro, u, o.spheres ? nullptr : &tool);
      // Two bodies: a node whose nearest point jumps between the triangles at a corner of the other mesh
      // (the meshes meet node on node at the origin) can keep a cycle of a few steps that no damping ends.
      // The force is then the mean over kCycleSteps steps, taken when it varies by at most kCycleSpread.
      double spread = 0, cycle_far = 0, cycle_support = 0;
      const bool cycling = o.spheres && r.stalled && !r.converged;
      if (cycling) {
        double lo = INFINITY, hi = -INFINITY;
        for (int k = 0; k < kCycleSteps; ++k) {
          backend->advance(1);
          const Reductions red = backend->reduce();
          if (red.bad_elem >= 0 || !red.finite)
            throw RelaxError(fmt::format("hertz: {} cells, delta/R* = {}: element {} inverted or a non-finite value "
                                         "while the force was averaged", n, ratio, red.bad_elem));
          const Fields now = backend->download();
          const double far = force_z(now, m.n_nodes, drive.nodes);
          lo = std::min(lo, far);
          hi = std::max(hi, far);
          cycle_far += far / kCycleSteps;
          cycle_support += force_z(now, m.n_nodes, base) / kCycleSteps;
        }
        spread = (hi - lo) / std::max(std::fabs(cycle_far), 1e-300);
      }
      if (!r.converged && !(cycling && spread <= kCycleSpread))
        throw std::runtime_error(fmt::format(
            "hertz: {} cells, delta/R{} = {}: the relaxation stopped after {} steps at residual {:.3g}, kinetic {:.3g}: "
            "it {}{}",
            n, o.spheres ? "*" : "", ratio, r.steps, r.residual, r.kinetic, r.why,
            cycling ? fmt::format("; the force then varied by {:.3g} of it over {} steps (the most taken is {:g})",
                                  spread, kCycleSteps, kCycleSpread)
                    : std::string()));
      const Fields f = backend->download();
      u = f.u;
      HertzPoint p;
      p.delta = delta;
      if (o.spheres) {
        const double far = cycling ? cycle_far : force_z(f, m.n_nodes, drive.nodes);
        const double support = cycling ? cycle_support : force_z(f, m.n_nodes, base);
        p.force = 4 * std::fabs(far);
        p.spread = spread;
        p.balance = std::fabs(far + support) / std::max(std::fabs(far), 1e-300);
        p.hertz = hertz_force_pair(o.E, o.nu, o.R, o.upper.E, o.upper.nu, o.upper.R, delta);
        p.contact_nodes = static_cast<index_t>(backend->body_contacts().size());
      } else {
        p.force = -4 * r.last.tools[0].reaction.z;
        p.hertz = hertz_force(o.E, o.nu, o.R, delta);
        p.contact_nodes = r.last.tools[0].contact;
      }
      p.error = (p.force - p.hertz) / p.hertz;
      level.max_error = std::max(level.max_error, std::fabs(p.error));
      level.points.push_back(p);
      tool.start = tool.held;
      if (o.verbose)
        fmt::print(stderr,
                   "  hertz{} nu {} {:3} cells ({} tets): delta/R{} {:.3f}  F {:.5g} N  Hertz {:.5g} N  error {:+.2f} %  "
                   "({} steps, {:.1f} s{})\n",
                   o.spheres ? " spheres" : "", o.nu, n, m.n_elems, o.spheres ? "*" : "", ratio, p.force, p.hertz, 100 * p.error, r.steps,
                   r.wall,
                   o.spheres ? fmt::format(", balance {:.2g}, spread {:.2g}, residual {:.2g}", p.balance, p.spread,
                                           r.residual)
                             : std::string());
    }
    level.wall = seconds_since(t0);
    study.levels.push_back(level);
  }
  return study;
}

std::string hertz_table(const HertzStudy& s) {
  const HertzOptions& o = s.options;
  const double R_eff = effective_radius(o);
  const std::string what =
      o.spheres ? fmt::format("two elastic spheres, R = {} mm (E = {} Pa, nu = {}) on R = {} mm (E = {} Pa, nu = {}), "
                              "R* = {:.4g} mm",
                              1e3 * o.upper.R, o.upper.E, o.upper.nu, 1e3 * o.R, o.E, o.nu, 1e3 * R_eff)
                : fmt::format("rigid sphere R = {} mm into E = {} Pa, nu = {}", 1e3 * o.R, o.E, o.nu);
  std::string out = fmt::format("Hertz: {} (quarter blocks {:.1f} mm, uniform core {:.2f} mm, grading {}), on {}\n",
                                what, 1e3 * s.L, 1e3 * o.core * std::sqrt(R_eff * R_eff * o.ratios.back()), o.grading,
                                s.device);
  out += fmt::format("{:>6} {:>8} {:>9} {:>10}", "cells", "tets", "h (mm)", "wall (s)");
  for (double r : o.ratios) out += o.spheres ? fmt::format(" d/R*={:<5g}", r) : fmt::format("  d/R={:<5g}", r);
  out += fmt::format("  {:>9}\n", "max |err|");
  for (const HertzLevel& l : s.levels) {
    out += fmt::format("{:>6} {:>8} {:>9.3f} {:>10.1f}", l.cells, l.elems, 1e3 * l.h_contact, l.wall);
    for (const HertzPoint& p : l.points) out += fmt::format("  {:>+9.2f}%", 100 * p.error);
    out += fmt::format("  {:>8.2f}%\n", 100 * l.max_error);
  }
  out += "error: (F - F_Hertz) / F_Hertz at each indentation; h: mean element edge under the deepest contact\n";
  if (o.spheres) {
    double worst = 0, cycle = 0;
    for (const HertzLevel& l : s.levels)
      for (const HertzPoint& p : l.points) {
        worst = std::max(worst, p.balance);
        cycle = std::max(cycle, p.spread);
      }
    out += fmt::format("the lower base's reaction balances the upper face's to {:.2g} of it at worst", worst);
    out += cycle > 0 ? fmt::format("; where contact nodes kept cycling, the forces are means over {} steps, the upper face's within "
                                   "{:.2g} of it at worst\n",
                                   kCycleSteps, cycle)
                     : std::string("\n");
  }
  return out;
}

std::string hertz_json(const HertzStudy& s) {
  const HertzOptions& o = s.options;
  std::string out = fmt::format(
      "{{\"E\": {}, \"nu\": {}, \"R\": {}, \"L\": {}, \"grading\": {}, \"device\": \"{}\", ", o.E, o.nu, o.R, s.L,
      o.grading, s.device);
  if (o.spheres)
    out += fmt::format("\"upper\": {{\"E\": {}, \"nu\": {}, \"R\": {}}}, ", o.upper.E, o.upper.nu, o.upper.R);
  out += "\"levels\": [";
  for (std::size_t k = 0; k < s.levels.size(); ++k) {
    const HertzLevel& l = s.levels[k];
    out += fmt::format("{}\n  {{\"cells\": {}, \"nodes\": {}, \"tets\": {}, \"h_contact\": {}, \"wall_s\": {}, "
                       "\"max_error\": {}, \"points\": [",
                       k ? "," : "", l.cells, l.nodes, l.elems, l.h_contact, l.wall, l.max_error);
    for (std::size_t j = 0; j < l.points.size(); ++j) {
      const HertzPoint& p = l.points[j];
      out += fmt::format(
          "{}{{\"delta\": {}, \"force\": {}, \"hertz\": {}, \"error\": {}, \"contact_nodes\": {}, \"balance\": {}, "
          "\"spread\": {}}}",
          j ? ", " : "", p.delta, p.force, p.hertz, p.error, p.contact_nodes, p.balance, p.spread);
    }
    out += "]}";
  }
  out += "\n]}\n";
  return out;
}

}  // namespace tissue::accuracy
