// Sub-command registration for the tissue command line. Each adds a CLI11
// sub-app whose callback runs the command and stores its exit code in rc.
#pragma once

#include <CLI/CLI.hpp>

#include <string>
#include <vector>

#include "scene/scene.hpp"
#include "scene/text.hpp"

namespace tissue::app {

void add_mesh_command(CLI::App& app, int& rc);
void add_run_command(CLI::App& app, int& rc);
void add_bench_command(CLI::App& app, int& rc);
void add_info_command(CLI::App& app, int& rc);
void add_view_command(CLI::App& app, int& rc);  ///< apps/view_forward.cpp: runs tissue-view
void add_reference_command(CLI::App& app, int& rc);  ///< apps/cmd_reference.cpp
void add_tradeoff_command(CLI::App& app, int& rc);   ///< apps/cmd_tradeoff.cpp
void add_locking_command(CLI::App& app, int& rc);    ///< apps/cmd_locking.cpp
void add_hertz_command(CLI::App& app, int& rc);      ///< apps/cmd_hertz.cpp
void add_converge_command(CLI::App& app, int& rc);   ///< apps/cmd_converge.cpp
void add_palpate_command(CLI::App& app, int& rc);    ///< apps/cmd_palpate.cpp
void add_cut_command(CLI::App& app, int& rc);        ///< apps/cmd_cut.cpp
void add_python_commands(CLI::App& app, int& rc);    ///< apps/python_forward.cpp: sweep and fit

/// What the command is doing now, in words ("reading the scene x.xml"):
/// main() names it when memory runs out (std::bad_alloc).
/// Parses argv into `app` (whose callbacks run the command and set rc) and
/// turns every failure into an exit code: CLI11's own for parse errors, 1
/// with "<program>: error: ..." on stderr for exceptions (out of memory
/// names the activity). main() of tissue and tissue-view.
int run_command_line(CLI::App& app, int argc, char** argv, const int& rc, const char* program);

/// "tissue 0.2.0 (commit 1a2b3c4)": the project version and the git commit
/// the build was configured from ("unknown" outside a git checkout, e.g. a
/// source archive). `tissue --version` and `tissue info` print it.
std::string version_line();

void set_activity(std::string what);
const std::string& activity();

/// Loads a scene file, or the built-in kidney for the name "@kidney".
scene::Scene load_scene_arg(const std::string& arg);
/// Refuses a scene with <load>s (file:line of the first) for a command that
/// cannot apply them.
void refuse_loads(const scene::Scene& s, const std::string& command);

/// JSON values as an array, one a line ("[\n  a,\n  b\n]").
std::string json_array(const std::vector<std::string>& values);
/// Writes a command's --json output whole or not at all and says so on
/// stdout ("wrote F"); nothing for an empty path (the option not given).
void write_json_output(const std::string& path, const std::string& text);

using scene::parse_depth;      // scene/text.hpp
using scene::parse_precision;  // scene/text.hpp

}  // namespace tissue::app
