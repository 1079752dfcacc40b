// tissue run: drives a scene's scripted tool through the Scheduler on the
// chosen backend, logs every tick, and ends with a summary.
#include <fmt/format.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <memory>

#include "apps/commands.hpp"
#include "apps/options.hpp"
#include "apps/run_session.hpp"

namespace tissue::app {

void add_run_command(CLI::App& app, int& rc) {
  auto* cmd = app.add_subcommand("run", "Run a scene's scripted tool path and print a summary");
  auto opt = std::make_shared<RunOptions>();
  cmd->add_option("scene", opt->scene, "Scene XML file, or @kidney for the built-in kidney")->required();
  cmd->add_option("--backend", opt->backend, "cpu | cuda (default: the scene's)");
  cmd->add_option("--precision", opt->precision, "float | double (default: the scene's)");
  cmd->add_option("--depth", opt->depth, "Region depth N (rings from the contact triangle), 'all' or 'auto'");
  auto* ticks = cmd->add_option("--ticks", opt->ticks, "Haptic ticks to run (default: the tool path's length)")
                    ->check(whole_number(1, 1'000'000'000'000));
  cmd->add_option("--time", opt->time, "Simulated seconds to run")
      ->check(real_number(0, 1e9, true))
      ->excludes(ticks);
  cmd->add_option("--out", opt->out_dir, "Write ticks.csv and VTU frames (series.pvd) into this folder")
      ->check(output_folder());
  cmd->add_option("--frames", opt->frames, "VTU frames to save over the run (with --out; 0 = ticks.csv only)")
      ->default_val(10)
      ->check(whole_number(0, 1'000'000));
  cmd->add_flag("--overwrite", opt->overwrite, "Replace another run's outputs in the --out folder");
  cmd->add_flag("--force", opt->force, "Run even when the work estimate is beyond any usual run (1e12 element updates, or over 10 s of a scene that needs more than 100 steps per tick)");
  cmd->add_flag("--quiet", opt->quiet, "No progress lines");
  cmd->callback([opt, &rc] { rc = run_scene(*opt); });
}

}  // namespace tissue::app
