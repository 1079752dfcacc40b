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
  long ticks = 0;                         ///< haptic ticks (>= 1); 0 = from `time` or the path length
  double time = 0;                        ///< simulated s (> 0); 0 = the tool path's length
  std::string out_dir;                    ///< empty = no files
  int frames = 10;                        ///< VTU frames over the run (0 = ticks.csv only)
  bool overwrite = false;                 ///< replace another run's outputs in out_dir
  bool force = false;                     ///< run work beyond scene::kMaxElementSteps
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
  long planned_ticks = 0;
  std::string stopped_by;              ///< "SIGINT" / "SIGTERM" when a signal ended the run early; "" = ran to the end
};

/// Applies the command-line overrides to the scene's solver settings.
void apply_overrides(scene::Scene& s, const RunOptions& o);

/// Haptic ticks a run takes: o.ticks, else o.time or the tool path's
/// duration (s) divided by the tick, at least 1.
long tick_count(const RunOptions& o, double path_duration, double tick);

/// "plan: N ticks x S TLED steps = .. steps on E elements = .. element
/// updates; about T on the <backend> backend (...)": what the run will cost,
/// printed before the backend is built.
std::string work_plan(const scene::Scene& s, const TissueModel<double>& model, long ticks);

/// Refuses (std::runtime_error naming the scene, the counts, what sets the
/// step and --force) unless `force`: a run of more than
/// scene::kMaxElementSteps element updates, and a run of a scene that needs
/// more than scene::kManyStepsPerTick steps per tick whose estimated time is
/// beyond scene::kMaxSecondsAtManySteps.
void check_work(const scene::Scene& s, const TissueModel<double>& model, long ticks, bool force);

/// Runs the session; prints warnings, progress and the summary. With
/// out_dir, writes ticks.csv, frame_NNNN.vtu and series.pvd into an
/// io::OutputFolder (locked; another run's outputs refused unless
/// overwrite). SIGINT / SIGTERM (apps/interrupt.hpp) stop it at the next
/// tick boundary: the last state is saved as a frame, the log closed, the
/// summary printed. Returns the exit code: 0, or 128 + the signal.
int run_scene(const RunOptions& o);

}  // namespace tissue::app
