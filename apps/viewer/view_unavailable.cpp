// tissue-view when the build found no windowing libraries: the program
// exists and says what to install (apps/viewer/CMakeLists.txt lists them).
#include <CLI/CLI.hpp>

#include <memory>
#include <stdexcept>
#include <string>

#include "apps/viewer/view_command.hpp"

namespace tissue::viewer {

void add_view_options(CLI::App& app, int& rc) {
  CLI::App* cmd = &app;
  cmd->description("Interactive viewer (not built here: run it to see what is missing)");
  auto scene = std::make_shared<std::string>();
  cmd->add_option("scene", *scene, "Scene XML file, or @kidney");
  cmd->allow_extras();
  cmd->callback([&rc] {
    rc = 1;
    throw std::runtime_error(std::string("`tissue view` was not built: missing ") + TISSUE_VIEWER_MISSING +
                             "; install them (scripts/setup.sh lists the Debian packages) and re-run cmake");
  });
}

}  // namespace tissue::viewer
