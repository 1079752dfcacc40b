#include "accuracy/convergence.hpp"

#include <fmt/format.h>

#include <cmath>
#include <stdexcept>

#include "core/device.hpp"
#include "io/kidney.hpp"
#include "scene/validate.hpp"
#include "session/engine.hpp"

namespace tissue::accuracy {

std::vector<ConvergenceLevel> default_convergence_levels() {
  const int f0 = io::KidneyScene::frequency, n0 = io::KidneyScene::target_tets;
  return {{"default", 0, {}},
          {"focus 3/4", n0, {8, 0.75}},
          {"focus 1/2", n0, {2 * f0, 0.5}},
          {"focus 1/3", n0, {3 * f0, 1.0 / 3.0}},
          {"focus 1/4", n0, {4 * f0, 0.25}}};
}

Extrapolation richardson(const std::vector<double>& h, const std::vector<double>& f) {
  if (h.size() != f.size() || h.size() < 3)
    throw std::invalid_argument("richardson: needs three or more sizes and values, as many of each");
  const std::size_t n = h.size();
  const double h1 = h[n - 3], h2 = h[n - 2], h3 = h[n - 1], f1 = f[n - 3], f2 = f[n - 2], f3 = f[n - 1];
  if (!(h1 > h2 && h2 > h3 && h3 > 0)) throw std::invalid_argument("richardson: sizes must descend and be > 0");
  Extrapolation e;
  e.value = f3;
  const double d12 = f1 - f2, d23 = f2 - f3;
  if (!(d12 * d23 > 0)) return e;  // not monotone (or converged to rounding): no order
  const double q = d12 / d23;
  auto g = [&](double p) { return (std::pow(h1, p) - std::pow(h2, p)) / (std::pow(h2, p) - std::pow(h3, p)) - q; };
  double lo = 0.25, hi = 6.0;
  if (g(lo) * g(hi) > 0) return e;
  for (int it = 0; it < 200; ++it) {
    const double mid = 0.5 * (lo + hi);
    (g(lo) * g(mid) <= 0 ? hi : lo) = mid;
  }
  e.order = 0.5 * (lo + hi);
  // F* from the last two: f3 - C h3^p with C = (f2 - f3) / (h2^p - h3^p)
  e.value = f3 - d23 / (std::pow(h2, e.order) - std::pow(h3, e.order)) * std::pow(h3, e.order);
  e.monotone = true;
  return e;
}

SlopeJump largest_slope_jump(const PressCurve& c, double window, double from) {
  if (c.depth.size() != c.force.size()) throw std::invalid_argument("largest_slope_jump: as many depths as forces");
  if (!(window > 0)) throw std::invalid_argument("largest_slope_jump: the window must be > 0");
  SlopeJump out;
  const std::size_t n = c.depth.size();
  if (n < 5) return out;
  const double start = c.depth.front(), end = c.depth.back(), floor = from * std::fabs(c.force.back());
  // least-squares slope of the points [i, j)
  const auto slope = [&](std::size_t i, std::size_t j) {
    double sd = 0, sf = 0, sdd = 0, sdf = 0;
    const double m = double(j - i);
    for (std::size_t k = i; k < j; ++k) {
      sd += c.depth[k];
      sf += c.force[k];
      sdd += c.depth[k] * c.depth[k];
      sdf += c.depth[k] * c.force[k];
    }
    const double den = m * sdd - sd * sd;
    return den > 0 ? (m * sdf - sd * sf) / den : NAN;
  };
  std::size_t lo = 0, hi = 0;  // the windows: [lo, i] before, [i, hi) after
  for (std::size_t i = 0; i < n; ++i) {
    const double d = c.depth[i];
    if (d - window < start || d + window > end) continue;
    while (c.depth[lo] < d - window) ++lo;
    if (hi < i) hi = i;
    while (hi < n && c.depth[hi] <= d + window) ++hi;
    if (std::fabs(c.force[lo]) < floor || i - lo < 2 || hi - i < 3) continue;
    const double before = slope(lo, i + 1), after = slope(i, hi);
    if (!(std::fabs(before) > 0) || !std::isfinite(after)) continue;
    const double jump = (after - before) / std::fabs(before);
    if (std::isnan(out.depth) || std::fabs(jump) > std::fabs(out.jump)) out = {jump, d};
  }
  return out;
}

PressCurve slow_press(const scene::Scene& scene, const HeldTool& held, double speed,
                      std::shared_ptr<const TissueModel<double>> model) {
  if (!(speed > 0) || !std::isfinite(speed))
    throw std::runtime_error(fmt::format("slow press: the speed {} m/s must be finite and > 0", speed));
  scene::Scene s = scene;
  const Vec3<double> travel = held.held.tip - held.start.tip;
  const double length = norm(travel), T = length / speed;
  if (!(length > 0)) throw std::runtime_error(s.source + ": slow press: the held pose is the start pose");
  const Vec3<double> dir = (1.0 / length) * travel;
  s.tools.front().path = {{0.0, held.start.tip, false, held.start.axis}, {T, held.held.tip, false, held.held.axis}};
  Engine e = build_engine(s, std::nullopt, std::move(model));
  ScriptedDevice device(s.tools.front().path);
  PressCurve c;
  double touched = NAN;
  for (TickReport rep; rep.time < T - 1e-9;) {
    rep = e.scheduler->tick(device);
    if (rep.contact_nodes == 0 && std::isnan(touched)) continue;
    const double along = speed * rep.time;
    if (std::isnan(touched)) touched = along;
    c.depth.push_back(along - touched);
    c.force.push_back(-dot(rep.force, dir));
  }
  return c;
}

namespace {

/// Mean edge of the undeformed surface triangles whose centroid lies within
/// `within` of the held tool's axis line, on its side of the body (m).
double edge_near_axis(const TissueModel<double>& m, const HeldTool& tool, double within) {
  const Vec3<double> a = tool.held.tip, d = tool.held.axis;
  double sum = 0;
  int count = 0;
  auto X = [&](index_t i) { return Vec3<double>{m.X[i], m.X[m.n_nodes + i], m.X[2 * size_t(m.n_nodes) + i]}; };
  for (index_t t = 0; t < m.n_tris; ++t) {
    const Vec3<double> p[3] = {X(m.tris[t]), X(m.tris[m.n_tris + t]), X(m.tris[2 * size_t(m.n_tris) + t])};
    const Vec3<double> c = (1.0 / 3.0) * (p[0] + p[1] + p[2]);
    const double s = dot(c - a, d);
    if (s < -tool.shape.radius) continue;  // the far side of the organ
    if (norm(c - a - s * d) > within) continue;
    for (int k = 0; k < 3; ++k) sum += norm(p[k] - p[(k + 1) % 3]);
    count += 3;
  }
  return count > 0 ? sum / count : NAN;
}

}  // namespace

ConvergenceResult kidney_convergence(const scene::Scene& scene, const std::vector<ConvergenceLevel>& levels,
                                     const ReferenceOptions& options, void (*progress)(const ConvergenceRow&),
                                     double curve_speed) {
  if (scene.tools.empty() || scene.tools.front().path.empty())
    throw std::invalid_argument(scene.source + ": the convergence study needs a scripted tool to hold");
  ConvergenceResult out;
  std::vector<double> h, f;
  for (const ConvergenceLevel& level : levels) {
    ConvergenceRow row;
    row.name = level.name;
    try {
      const scene::Scene s = level.target_tets > 0 ? remesh_scene(scene, level.target_tets, level.surfacing) : scene;
      const auto built = std::make_shared<const TissueModel<double>>(scene::load_model(s));
      const TissueModel<double>& model = *built;
      row.nodes = model.n_nodes;
      row.tets = model.n_elems;
      const auto& path = s.tools.front().path;
      const ToolSetting setting = scene::scheduler_settings(s).tools.front();
      const HeldTool held = held_tool(model, setting, path, s.solver.tick, hold_start(path));
      row.edge_under_tool = edge_near_axis(model, held, 2 * setting.shape.radius);
      const ReferenceSolution ref = reference_solution(model, {}, options, &held);
      row.force = ref.tool_force;
      row.residual = ref.relax.residual;
      row.at_contact_floor = ref.relax.at_contact_floor;
      row.steps = ref.relax.steps;
      row.wall = ref.relax.wall;
      h.push_back(row.edge_under_tool);
      f.push_back(norm(row.force));
      if (curve_speed > 0) try {
          row.slope_jump = largest_slope_jump(slow_press(s, held, curve_speed, built), kCurveWindow);
        } catch (const std::exception& e) {
          row.curve_failed = e.what();
        }
    } catch (const std::exception& e) {
      row.failed = e.what();
    }
    out.rows.push_back(row);
    if (progress) progress(out.rows.back());
  }
  if (f.size() >= 3) {
    out.limit = richardson(h, f);
    for (ConvergenceRow& r : out.rows)
      if (r.failed.empty()) r.rel_err = norm(r.force) / out.limit.value - 1;
  }
  return out;
}

}  // namespace tissue::accuracy
