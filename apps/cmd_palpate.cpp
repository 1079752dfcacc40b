// tissue palpate: the palpation example (accuracy/palpation.hpp): a
// line scan of the tool over a block with a stiff spherical tumour, and the
// same scan without it; a table, optional JSON and a PNG.
#include <fmt/format.h>

#include <cmath>
#include <memory>

#include "accuracy/palpation.hpp"
#include "apps/commands.hpp"
#include "apps/options.hpp"

namespace tissue::app {
namespace {

struct PalpateArgs {
  accuracy::PalpationOptions o;
  std::string json;
};

int run_palpate(const PalpateArgs& a) {
  const accuracy::PalpationScan s = accuracy::run_palpation(a.o);
  fmt::print("palpation: {:g} mm press of a {:g} mm sphere across {:g} mm; tumour r = {:g} mm, centre {:g} mm deep, "
             "E x {:g}; {} tets ({} in the tumour), {} nodes\n",
             1e3 * a.o.press, 1e3 * a.o.tool_radius, 1e3 * a.o.scan, 1e3 * a.o.tumour_radius, 1e3 * a.o.tumour_depth,
             a.o.stiffness_ratio, s.tets, s.tumour_tets, s.nodes);
  fmt::print("   x (mm)   |F_z| tumour (N)   tumour as tissue (N)   ratio\n");
  std::vector<std::string> rows;
  for (std::size_t k = 0; k < s.with.size(); ++k) {
    const double fw = std::fabs(s.with[k].force.z), fo = std::fabs(s.without[k].force.z);
    fmt::print("  {:7.2f}   {:16.5g}   {:20.5g}   {:5.3f}\n", 1e3 * s.with[k].x, fw, fo, fw / fo);
    rows.push_back(fmt::format("{{\"x\": {}, \"force_tumour\": {}, \"force_baseline\": {}}}", s.with[k].x, fw, fo));
  }
  write_json_output(a.json, fmt::format("{{\"press\": {}, \"tool_radius\": {}, \"tumour_radius\": {}, \"tumour_depth\": {}, "
                                        "\"stiffness_ratio\": {}, \"E\": {}, \"nu\": {}, \"tets\": {}, \"points\": {}}}\n",
                                        a.o.press, a.o.tool_radius, a.o.tumour_radius, a.o.tumour_depth,
                                        a.o.stiffness_ratio, a.o.E, a.o.nu, s.tets, json_array(rows)));
  return 0;
}

}  // namespace

void add_palpate_command(CLI::App& app, int& rc) {
  auto a = std::make_shared<PalpateArgs>();
  auto* cmd = app.add_subcommand("palpate", "Palpation example: a line scan over a block with a stiff tumour");
  cmd->add_option("--ratio", a->o.stiffness_ratio, "tumour E / tissue E")->capture_default_str()
      ->check(positive_real());
  cmd->add_option("--press", a->o.press, "press depth (m)")->capture_default_str()->check(positive_real());
  cmd->add_option("--positions", a->o.positions, "scan points")->capture_default_str()->check(CLI::Range(2, 200));
  cmd->add_option("--target-tets", a->o.target_tets, "mesh size")->capture_default_str()->check(CLI::Range(500, 2000000));
  cmd->add_option("--depth", a->o.tumour_depth, "tumour centre below the top (m)")->capture_default_str()
      ->check(positive_real());
  cmd->add_option("--tumour-radius", a->o.tumour_radius, "m")->capture_default_str()->check(positive_real());
  cmd->add_option("--tool-radius", a->o.tool_radius, "the probe's sphere (m)")->capture_default_str()
      ->check(positive_real());
  cmd->add_option("--backend", a->o.backend, "cpu | cuda (relaxes in double)")->capture_default_str()
      ->check(CLI::IsMember({"cpu", "cuda"}));
  cmd->add_option("--json", a->json, "write the profile as JSON (scripts/plot palpate draws it)")->check(output_file());
  cmd->callback([a, &rc] { rc = run_palpate(*a); });
}

}  // namespace tissue::app
