// A `tissue run` session: scene -> model -> backend -> Scheduler -> ticks,
// with progress, CSV/VTU output and a summary. Shared by run and bench.
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "core/backend.hpp"
#include "core/scheduler.hpp"
#include "scene/scene.hpp"

namespace tissue::app {

struct RunOptions {
  std::string scene;
  std::string backend, precision, depth;  ///< empty = the scene's setting
  long ticks = -1;                        ///< < 0: from --time or the path length
  double time = -1;                       ///< s
  std::string out_dir;
  int frames = 10;
  bool quiet = false;
};

/// What a finished run measured (the summary's numbers).
struct RunSummary {
  long ticks = 0, steps = 0;
  double sim_time = 0, wall_time = 0;  ///< s
  double max_disp = 0;                 ///< m, at the end
  struct Tool {
    std::string name;
    double peak_force = 0;             ///< N, largest |force on the tool| seen
    Vec3<double> final_force = {};     ///< N
    index_t contact_nodes = 0;         ///< at the end
  };
  std::vector<Tool> tools;             ///< per tool, scene order
  index_t region_nodes = 0, region_elems = 0;
  bool equilibrium = false;
};

/// Applies the command-line overrides to the scene's solver settings.
void apply_overrides(scene::Scene& s, const RunOptions& o);

/// Runs the session; prints progress and the summary. Returns the exit code.
int run_scene(const RunOptions& o);

}  // namespace tissue::app
