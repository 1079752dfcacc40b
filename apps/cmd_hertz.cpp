// tissue hertz: the contact verification against Hertz's closed form
// (accuracy/hertz.hpp): a table on stdout and optional JSON (scripts/plot hertz draws it).
#include <fmt/format.h>

#include <cmath>
#include <memory>

#include "accuracy/hertz.hpp"
#include "apps/commands.hpp"
#include "apps/options.hpp"
#include "io/tetgen_mesher.hpp"
#include "scene/text.hpp"

namespace tissue::app {
namespace {

/// Memory of one Hertz mesh per tet (bytes), counted from the arrays rather
/// than measured: the model in double (corners, shape gradients, volume,
/// moduli, incidence: about 250 bytes), its ModelInput, the backend's copy
/// and per-element force slots, with a margin. The mesh has 6 n^3 tets for
/// n cells per axis, so its memory grows as n^3.
constexpr double kHertzBytesPerTet = 1000;

/// The largest indentation ratio delta / R the closed form is checked at:
/// Hertz assumes the contact radius a = sqrt(R delta) small against R (a
/// small-strain, half-space limit); at delta / R = 0.2, a is already 0.45 R
/// and the Neo-Hookean answer leaves the closed form by more than the mesh
/// error the study measures. The study's own ratios reach 0.1.
constexpr double kMaxHertzRatio = 0.2;

/// --levels: a whole number of cells per axis in [2, 100000] whose mesh fits
/// in the memory available now; "" when `text` is one.
std::string hertz_level_error(const std::string& text) {
  if (std::string e = whole_number_error(text, 2, 100000); !e.empty()) return e + " (cells per axis)";
  const double n = double(*scene::parse_integer(text)), tets = 6 * n * n * n;
  const double need = tets * kHertzBytesPerTet, have = io::available_memory();
  if (need > have)
    return fmt::format("{} cells per axis make 6 x {}^3 = {:.3g} tets, which need about {:.3g} GB of memory ({:.0f} "
                       "bytes per tet in double); only {:.3g} GB are available: use at most {} cells per axis",
                       text, text, tets, need / 1e9, kHertzBytesPerTet, have / 1e9,
                       int(std::cbrt(have / kHertzBytesPerTet / 6)));
  return "";
}

/// --ratios: delta / R in (0, kMaxHertzRatio]; "" when `text` is one.
std::string hertz_ratio_error(const std::string& text) {
  if (std::string e = real_number_error(text, 0, 1e300, true); !e.empty()) return e;
  if (*scene::parse_real(text) > kMaxHertzRatio)
    return fmt::format("delta / R = {} is outside the range where Hertz's closed form holds, (0, {}]: it assumes "
                       "the contact radius sqrt(R delta) small against R (at {} it is already {:.2f} R)",
                       text, kMaxHertzRatio, kMaxHertzRatio, std::sqrt(kMaxHertzRatio));
  return "";
}

/// A length in contact radii at the deepest press within [lo, hi] (--core, --block); "" when `text` is one,
/// else the rule and `why`.
std::string radii_error(const std::string& text, const char* what, double lo, double hi, const char* why) {
  if (std::string e = real_number_error(text, 0, INFINITY, true, true); !e.empty()) return e;
  const double v = *scene::parse_real(text);
  if (v < lo || v > hi) return fmt::format("a {} of {} contact radii is outside [{}, {}]: {}", what, text, lo, hi, why);
  return "";
}

/// --core: the uniform core under the tool.
std::string hertz_core_error(const std::string& text) {
  return radii_error(text, "core", 0.25, 5,
                     "the core's uniform cells must hold the contact (below a quarter of its radius the contact falls "
                     "on the graded cells, which a core of 1e-9 makes degenerate), and a core much wider than the "
                     "contact spends its cells away from it");
}

/// --block: the block's edge.
std::string hertz_block_error(const std::string& text) {
  return radii_error(text, "block", 10, 1000,
                     "it stands for Hertz's half-space, so its base and sides must lie far from the contact (10 radii "
                     "at least), and beyond 1000 the graded cells stretch so far that the relaxation stalls");
}

struct HertzArgs {
  accuracy::HertzOptions options;
  std::vector<double> nus = {0.45, 0.49};
  std::string json;
  bool quick = false;
};

int run_hertz_command(HertzArgs& a) {
  if (a.quick) a.options.levels = {6, 8};
  std::vector<std::string> json;
  std::vector<accuracy::HertzStudy> studies;
  for (std::size_t k = 0; k < a.nus.size(); ++k) {
    accuracy::HertzOptions o = a.options;
    o.nu = a.nus[k];
    o.upper.nu = a.nus[k];  // two spheres: one Poisson's ratio for both
    studies.push_back(accuracy::run_hertz(o));
    fmt::print("{}\n", accuracy::hertz_table(studies.back()));
    json.push_back(accuracy::hertz_json(studies.back()));
  }
  write_json_output(a.json, json_array(json) + "\n");
  return 0;
}

}  // namespace

void add_hertz_command(CLI::App& app, int& rc) {
  auto args = std::make_shared<HertzArgs>();
  auto* cmd = app.add_subcommand(
      "hertz", "Verify the contact against Hertz: a rigid sphere pressed into a block, or (--spheres) two elastic "
                "spheres pressed together through the body contact, refined under the contact");
  cmd->add_option("--nu", args->nus, "Poisson's ratios to run")
      ->capture_default_str()
      ->check(real_number(-1, 0.5, true, true));  // 0.5 is incompressible: K would be infinite
  cmd->add_option("--E", args->options.E, "Young's modulus (Pa)")->capture_default_str()->check(positive_real());
  // a sphere from a micrometre to a metre: beyond, the block's coordinates leave any physical scale (and overflow)
  cmd->add_option("--radius", args->options.R, "sphere radius (m)")->capture_default_str()->check(real_number(1e-6, 1));
  cmd->add_option("--ratios", args->options.ratios, "indentations delta / R, ascending")
      ->capture_default_str()
      ->check(CLI::Validator([](std::string& t) { return hertz_ratio_error(t); },
                             fmt::format("delta / R in (0, {}]", kMaxHertzRatio)));
  cmd->add_option("--levels", args->options.levels, "cells per axis of each mesh, coarse to fine")
      ->capture_default_str()
      ->check(CLI::Validator([](std::string& t) { return hertz_level_error(t); }, "CELLS >= 2"));
  cmd->add_option("--grading", args->options.grading, "aspect ratio of the graded cells beyond the core")
      ->capture_default_str()
      ->check(real_number(1, 100));  // >= 1: cells that grow away from the core
  cmd->add_option("--core", args->options.core, "uniform core edge / contact radius at the deepest press")
      ->capture_default_str()
      ->check(CLI::Validator([](std::string& t) { return hertz_core_error(t); }, "[0.25, 5]"));
  cmd->add_option("--block", args->options.block, "block edge L / contact radius at the deepest press")
      ->capture_default_str()
      ->check(CLI::Validator([](std::string& t) { return hertz_block_error(t); }, "[10, 1000]"));
  auto* spheres = cmd->add_flag("--spheres", args->options.spheres,
                "two elastic spheres pressed together through the body contact (E and --radius the lower, "
                "--upper-E and --upper-radius the upper; ratios are delta / R*)");
  cmd->add_option("--upper-E", args->options.upper.E, "the upper sphere's Young's modulus (Pa), with --spheres")
      ->capture_default_str()
      ->check(positive_real())
      ->needs(spheres);
  cmd->add_option("--upper-radius", args->options.upper.R, "the upper sphere's radius (m), with --spheres")
      ->capture_default_str()
      ->check(real_number(1e-6, 1))
      ->needs(spheres);
  cmd->add_option("--backend", args->options.backend, "cpu | cuda (relaxes in double)")->capture_default_str();
  cmd->add_option("--json", args->json, "write the studies as JSON (scripts/plot hertz draws them)")
      ->check(output_file());
  cmd->add_flag("--quick", args->quick, "two coarse meshes only (a smoke run)");
  cmd->callback([args, &rc] { rc = run_hertz_command(*args); });
}

}  // namespace tissue::app
