#include "apps/run_session.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>

#include "apps/commands.hpp"
#include "apps/interrupt.hpp"
#include "backends/registry.hpp"
#include "io/csv_log.hpp"
#include "io/output_dir.hpp"
#include "io/vtu_writer.hpp"
#include "scene/checks.hpp"
#include "scene/validate.hpp"
#include "session/engine.hpp"
#include "session/session.hpp"

namespace tissue::app {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

/// One scripted device per tool of the scene, in its order.
std::vector<ScriptedDevice> scripted_devices(const scene::Scene& s) {
  if (s.tools.empty()) throw std::runtime_error(s.source + ": the scene has no tool to drive");
  std::vector<ScriptedDevice> devices;
  for (const scene::Tool& tool : s.tools) {
    if (tool.device != "scripted")
      throw std::runtime_error(fmt::format("{}: tool '{}' uses the '{}' device; `tissue run` needs scripted tools "
                                           "(use `tissue view` for interactive devices)",
                                           s.source, tool.name, tool.device));
    devices.emplace_back(tool.path);  // read_scene has loaded a path file into `path`
  }
  return devices;
}

/// "off", or what selective mass scaling added and what it bought.
std::string mass_scaling_line(const TissueModel<double>& m) {
  if (m.scaled_elems == 0) return fmt::format("none (dt_crit without it: {:.4g} s)", m.dt_crit_physical);
  return fmt::format("+{:.3g} % mass on {} elements (density up to x{:.3g}); dt_crit {:.4g} -> {:.4g} s",
                     100 * m.added_mass / m.total_mass, m.scaled_elems, m.max_density_scale, m.dt_crit_physical,
                     m.dt_crit);
}

std::string tool_lines(const RunSummary& r) {
  std::string out;
  for (const RunSummary::Tool& t : r.tools)
    out += fmt::format(
        "  tool '{}'{}peak force {:.4g} N, final force ({:.4g}, {:.4g}, {:.4g}) N, {} nodes in contact at the end\n",
        t.name, std::string(t.name.size() < 10 ? 10 - t.name.size() : 1, ' '), t.peak_force, t.final_force.x,
        t.final_force.y, t.final_force.z, t.contact_nodes);
  return out;
}

void print_summary(const RunSummary& r, const Backend& b, const TissueModel<double>& m, int steps_per_tick) {
  fmt::print(
      "summary\n"
      "  backend            {} ({}, {})\n"
      "  mesh               {} nodes, {} tets, {} surface triangles\n"
      "  time step          dt = {:.4g} s (dt_crit = {:.4g} s, element {}), {} TLED steps per {:.3g} ms tick\n"
      "  mass scaling       {}\n"
      "  TLED steps         {}\n"
      "  haptic ticks       {}{}\n"
      "  simulated time     {:.4f} s\n"
      "  wall time          {:.3f} s ({:.2f}x real time)\n"
      "  steps/s            {:.0f}\n"
      "  max displacement   {:.4g} mm\n"
      "{}"
      "  region             {} nodes, {} elements\n"
      "  equilibrium        {}\n",
      b.name(), to_string(b.precision()), b.device_name(), m.n_nodes, m.n_elems, m.n_tris, m.dt, m.dt_crit,
      m.dt_crit_elem, steps_per_tick, 1e3 * m.dt * steps_per_tick, mass_scaling_line(m), r.steps, r.ticks,
      r.stopped_by.empty() ? std::string()
                           : fmt::format(" of {} (stopped by {} at a tick boundary)", r.planned_ticks, r.stopped_by),
      r.sim_time, r.wall_time, r.sim_time / std::max(r.wall_time, 1e-12), r.steps / std::max(r.wall_time, 1e-12),
      1e3 * r.max_disp, tool_lines(r), r.region_nodes, r.region_elems, r.equilibrium ? "reached" : "not reached");
}

/// "0.25 s", "3.2 min", "5.1 h": a duration for the plan line.
std::string duration_text(double seconds) {
  if (seconds < 120) return fmt::format("{:.2g} s", seconds);
  if (seconds < 7200) return fmt::format("{:.2g} min", seconds / 60);
  return fmt::format("{:.3g} h", seconds / 3600);
}

}  // namespace

void apply_overrides(scene::Scene& s, const RunOptions& o) {
  if (!o.backend.empty()) s.solver.backend = o.backend;
  if (!o.precision.empty()) s.solver.precision = parse_precision(o.precision);
  if (!o.depth.empty()) s.solver.depth = parse_depth(o.depth);
}

