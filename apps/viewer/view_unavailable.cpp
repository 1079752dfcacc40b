// `tissue view` when the build found no windowing libraries: the command
// exists and says what to install (apps/viewer/CMakeLists.txt lists them).
#include <CLI/CLI.hpp>

#include <memory>
#include <stdexcept>
#include <string>

#include "apps/commands.hpp"

namespace tissue::app {

void add_view_command(CLI::App& app, int& rc) {
  auto* cmd = app.add_subcommand("view", "Interactive viewer (not built: see `tissue view --help`)");
  auto scene = std::make_shared<std::string>();
  cmd->add_option("scene", *scene, "Scene XML file, or @kidney");
  cmd->allow_extras();
  cmd->callback([&rc] {
    rc = 1;
    throw std::runtime_error(std::string("`tissue view` was not built: missing ") + TISSUE_VIEWER_MISSING +
                             "; install them (scripts/setup.sh lists the Debian packages) and re-run cmake");
  });
}

}  // namespace tissue::app
