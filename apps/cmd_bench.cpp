// tissue bench: JSON rows of throughput and latency (bench/bench.hpp).
#include <fmt/format.h>

#include <memory>

#include "apps/commands.hpp"
#include "apps/interrupt.hpp"
#include "apps/options.hpp"
#include "bench/bench.hpp"
#include "io/kidney.hpp"

namespace tissue::app {

void add_bench_command(CLI::App& app, int& rc) {
  auto* cmd = app.add_subcommand("bench", "Measure TLED steps/s, contact-step latency and haptic tick time (JSON rows)");
  auto o = std::make_shared<bench::BenchOptions>();
  auto precision = std::make_shared<std::string>("both");
  cmd->add_option("--backend", o->backend, "cpu | cuda")->default_val("cpu");
  cmd->add_option("--precision", *precision, "float | double | both")->default_val("both");
  cmd->add_option("--json", o->json_path, "Also write the rows as a JSON array to this file")->check(output_file());
  CLI::Option* sizes = cmd->add_option("--sizes", o->sizes, "Whole-mesh TLED meshes: kidney 100k 1m 4m")->delimiter(',');
  CLI::Option* laws = cmd->add_option("--laws", o->laws, "Material laws of the whole-mesh and haptic-tick rows: neo-hookean visco fibre fibre-visco")
      ->delimiter(',')
      ->check(CLI::IsMember({"neo-hookean", "visco", "fibre", "fibre-visco"}));
  cmd->add_option("--min-seconds", o->min_seconds, "Time each measurement at least this long")
      ->default_val(0.5)
      ->check(real_number(0, 3600, true));
  CLI::Option* safety = cmd->add_option("--tick-dt-safety", o->tick_dt_safety,
                  "dt-safety values of the haptic-tick rows, compared in one run (default: the kidney scene's)")
      ->delimiter(',')
      ->check(real_number(0, 1, true, true));
  CLI::Option* scenes = cmd->add_option("--scene", o->scenes,
                  "Scene files (or built-in scenes: @kidney-fat) whose haptic-tick rows run beside the kidney's, "
                  "each pressed along its first tool's scripted path; a scene of bodies in contact also gives "
                  "the contact's cost per step")
      ->delimiter(',')
      ->check(CLI::Validator(
          [](std::string& v) { return io::is_builtin_scene(v) ? std::string() : CLI::ExistingFile(v); },
          "FILE|@SCENE"));
  CLI::Option* batch = cmd->add_option("--batch", o->batch,
                  "Batch sizes: step that many kidneys together, every tool moving in contact (only the batch rows "
                  "run; docs/batch.md)")
      ->delimiter(',')
      ->check(whole_number(1, 1'000'000));
  CLI::Option* friction = cmd->add_option("--friction", o->friction,
                  "Friction coefficients of the contact-step and haptic-tick rows' tools, a set of rows each "
                  "(default: frictionless contact steps, the scenes' own tools)")
      ->delimiter(',')
      ->check(real_number(0, 1e6));
  cmd->add_flag("--quick", o->quick, "Smoke run on tiny meshes (CI)");
  cmd->add_flag("--cut", o->cut,
                "Only the live-cut rows: the pressed kidney cut across between ticks, each cut timed, then the "
                "haptic tick of the cut kidney")
      ->excludes(batch)
      ->excludes(friction)
      ->excludes(sizes)
      ->excludes(laws)
      ->excludes(safety)
      ->excludes(scenes);
  cmd->callback([o, precision, &rc] {
    InterruptGuard interrupt;
    if (*precision != "both") o->precisions = {parse_precision(*precision)};
    o->stop = [] { return InterruptGuard::requested(); };
    set_activity("benchmarking");
    const std::vector<std::string> rows = bench::run_bench(*o);
    if (InterruptGuard::requested())
      fmt::print(stderr, "stopped by {} after {} rows{}\n", InterruptGuard::signal_name(), rows.size(),
                 o->json_path.empty() ? "" : " (all written to " + o->json_path + ")");
    rc = InterruptGuard::requested() ? InterruptGuard::exit_code() : 0;
  });
}

}  // namespace tissue::app
