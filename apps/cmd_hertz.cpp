// tissue hertz: the contact verification against Hertz's closed form
// (accuracy/hertz.hpp): a table on stdout and optional JSON (scripts/plot hertz draws it).
#include <fmt/format.h>


#include "accuracy/hertz.hpp"
#include "apps/commands.hpp"
#include "apps/options.hpp"
#include "io/atomic_file.hpp"

namespace tissue::app {
namespace {

struct HertzArgs {
  accuracy::HertzOptions options;
  std::vector<double> nus = {0.45, 0.49};
  std::string json;
  bool quick = false;
};

int run_hertz_command(HertzArgs& a) {
  if (a.quick) a.options.levels = {6, 8};
  std::string json = "[";
  std::vector<accuracy::HertzStudy> studies;
  for (std::size_t k = 0; k < a.nus.size(); ++k) {
    accuracy::HertzOptions o = a.options;
    o.nu = a.nus[k];
    studies.push_back(accuracy::run_hertz(o));
    fmt::print("{}\n", accuracy::hertz_table(studies.back()));
    json += (k ? ",\n" : "\n") + accuracy::hertz_json(studies.back());
  }
  json += "]\n";
  if (!a.json.empty()) {
    io::write_file_atomic(a.json, json);  // whole or not at all
    fmt::print("wrote {}\n", a.json);
  }
  return 0;
}

}  // namespace

void add_hertz_command(CLI::App& app, int& rc) {
  auto args = std::make_shared<HertzArgs>();
  auto* cmd = app.add_subcommand(
      "hertz", "Verify the tool contact against Hertz: a rigid sphere pressed into a block, refined under the tool");
  cmd->add_option("--nu", args->nus, "Poisson's ratios to run")->capture_default_str();
  cmd->add_option("--E", args->options.E, "Young's modulus (Pa)")->capture_default_str()->check(CLI::PositiveNumber);
  cmd->add_option("--radius", args->options.R, "sphere radius (m)")->capture_default_str()->check(CLI::PositiveNumber);
  cmd->add_option("--ratios", args->options.ratios, "indentations delta / R, ascending")->capture_default_str();
  cmd->add_option("--levels", args->options.levels, "cells per axis of each mesh, coarse to fine")->capture_default_str();
  cmd->add_option("--grading", args->options.grading, "aspect ratio of the graded cells beyond the core")->capture_default_str();
  cmd->add_option("--core", args->options.core, "uniform core edge / contact radius at the deepest press")
      ->capture_default_str()
      ->check(CLI::PositiveNumber);
  cmd->add_option("--block", args->options.block, "block edge L / contact radius at the deepest press")->capture_default_str()->check(CLI::PositiveNumber);
  cmd->add_option("--backend", args->options.backend, "cpu | cuda (relaxes in double)")->capture_default_str();
  cmd->add_option("--json", args->json, "write the studies as JSON (scripts/plot hertz draws them)")
      ->check(output_file());
  cmd->add_flag("--quick", args->quick, "two coarse meshes only (a smoke run)");
  cmd->callback([args, &rc] { rc = run_hertz_command(*args); });
}

}  // namespace tissue::app