long tick_count(const RunOptions& o, double path_duration, double tick) {
  if (o.ticks > 0) return o.ticks;
  const double t = o.time > 0 ? o.time : path_duration;
  const double n = std::round(t / tick);
  if (!(n < 9e18)) throw std::runtime_error(fmt::format("{:.4g} s of {:.4g} s ticks is beyond counting", t, tick));
  return std::max(1L, static_cast<long>(n));
}

std::string work_plan(const scene::Scene& s, const TissueModel<double>& model, long ticks) {
  const scene::WorkEstimate w = scene::estimate_work(model, s.solver.tick, double(ticks), s.solver.backend);
  const scene::StepCost c = scene::nominal_step_cost(s.solver.backend);
  return fmt::format("plan: {} ticks x {:.0f} TLED steps = {:.4g} steps on {} elements = {:.3g} element updates; "
                     "about {} on the {} backend (at its nominal {:.2g} s a step + {:.2g} s an element update)",
                     ticks, w.steps_per_tick, w.steps, model.n_elems, w.element_steps, duration_text(w.seconds),
                     s.solver.backend, c.per_step, c.per_element);
}

void check_work(const scene::Scene& s, const TissueModel<double>& model, long ticks, bool force) {
  const scene::WorkEstimate w = scene::estimate_work(model, s.solver.tick, double(ticks), s.solver.backend);
  if (force) return;
  if (w.element_steps > scene::kMaxElementSteps)
    throw std::runtime_error(fmt::format(
        "{}: this run would take {} ticks x {:.0f} TLED steps x {} elements = {:.3g} element updates, beyond the "
        "{:.0e} a run may take without --force (hours even on a GPU; a laptop CPU does ~1e8 per second). The step: "
        "{}. Pass fewer --ticks or --time, fix the scene, or --force to run it anyway",
        s.source, ticks, w.steps_per_tick, model.n_elems, w.element_steps, scene::kMaxElementSteps,
        scene::step_cause(s, model)));
  if (w.steps_per_tick > scene::kManyStepsPerTick && w.seconds > scene::kMaxSecondsAtManySteps) {
    std::string also;
    for (const std::string& f : scene::incompressibility_findings(s)) also += "; " + f;
    throw std::runtime_error(fmt::format(
        "{}: {:.0f} TLED steps per {:.4g} s tick, more than the {:.0f} above which a scene is far from what was "
        "meant (typical scenes need 1..20): this run would take {} ticks x {:.0f} steps = {:.4g} steps x {} elements "
        "= {:.3g} element updates, about {} on the {} backend, beyond the {:.0f} s such a run may take without "
        "--force. The step: {}{}. Fix the material (its units: Pa, kg/m^3), pass fewer --ticks or --time, or --force "
        "to run it anyway",
        s.source, w.steps_per_tick, s.solver.tick, scene::kManyStepsPerTick, ticks, w.steps_per_tick, w.steps,
        model.n_elems, w.element_steps, duration_text(w.seconds), s.solver.backend, scene::kMaxSecondsAtManySteps,
        scene::step_cause(s, model), also));
  }
}

