// The viewer's command-line options (apps/viewer/view_command.cpp, or
// view_unavailable.cpp where the windowing libraries were not found).
#pragma once

#include <CLI/CLI.hpp>

namespace tissue::viewer {

/// Registers the viewer's options and its run on `app` (tissue-view's root
/// app; tests give it a sub-app). rc receives the exit code.
void add_view_options(CLI::App& app, int& rc);

}  // namespace tissue::viewer
