// tissue tradeoff: the speed-accuracy sweep (accuracy/tradeoff.hpp) with a
// table on stdout, optional JSON and a PNG plot of error against cost.
#include <fmt/format.h>

#include <fstream>
#include <memory>

#include "accuracy/plot.hpp"
#include "accuracy/tradeoff.hpp"
#include "apps/commands.hpp"

namespace tissue::app {
namespace {

struct TradeoffArgs {
  std::string scene, json, plot, backend;
  accuracy::TradeoffOptions options;
  std::vector<std::string> depths;
  std::vector<int> meshes;
  bool quick = false;
};

int run_tradeoff_command(TradeoffArgs& a) {
  const scene::Scene s = load_scene_arg(a.scene);
  accuracy::TradeoffOptions& o = a.options;
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
  const accuracy::TradeoffResult res = accuracy::run_tradeoff(s, o);
  fmt::print("{}", accuracy::tradeoff_table(res));
  if (!a.json.empty()) {
    std::ofstream f(a.json);
    if (!f) throw std::runtime_error("cannot write " + a.json);
    f << accuracy::tradeoff_json(res);
    if (!f) throw std::runtime_error("write failed: " + a.json);
    fmt::print("wrote {}\n", a.json);
  }
  if (!a.plot.empty()) {
    accuracy::write_tradeoff_plot(res, a.plot);
    fmt::print("wrote {}\n", a.plot);
  }
  return 0;
}

}  // namespace

void add_tradeoff_command(CLI::App& app, int& rc) {
  auto* cmd = app.add_subcommand("tradeoff",
                                 "Sweep region depth, precision, dt safety, mass scaling, mesh size and equilibrium "
                                 "tolerance; "
                                 "measure cost and error against the reference solution");
  auto a = std::make_shared<TradeoffArgs>();
  cmd->add_option("scene", a->scene, "Scene XML file, or @kidney for the built-in kidney")->required();
  cmd->add_option("--json", a->json, "Write the results as JSON");
  cmd->add_option("--plot", a->plot, "Write a PNG plot of error against cost with the Pareto front");
  cmd->add_option("--backend", a->backend, "cpu | cuda (default: the scene's)");
  cmd->add_option("--depths", a->depths, "Fixed depths to sweep (numbers or 'all')")->delimiter(',');
  cmd->add_option("--meshes", a->meshes, "Target tet counts, ascending (0 = the scene's own mesh); default 3000,0,20000,25000")
      ->delimiter(',');
  cmd->add_option("--max-hold", a->options.max_hold, "Simulated seconds of hold before giving up on equilibrium");
  cmd->add_flag("--quick", a->quick, "Smoke run: the scene's mesh only and a handful of settings");
  cmd->callback([a, &rc] { rc = run_tradeoff_command(*a); });
}

}  // namespace tissue::app