int run_scene(const RunOptions& o) {
  InterruptGuard interrupt;
  scene::Scene s = load_scene_arg(o.scene);
  apply_overrides(s, o);
  set_activity(fmt::format("building the model of {}", s.source));
  // validates the whole scene first
  const auto model_ptr = std::make_shared<const TissueModel<double>>(scene::load_model(s));
  const TissueModel<double>& model = *model_ptr;  // before any cut
  std::vector<ScriptedDevice> devices = scripted_devices(s);
  std::vector<Device*> device_ptrs;
  for (ScriptedDevice& d : devices) device_ptrs.push_back(&d);
  const SchedulerSettings settings = scene::scheduler_settings(s);
  double path_duration = 0;  // the longest tool path
  for (const ScriptedDevice& d : devices) path_duration = std::max(path_duration, d.duration());
  const long n_ticks = tick_count(o, path_duration, settings.tick);
  for (const std::string& w : scene::scene_warnings(s, model)) fmt::print(stderr, "warning: {}\n", w);
  fmt::print("{}\n", work_plan(s, model, n_ticks));  // before the backend is built and the ticks start
  if (!s.bodies.empty()) {
    std::string list;
    for (const scene::Body& b : s.bodies)
      list += fmt::format("{}'{}' ({} nodes, {} tets)", list.empty() ? "" : ", ", b.name, b.n_nodes, b.n_elements);
    fmt::print("bodies: {}\n", list);
  }
  std::fflush(stdout);
  check_work(s, model, n_ticks, o.force);

  std::optional<io::OutputFolder> folder;
  if (!o.out_dir.empty()) {
    folder.emplace(o.out_dir, std::vector<std::string>{"ticks.csv", "series.pvd", "frame_*.vtu"}, o.overwrite);
    if (folder->removed() > 0)
      fmt::print("--overwrite: removed {} files of the previous run from {}\n", folder->removed(), o.out_dir);
  }
  set_activity(fmt::format("uploading {} to the {} backend", s.source, s.solver.backend));
  // a scene with a blade runs as a Session, which makes the blade's cuts (docs/cutting.md): its mesh, model and
  // backend change between ticks; every other scene runs its engine alone
  Engine engine;
  std::unique_ptr<Session> session;
  if (has_blade(s)) {
    session = std::make_unique<Session>(std::make_shared<const scene::Scene>(s), model_ptr,
                                        create_backend(s.solver.backend, s.solver.precision));
    session->drive_with(device_ptrs);
  } else {
    engine = build_engine(s, settings, model_ptr);
  }
  Engine& live = session ? session->engine() : engine;  // a cut replaces its model and backend
  Scheduler& sched = *live.scheduler;

  fmt::print("running {} ticks of {} on {} ({}), region depth {}\n", n_ticks, s.source, live.backend->name(),
             to_string(live.backend->precision()), settings.depth == kDepthAll ? "all" : settings.depth == kDepthAuto ? "auto" : std::to_string(settings.depth));

  std::optional<io::TickLog> log;
  std::optional<io::VtuSeries> frames;
  long frame_every = 0, last_frame = 0;
  if (folder) {
    log.emplace(folder->file("ticks.csv"), sched.n_tools());
    if (o.frames > 0) {
      frames.emplace(folder->path(), s.bodies);
      frame_every = std::max(1L, n_ticks / o.frames);
    }
  }

  set_activity(fmt::format("running {}", s.source));
  RunSummary sum;
  for (const ToolSetting& t : settings.tools) sum.tools.push_back({t.shape.name});
  sum.planned_ticks = n_ticks;
  TickReport rep;
  const auto t0 = Clock::now();
  auto last_progress = t0;
  try {
    for (long k = 0; k < n_ticks && !InterruptGuard::requested(); ++k) {
      rep = session ? session->tick() : sched.tick(device_ptrs);
      for (std::size_t t = 0; t < sum.tools.size(); ++t)
        sum.tools[t].peak_force = std::max(sum.tools[t].peak_force, norm(rep.tools[t].force));
      for (const std::string& note : sched.take_notes()) fmt::print(stderr, "note: {}\n", note);
      if (log) log->write(rep);
      if (frames && ((k + 1) % frame_every == 0 || k + 1 == n_ticks)) {
        frames->write(*live.model, live.backend->download(), rep.time);  // a cut's mesh in each frame after it
        last_frame = k + 1;
      }
      if (!o.quiet && seconds_since(last_progress) > 1.0) {
        last_progress = Clock::now();
        const double wall = seconds_since(t0);
        fmt::print(stderr, "  tick {}/{}  t = {:.3f} s  {:.0f} steps/s  |f| = {:.4g} N  region {} nodes\n", k + 1,
                   n_ticks, rep.time, sched.total_steps() / wall, norm(rep.force), rep.region_nodes);
      }
    }
  } catch (const SimulationError& e) {
    if (session) throw;  // its stop names the likely causes already (Session::tick)
    throw SimulationError(e.what() + scene::stop_cause_text(s, model));  // the log keeps the ticks that ran
  }
  if (InterruptGuard::requested()) {
    sum.stopped_by = InterruptGuard::signal_name();
    if (frames && sched.ticks() > last_frame) frames->write(*live.model, live.backend->download(), rep.time);  // the last state
  }
  if (log) log->close();
  sum.wall_time = seconds_since(t0);
  sum.ticks = sched.ticks();
  sum.steps = sched.total_steps();
  sum.sim_time = sched.time();
  sum.max_disp = rep.max_disp;
  for (std::size_t t = 0; t < sum.tools.size(); ++t) {
    sum.tools[t].final_force = rep.tools[t].force;
    sum.tools[t].contact_nodes = rep.tools[t].contact_nodes;
  }
  sum.region_nodes = rep.region_nodes;
  sum.region_elems = rep.region_elems;
  sum.equilibrium = rep.equilibrium;
  print_summary(sum, *live.backend, *live.model, sched.steps_per_tick());
  if (session)
    fmt::print("cuts: {}, the mesh now {} nodes and {} elements (was {} and {})\n", session->cuts(), live.model->n_nodes,
               live.model->n_elems, model.n_nodes, model.n_elems);
  if (folder)
    fmt::print("wrote {} ({} rows){}\n", log->path(), log->rows(),
               frames ? fmt::format(" and {} ({} frames)", frames->pvd_path(), frames->frames()) : "");
  return sum.stopped_by.empty() ? 0 : InterruptGuard::exit_code();
}

}  // namespace tissue::app
