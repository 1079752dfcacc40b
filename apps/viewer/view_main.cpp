// tissue-view: the viewer and the 1 kHz haptic loop on screen, or offscreen
// pictures (--screenshot). Its own program so that `tissue` links no GL,
// EGL, GLFW or X library and runs on a headless GPU server; `tissue view
// ARGS` runs `tissue-view ARGS` (apps/view_forward.cpp).
#include <CLI/CLI.hpp>

#include "apps/commands.hpp"
#include "apps/viewer/view_command.hpp"

int main(int argc, char** argv) {
  CLI::App app{"tissue-view (tissue view): interactive nonlinear soft-tissue deformation on screen"};
  int rc = 0;
  tissue::viewer::add_view_options(app, rc);
  return tissue::app::run_command_line(app, argc, argv, rc, "tissue view");
}
