// tissue: the command line. Sub-commands live one per file (cmd_*.cpp); each
// registers its options on a CLI11 sub-app and returns an exit code.
#include <CLI/CLI.hpp>

#include "apps/commands.hpp"

int main(int argc, char** argv) {
  CLI::App app{"tissue: interactive nonlinear soft-tissue deformation (TLED, Neo-Hookean, IANP)"};
  // --version answers before the sub-command requirement is checked (CLI11
  // throws CallForVersion while parsing; run_command_line prints it, exit 0)
  app.set_version_flag("--version", tissue::app::version_line(), "Print the version and the git commit, and exit");
  app.require_subcommand(1);
  int rc = 0;
  tissue::app::add_mesh_command(app, rc);
  tissue::app::add_run_command(app, rc);
  tissue::app::add_bench_command(app, rc);
  tissue::app::add_info_command(app, rc);
  tissue::app::add_view_command(app, rc);
  tissue::app::add_reference_command(app, rc);
  tissue::app::add_tradeoff_command(app, rc);
  tissue::app::add_locking_command(app, rc);
  tissue::app::add_hertz_command(app, rc);
  tissue::app::add_converge_command(app, rc);
  tissue::app::add_palpate_command(app, rc);
  tissue::app::add_cut_command(app, rc);
  tissue::app::add_python_commands(app, rc);
  return tissue::app::run_command_line(app, argc, argv, rc, "tissue");
}
