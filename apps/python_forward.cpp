// `tissue sweep ARGS` and `tissue fit ARGS`: run `python3 -m tissue.cli
// sweep|fit ARGS` (python/tissue/cli.py), the Python package's command line
// over Dask and SciPy. The interpreter is the one the package was built for;
// the package is looked for in the build folder, then where `cmake
// --install` puts it, then on the interpreter's own path (PYTHONPATH, a
// .pth file).
#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <unistd.h>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include "apps/commands.hpp"

#ifndef TISSUE_PYTHON
#define TISSUE_PYTHON ""
#endif
#ifndef TISSUE_PYTHON_DIRS
#define TISSUE_PYTHON_DIRS ""
#endif

namespace tissue::app {

namespace {

/// The folders holding tissue/cli.py that this build knows of (build, then install; ':' between).
std::vector<std::string> package_dirs() {
  std::vector<std::string> out;
  const std::string dirs = TISSUE_PYTHON_DIRS;
  std::size_t start = 0;
  while (start <= dirs.size()) {
    const std::size_t end = std::min(dirs.find(':', start), dirs.size());
    const std::string d = dirs.substr(start, end - start);
    if (!d.empty() && std::filesystem::exists(std::filesystem::path(d) / "tissue" / "cli.py")) out.push_back(d);
    start = end + 1;
  }
  return out;
}

void forward(const std::string& command, const std::vector<std::string>& args) {
  const char* env = std::getenv("TISSUE_PYTHON");
  const std::string python = env && *env ? env : TISSUE_PYTHON;
  if (python.empty())
    throw std::runtime_error(fmt::format(
        "`tissue {}` runs in the Python package, which this build does not have: it is built when pybind11-dev, "
        "python3-dev and python3-numpy are installed (scripts/setup.sh lists them)",
        command));
  std::vector<std::string> dirs = package_dirs();
  if (!dirs.empty()) {
    const char* old = std::getenv("PYTHONPATH");
    std::string path = dirs.front();
    if (old && *old) path += std::string(":") + old;
    ::setenv("PYTHONPATH", path.c_str(), 1);
  }
  std::vector<std::string> all = {python, "-m", "tissue.cli", command};
  all.insert(all.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& a : all) argv.push_back(a.data());
  argv.push_back(nullptr);
  std::fflush(stdout);
  ::execv(python.c_str(), argv.data());
  throw std::runtime_error(fmt::format("`tissue {}`: cannot start {}: {}", command, python, std::strerror(errno)));
}

void add_forward(CLI::App& app, int& rc, const std::string& name, const std::string& what) {
  auto* cmd = app.add_subcommand(name, what);
  cmd->prefix_command();
  cmd->set_help_flag();  // --help goes to the Python command
  cmd->callback([cmd, &rc, name] {
    rc = 1;
    forward(name, cmd->remaining());
  });
}

}  // namespace

void add_python_commands(CLI::App& app, int& rc) {
  add_forward(app, rc, "sweep",
              "Run a scene over a grid of parameters on this machine or a Dask cluster (Python; `tissue sweep "
              "--help`)");
  add_forward(app, rc, "fit",
              "Estimate material parameters from a measured force curve (Python, SciPy; `tissue fit --help`)");
}

}  // namespace tissue::app
