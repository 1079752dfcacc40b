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

}  // namespace

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
  const double a_max = std::sqrt(o.R * o.R * o.ratios.back());
  study.L = o.block * a_max;
  study.device = create_backend(o.backend, Precision::Double)->device_name();
  for (int n : o.levels) {
    const auto t0 = Clock::now();
    const ModelInput in = hertz_block(n, study.L, o.core * a_max, o.grading, o.E, o.nu);
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
    std::vector<double> u;
    for (double ratio : o.ratios) {
      const double delta = ratio * o.R;
      tool.held = {{0, 0, o.R - delta}, {0, 0, 1}};
      const RelaxResult r = relax(*backend, m, {}, ro, u, &tool);
      if (!r.converged)
        throw std::runtime_error(fmt::format(
            "hertz: {} cells, delta/R = {}: the relaxation stopped after {} steps at residual {:.3g}, kinetic {:.3g}: "
            "it {}",
            n, ratio, r.steps, r.residual, r.kinetic, r.why));
      u = backend->download().u;
      HertzPoint p;
      p.delta = delta;
      p.force = -4 * r.last.tools[0].reaction.z;
      p.hertz = hertz_force(o.E, o.nu, o.R, delta);
      p.error = (p.force - p.hertz) / p.hertz;
      p.contact_nodes = r.last.tools[0].contact;
      level.max_error = std::max(level.max_error, std::fabs(p.error));
      level.points.push_back(p);
      tool.start = tool.held;
      if (o.verbose)
        fmt::print(stderr, "  hertz nu {} {:3} cells ({} tets): delta/R {:.3f}  F {:.5g} N  Hertz {:.5g} N  error {:+.2f} %\n",
                   o.nu, n, m.n_elems, ratio, p.force, p.hertz, 100 * p.error);
    }
    level.wall = seconds_since(t0);
    study.levels.push_back(level);
  }
  return study;
}

std::string hertz_table(const HertzStudy& s) {
  const HertzOptions& o = s.options;
  std::string out = fmt::format(
      "Hertz: rigid sphere R = {} mm into E = {} Pa, nu = {} (quarter block {:.1f} mm, uniform core {:.2f} mm, grading {}), on {}\n", 1e3 * o.R,
      o.E, o.nu, 1e3 * s.L, 1e3 * o.core * std::sqrt(o.R * o.R * o.ratios.back()), o.grading, s.device);
  out += fmt::format("{:>6} {:>8} {:>9} {:>10}", "cells", "tets", "h (mm)", "wall (s)");
  for (double r : o.ratios) out += fmt::format("  d/R={:<5g}", r);
  out += fmt::format("  {:>9}\n", "max |err|");
  for (const HertzLevel& l : s.levels) {
    out += fmt::format("{:>6} {:>8} {:>9.3f} {:>10.1f}", l.cells, l.elems, 1e3 * l.h_contact, l.wall);
    for (const HertzPoint& p : l.points) out += fmt::format("  {:>+9.2f}%", 100 * p.error);
    out += fmt::format("  {:>8.2f}%\n", 100 * l.max_error);
  }
  out += "error: (F - F_Hertz) / F_Hertz at each indentation; h: mean element edge under the deepest contact\n";
  return out;
}

std::string hertz_json(const HertzStudy& s) {
  const HertzOptions& o = s.options;
  std::string out = fmt::format(
      "{{\"E\": {}, \"nu\": {}, \"R\": {}, \"L\": {}, \"grading\": {}, \"device\": \"{}\", \"levels\": [", o.E, o.nu,
      o.R, s.L, o.grading, s.device);
  for (std::size_t k = 0; k < s.levels.size(); ++k) {
    const HertzLevel& l = s.levels[k];
    out += fmt::format("{}\n  {{\"cells\": {}, \"nodes\": {}, \"tets\": {}, \"h_contact\": {}, \"wall_s\": {}, "
                       "\"max_error\": {}, \"points\": [",
                       k ? "," : "", l.cells, l.nodes, l.elems, l.h_contact, l.wall, l.max_error);
    for (std::size_t j = 0; j < l.points.size(); ++j) {
      const HertzPoint& p = l.points[j];
      out += fmt::format("{}{{\"delta\": {}, \"force\": {}, \"hertz\": {}, \"error\": {}, \"contact_nodes\": {}}}",
                         j ? ", " : "", p.delta, p.force, p.hertz, p.error, p.contact_nodes);
    }
    out += "]}";
  }
  out += "\n]}\n";
  return out;
}

}  // namespace tissue::accuracy
