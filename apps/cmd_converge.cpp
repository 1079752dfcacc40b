// tissue converge: the mesh convergence of the tool force on the built-in
// kidney (accuracy/convergence.hpp): the probe held at its indentation on
// meshes refined under it, the force's extrapolated limit, and each mesh's
// distance from it; optionally uniform re-meshes as comparison rows.
#include <fmt/format.h>

#include <cmath>
#include <limits>
#include <memory>

#include "accuracy/convergence.hpp"
#include "apps/commands.hpp"
#include "apps/options.hpp"
#include "scene/text.hpp"

namespace tissue::app {
namespace {

struct ConvergeArgs {
  std::string scene = "@kidney", backend = "cpu", json;
  double tol = 1e-7;
  double curve_speed = accuracy::kCurveSpeed;
  int levels = 5;
  std::vector<int> uniform;
};

void print_row(const accuracy::ConvergenceRow& r) {
  if (!r.failed.empty()) {
    fmt::print("  {:<10} failed: {}\n", r.name, r.failed);
    return;
  }
  fmt::print("  {:<10} {:>7} nodes {:>7} tets  edge under the tool {:5.2f} mm  |F| = {:.5f} N  residual {:.2g}{}  "
             "{} steps {:.1f} s\n",
             r.name, r.nodes, r.tets, 1e3 * r.edge_under_tool, norm(r.force), r.residual,
             r.at_contact_floor ? " (contact floor)" : "", r.steps, r.wall);
  if (!r.curve_failed.empty())
    fmt::print("  {:<10} slow press failed: {}\n", r.name, r.curve_failed);
  else if (!std::isnan(r.slope_jump.depth))
    fmt::print("  {:<10} slow press: largest slope jump {:+.1f} % at {:.2f} mm\n", r.name, 100 * r.slope_jump.jump,
               1e3 * r.slope_jump.depth);
}

std::string row_json(const accuracy::ConvergenceRow& r, bool in_limit) {
  const bool curve = !std::isnan(r.slope_jump.depth);
  return fmt::format(
      "{{\"mesh\": \"{}\", \"nodes\": {}, \"tets\": {}, \"edge_under_tool\": {}, \"force\": [{}, {}, {}], "
      "\"force_norm\": {}, \"rel_err\": {}, \"residual\": {}, \"steps\": {}, \"wall_s\": {}, \"in_limit\": {}, "
      "\"failed\": \"{}\", \"slope_jump\": {}, \"slope_jump_depth\": {}, \"curve_failed\": \"{}\"}}",
      r.name, r.nodes, r.tets, r.edge_under_tool, r.force.x, r.force.y, r.force.z, norm(r.force), r.rel_err,
      r.residual, r.steps, r.wall, in_limit, r.failed, curve ? fmt::format("{}", r.slope_jump.jump) : "null",
      curve ? fmt::format("{}", r.slope_jump.depth) : "null", r.curve_failed);
}

/// The smallest --tol: the relaxation runs in double, and a node's force is
/// a sum of tens of element forces of opposite signs, each rounded to
/// epsilon = 2.2e-16 of its size, so the free nodes' relative residual
/// stalls at a few thousand epsilons; a tolerance below 1e-12 is never
/// reached and the study would run until its time limit.
constexpr double kMinResidualTol = 1e-12;

/// --tol in [kMinResidualTol, 1); "" when `text` is one.
std::string residual_tol_error(const std::string& text) {
  if (std::string e = real_number_error(text, 0, 1, true, true); !e.empty()) return e;
  if (*scene::parse_real(text) < kMinResidualTol)
    return fmt::format("{} is below what double precision resolves: the relative residual of the forces stalls at "
                       "rounding noise above {:g}; give a tolerance in [{:g}, 1)",
                       text, kMinResidualTol, kMinResidualTol);
  return "";
}

int run_converge(const ConvergeArgs& a) {
  const scene::Scene s = load_scene_arg(a.scene);
  refuse_loads(s, "converge");
  if (s.source != "@kidney") throw std::runtime_error(s.source + ": tissue converge refines the built-in @kidney only");
  std::vector<accuracy::ConvergenceLevel> levels = accuracy::default_convergence_levels();
  if (a.levels < 3 || a.levels > static_cast<int>(levels.size()))
    throw std::runtime_error(fmt::format("--levels {} must be in 3..{}", a.levels, levels.size()));
  levels.resize(a.levels);
  accuracy::ReferenceOptions o;
  o.backend = a.backend;
  o.relax.residual_tol = a.tol;
  fmt::print("tool force at the held indentation, meshes refined under the tool ({} backend, residual {:.1g}):\n",
             a.backend, a.tol);
  if (a.curve_speed > 0)
    fmt::print("and each mesh pressed at {:g} mm/s with the scene's own solver, its force-depth curve's largest "
               "change of slope over {:g} mm either side\n",
               1e3 * a.curve_speed, 1e3 * accuracy::kCurveWindow);
  const accuracy::ConvergenceResult res = accuracy::kidney_convergence(s, levels, o, print_row, a.curve_speed);
  const accuracy::Extrapolation& lim = res.limit;
  fmt::print("extrapolated |F| = {:.5f} N ({}, order {:.2f} in the edge under the tool)\n", lim.value,
             lim.monotone ? "Richardson over the last three" : "not monotone: the finest value", lim.order);
  for (const auto& r : res.rows)
    if (r.failed.empty()) fmt::print("  {:<10} {:+6.2f} % from the limit\n", r.name, 100 * r.rel_err);
  std::vector<accuracy::ConvergenceRow> uniform;
  if (!a.uniform.empty()) {
    fmt::print("uniform re-meshes (surface and volume refined together), against that limit:\n");
    std::vector<accuracy::ConvergenceLevel> u;
    for (int n : a.uniform) u.push_back({fmt::format("uniform {}", n), n, {}});
    // (one level at a time: the study's extrapolation needs three; these rows only compare)
    for (const auto& level : u) {
      accuracy::ConvergenceResult one = accuracy::kidney_convergence(s, {level}, o, nullptr, a.curve_speed);
      accuracy::ConvergenceRow r = one.rows.front();
      if (r.failed.empty()) r.rel_err = norm(r.force) / lim.value - 1;
      print_row(r);
      if (r.failed.empty()) fmt::print("  {:<10} {:+6.2f} % from the limit\n", r.name, 100 * r.rel_err);
      uniform.push_back(r);
    }
  }
  if (!a.json.empty()) {
    std::vector<std::string> rows;
    for (const auto& r : res.rows) rows.push_back(row_json(r, true));
    for (const auto& r : uniform) rows.push_back(row_json(r, false));
    write_json_output(a.json, fmt::format("{{\"backend\": \"{}\", \"residual_tol\": {}, \"limit\": {}, \"order\": {}, "
                                          "\"monotone\": {}, \"rows\": {}}}\n",
                                          a.backend, a.tol, lim.value, lim.order, lim.monotone, json_array(rows)));
  }
  return 0;
}

}  // namespace

void add_converge_command(CLI::App& app, int& rc) {
  auto a = std::make_shared<ConvergeArgs>();
  auto* cmd = app.add_subcommand(
      "converge", "Mesh convergence of the tool force on the built-in kidney: meshes refined under the probe, "
                  "Richardson limit");
  cmd->add_option("scene", a->scene, "scene (the built-in @kidney)")->capture_default_str();
  cmd->add_option("--backend", a->backend, "cpu | cuda (relaxes in double)")->capture_default_str();
  cmd->add_option("--tol", a->tol, "relative residual to reach")->capture_default_str()->check(
      CLI::Validator([](std::string& t) { return residual_tol_error(t); }, fmt::format("REAL in [{:g}, 1)", kMinResidualTol)));
  cmd->add_option("--levels", a->levels, "how many of the family's meshes (3..5; docs/contact.md)")
      ->capture_default_str();
  cmd->add_option("--uniform", a->uniform, "also these uniform re-mesh tet counts, as comparison rows")
      ->check(whole_number(100, std::numeric_limits<int>::max()));  // fewer than 100 tets keep no kidney shape
  cmd->add_option("--curve-speed", a->curve_speed,
                  "also press each mesh at this speed (m/s) for its force-depth curve's largest slope jump; 0 = not")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 0.1));  // faster than 10 cm/s is no longer quasi-static on the kidney
  cmd->add_option("--json", a->json, "write the rows as JSON")->check(output_file());
  cmd->callback([a, &rc] { rc = run_converge(*a); });
}

}  // namespace tissue::app
