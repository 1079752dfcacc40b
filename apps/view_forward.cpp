// `tissue view ARGS`: runs `tissue-view ARGS`, the viewer's own program
// beside this one (apps/viewer/view_main.cpp). The viewer links GL, EGL,
// GLFW and X; `tissue` links none of them, so run, mesh, bench, reference,
// tradeoff and info start on a headless GPU server (tests/test_app.cpp,
// "NeedsNoDisplayLibrary").
#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include "apps/commands.hpp"

namespace tissue::app {

std::filesystem::path viewer_program() {
  std::error_code ec;
  const std::filesystem::path self = std::filesystem::read_symlink("/proc/self/exe", ec);
  return ec ? std::filesystem::path("tissue-view") : self.parent_path() / "tissue-view";
}

void add_view_command(CLI::App& app, int& rc) {
  auto* cmd = app.add_subcommand(
      "view", "Interactive viewer and offscreen pictures: runs tissue-view (`tissue view --help` lists its options)");
  cmd->prefix_command();
  cmd->set_help_flag();  // --help goes to tissue-view
  cmd->callback([cmd, &rc] {
    std::vector<std::string> args = cmd->remaining();
    const std::filesystem::path exe = viewer_program();
    if (::access(exe.c_str(), X_OK) != 0) {
      rc = 1;
      throw std::runtime_error(fmt::format(
          "`tissue view` runs the viewer program {}, which is not there ({}): it is built beside `tissue` by the "
          "project's build (the windowing libraries are listed by scripts/setup.sh); every other command works "
          "without it",
          exe.string(), std::strerror(errno)));
    }
    std::string name = "tissue-view";
    std::vector<char*> argv{name.data()};
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    std::fflush(stdout);
    ::execv(exe.c_str(), argv.data());
    rc = 1;
    throw std::runtime_error(fmt::format("`tissue view`: cannot start {}: {}", exe.string(), std::strerror(errno)));
  });
}

}  // namespace tissue::app
