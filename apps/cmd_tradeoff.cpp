// tissue tradeoff: the speed-accuracy sweep (accuracy/tradeoff.hpp) with a
// table on stdout and optional JSON (scripts/plot tradeoff draws it).
#include <fmt/format.h>

#include <algorithm>
#include <memory>

#include "accuracy/tradeoff.hpp"
#include "apps/commands.hpp"
#include "apps/interrupt.hpp"
#include "apps/options.hpp"

namespace tissue::app {
namespace {

struct TradeoffArgs {
  std::string scene, json, backend;
  accuracy::TradeoffOptions options;
  std::vector<std::string> depths;
  std::vector<int> meshes;
  bool quick = false;
  bool max_hold_given = false;  ///< --max-hold was given (--quick sets its own)
};

int run_tradeoff_command(TradeoffArgs& a) {
  InterruptGuard interrupt;
  const scene::Scene s = load_scene_arg(a.scene);
  refuse_loads(s, "tradeoff");
  accuracy::TradeoffOptions& o = a.options;
  // a hold shorter than one haptic tick runs no tick: every row would be unconverged
  if (a.max_hold_given && o.max_hold < s.solver.tick)
    throw std::invalid_argument(fmt::format(
        "--max-hold {:g} s is shorter than one haptic tick of {} ({:g} s): the hold could not run a single tick "
        "and every row would be unconverged; give at least {:g} s",
        o.max_hold, s.source, s.solver.tick, s.solver.tick));
  o.backend = a.backend;
  if (!a.depths.empty()) {
    o.depths.clear();
    for (const std::string& d : a.depths) o.depths.push_back(parse_depth(d));
  }
  if (!a.meshes.empty()) {
    o.mesh_targets = a.meshes;
    o.mesh_names.clear();
    for (int t : a.meshes) o.mesh_names.push_back(t == 0 ? "default" : fmt::format("{}k", (t + 500) / 1000));
  }
  if (a.quick) {  // a smoke run: the scene's mesh only, a few settings
    o.mesh_targets = {0};
    o.mesh_names = {"default"};
    o.depths = {1, kDepthAll};
    o.auto_tols = {0.02};
    o.safeties = {0.5};
    o.mass_scalings = {0};
    o.residual_tols = {1e-2};
    o.max_hold = 0.3;
  }
  o.stop = [] { return InterruptGuard::requested(); };
  set_activity(fmt::format("sweeping the settings of {}", s.source));
  const accuracy::TradeoffResult res = accuracy::run_tradeoff(s, o);
  if (res.interrupted)
    fmt::print("stopped by {}: the rows below are the settings done before it\n", InterruptGuard::signal_name());
  fmt::print("{}", accuracy::tradeoff_table(res));
  if (!a.json.empty()) write_json_output(a.json, accuracy::tradeoff_json(res));
  return res.interrupted ? InterruptGuard::exit_code() : 0;
}

}  // namespace

void add_tradeoff_command(CLI::App& app, int& rc) {
  auto* cmd = app.add_subcommand("tradeoff",
                                 "Sweep region depth, precision, dt safety, mass scaling, mesh size and equilibrium "
                                 "tolerance; "
                                 "measure cost and error against the reference solution");
  auto a = std::make_shared<TradeoffArgs>();
  cmd->add_option("scene", a->scene, "Scene XML file, or @kidney for the built-in kidney")->required();
  cmd->add_option("--json", a->json, "Write the results as JSON (scripts/plot tradeoff draws error against cost)")
      ->check(output_file());
  cmd->add_option("--backend", a->backend, "cpu | cuda (default: the scene's)");
  cmd->add_option("--depths", a->depths, "Fixed depths to sweep (numbers or 'all')")->delimiter(',');
  cmd->add_option("--meshes", a->meshes, "Target tet counts, ascending (0 = the scene's own mesh); default 3000,0,20000,25000")
      ->delimiter(',')
      ->check(whole_number(0, 100'000'000));
  cmd->add_option("--max-hold", a->options.max_hold, "Simulated seconds of hold before giving up on equilibrium")
      ->check(real_number(0, 1e6, true))
      ->each([a](const std::string&) { a->max_hold_given = true; });
  cmd->add_flag("--quick", a->quick, "Smoke run: the scene's mesh only and a handful of settings");
  cmd->callback([a, &rc] { rc = run_tradeoff_command(*a); });
}

}  // namespace tissue::app
