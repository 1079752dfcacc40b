#include <fmt/format.h>

#include <cstdio>
#include <exception>
#include <new>
#include <stdexcept>

#include "apps/commands.hpp"
#include "io/atomic_file.hpp"
#include "io/kidney.hpp"
#include "io/surface_import.hpp"
#include "io/scene_xml.hpp"
#include "scene/validate.hpp"

namespace tissue::app {

namespace {
std::string g_activity = "starting";
}  // namespace

int run_command_line(CLI::App& app, int argc, char** argv, const int& rc, const char* program) {
  try {
    app.parse(argc, argv);
  } catch (const CLI::RequiredError& e) {
    // a first word that is no command: name it and the commands (CLI11 says only that one is required)
    if (argc > 1 && argv[1][0] != '-' && app.get_subcommands().empty()) {
      std::string names;
      for (const CLI::App* c : app.get_subcommands({})) names += (names.empty() ? "" : ", ") + c->get_name();
      std::fprintf(stderr, "%s: '%s' is not a command; the commands are %s (%s --help)\n", program, argv[1],
                   names.c_str(), program);
      return e.get_exit_code();
    }
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  } catch (const io::MeshInterrupted& e) {  // Ctrl-C while TetGen ran: the user's request, 128 + the signal
    std::fprintf(stderr, "%s: interrupted: %s\n", program, e.what());
    return 128 + e.signal;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr, "%s: error: out of memory while %s\n", program, activity().c_str());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s: error: %s\n", program, e.what());
    return 1;
  }
  return rc;
}

void set_activity(std::string what) {
  g_activity = std::move(what);
}

const std::string& activity() {
  return g_activity;
}

scene::Scene load_scene_arg(const std::string& arg) {
  set_activity(fmt::format("reading the scene {}", arg));
  if (auto builtin = io::builtin_scene(arg)) return *builtin;
  return io::read_scene(arg);
}

std::string json_array(const std::vector<std::string>& values) {
  std::string out = "[";
  for (std::size_t k = 0; k < values.size(); ++k) out += (k ? ",\n  " : "\n  ") + values[k];
  return out + "\n]";
}

void write_json_output(const std::string& path, const std::string& text) {
  if (path.empty()) return;
  io::write_file_atomic(path, text);
  fmt::print("wrote {}\n", path);
}

void refuse_loads(const scene::Scene& s, const std::string& command) {
  if (s.loads.empty()) return;
  throw std::runtime_error(fmt::format(
      "{}: <load>: `tissue {}` does not apply loads (its reference solution holds the tool, with no applied-load "
      "term); remove the scene's <load>s, or use `tissue run`",
      scene::location(s, s.loads.front().where.line), command));
}

}  // namespace tissue::app
