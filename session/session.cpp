#include "session/session.hpp"

#include <fmt/format.h>

#include <cmath>
#include <stdexcept>

#include "backends/registry.hpp"
#include "scene/checks.hpp"
#include "scene/cut_scene.hpp"
#include "scene/validate.hpp"

namespace tissue {

ToolInput HostDevice::read(double t) {
  if (!host_) {
    ToolInput in = script_.read(t);
    in.grasp = in.grasp || grasp_;
    return in;
  }
  return {tip_, axis_, grasp_};
}

Session::Session(scene::Scene scene)
    : Session(std::make_shared<const scene::Scene>(scene),
              std::make_shared<const TissueModel<double>>(scene::load_model(scene)),
              create_backend(scene.solver.backend, scene.solver.precision)) {}

Session::Session(std::shared_ptr<const scene::Scene> scene, std::shared_ptr<const TissueModel<double>> model,
                 std::unique_ptr<Backend> backend)
    : scene_(std::move(scene)), engine_{std::move(model), std::move(backend), nullptr} {
  if (scene_->tools.empty()) throw std::runtime_error(scene_->source + ": the scene has no tool to drive");
  settings_ = scene::scheduler_settings(*scene_);
  box_ = scene::mesh_box(scene_->nodes);
  for (const scene::Tool& t : scene_->tools) devices_.emplace_back(t.path);
  for (HostDevice& d : devices_) device_ptrs_.push_back(&d);
  restart();
}

void Session::restart() {
  if (uncut_scene_) {
    scene_ = std::move(uncut_scene_);
    engine_.model = std::move(uncut_model_);
    box_ = scene::mesh_box(scene_->nodes);
  }
  start_engine(engine_, *scene_, settings_, loads_ ? &*loads_ : nullptr);
  last_ = TickReport{};
  last_.n_tools = n_tools();
  fields_.reset();
  failure_.clear();
}

void Session::check_tool(int tool) const {
  if (tool < 0 || tool >= n_tools())
    throw std::invalid_argument(fmt::format("{}: tool {} does not exist (the scene has {} tool{}: 0..{})", name(), tool,
                                            n_tools(), n_tools() == 1 ? "" : "s", n_tools() - 1));
}

void Session::set_tool_friction(int tool, double friction) {
  check_tool(tool);
  if (const std::string e = tool_friction_error(scene().tools[std::size_t(tool)].name, friction); !e.empty())
    throw std::invalid_argument(fmt::format("{}: set_tool_friction: {}", name(), e));
  scheduler().set_tool_friction(tool, friction);
  settings_.tools[std::size_t(tool)].shape.friction = friction;  // kept by restart()
}

double Session::tool_friction(int tool) const {
  check_tool(tool);
  return settings_.tools[std::size_t(tool)].shape.friction;
}

void Session::set_tool_pose(int tool, Vec3<double> tip, Vec3<double> axis) {
  check_tool_pose(tool, tip, axis);
  device(tool).set_pose(tip, axis);
}

void Session::check_tool_pose(int tool, Vec3<double> tip, Vec3<double> axis) const {
  check_tool(tool);
  const bool finite = std::isfinite(tip.x) && std::isfinite(tip.y) && std::isfinite(tip.z) && std::isfinite(axis.x) &&
                      std::isfinite(axis.y) && std::isfinite(axis.z);
  if (!finite)
    throw std::invalid_argument(fmt::format("{}: tool {} pose tip ({}, {}, {}) m axis ({}, {}, {}) is not finite", name(),
                                            tool, tip.x, tip.y, tip.z, axis.x, axis.y, axis.z));
  // the scene rule for waypoints: a tip this far away is a unit or typing mistake and overflows the float
  // collision query
  const double d = box_.distance(tip), reach = scene::kToolReach * box_.size;
  if (d > reach)
    throw std::invalid_argument(fmt::format(
        "{}: tool {} ('{}') tip ({}, {}, {}) m is {:.3g} m from the mesh, more than {:.0f} x its size ({:.3g} m) = "
        "{:.3g} m; coordinates are metres",
        name(), tool, scene_->tools[std::size_t(tool)].name, tip.x, tip.y, tip.z, d, scene::kToolReach, box_.size,
        reach));
}

void Session::check_running() const {
  if (failed())
    throw SimulationError(fmt::format("{}: the simulation stopped at tick {} ({}); call reset() to start again", name(),
                                      engine_.scheduler->ticks(), failure_));
}

void Session::fail(const SimulationError& e) {
  // the values that most likely made it stop, as `tissue run` names them, the host's loads among them
  failure_ = e.what() + scene::stop_cause_text(*scene_, model(), loads_ ? &*loads_ : nullptr);
  throw SimulationError(failure_);
}

TickReport Session::tick() {
  begin_tick();
  return end_tick();
}

void Session::begin_tick() {
  check_running();
  fields_.reset();
  try {
    engine_.scheduler->begin_tick(device_ptrs_);
  } catch (const SimulationError& e) {
    fail(e);
  }
}

TickReport Session::end_tick() {
  try {
    last_ = engine_.scheduler->end_tick();
  } catch (const SimulationError& e) {
    fail(e);
  }
  return last_;
}

void Session::set_loads(std::vector<index_t> nodes, std::vector<double> forces) {
  try {
    engine_.scheduler->set_loads(nodes, forces);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(fmt::format("{}: {}", name(), e.what()));
  }
  loads_ = scene::SceneLoads{std::move(nodes), std::move(forces)};
}

SessionCut Session::cut(const CutSurface& surface, const CutOptions& options) {
  check_running();
  scene::check_cuttable(*scene_);
  const TissueModel<double>& before = model();
  if (scene_->nodes.size() != 3 * std::size_t(before.n_nodes) || scene_->tets.size() != 4 * std::size_t(before.n_elems))
    throw std::logic_error(fmt::format("{}: the scene's mesh ({} nodes, {} elements) is not its model's", name(),
                                       scene_->nodes.size() / 3, scene_->tets.size() / 4));
  SessionCut out;
  out.dt_before = before.dt;
  out.dt_crit_before = before.dt_crit_physical;
  out.added_mass_before = before.added_mass;
  out.nodes_before = before.n_nodes;
  out.elements_before = before.n_elems;
  const std::vector<double> u = backend().download().u, u_prev = backend().previous_displacements();
  DeformedCut d = cut_deformed(scene_->nodes, scene_->tets, u, u_prev, surface, options);
  auto cut_scene = std::make_shared<const scene::Scene>(scene::scene_after_cut(*scene_, d.cut));
  auto cut_model = std::make_shared<const TissueModel<double>>(scene::load_model(*cut_scene));
  out.dt_after = cut_model->dt;
  out.dt_crit_after = cut_model->dt_crit_physical;
  out.added_mass_after = cut_model->added_mass;
  // the same velocity at the new step: u - u_prev scales with dt
  const double ratio = cut_model->dt / before.dt;
  if (ratio != 1)
    for (std::size_t k = 0; k < d.u.size(); ++k) d.u_prev[k] = d.u[k] - ratio * (d.u[k] - d.u_prev[k]);
  // the host's loads on the nodes that keep their ids (a copy takes none: the total is kept)
  std::optional<scene::SceneLoads> loads = loads_;
  try {
    backend().upload(*cut_model);
    scheduler().remesh(*cut_model, d.cut.from);
    if (loads)
      scheduler().set_loads(loads->nodes, loads->force);
    else
      scene::apply_loads(*cut_scene, *cut_model, scheduler());
    backend().set_motion(d.u, d.u_prev);
  } catch (const std::exception& e) {
    // the backend holds the cut mesh in part: this session cannot go on
    failure_ = fmt::format("the cut could not be carried over to the backend: {}", e.what());
    throw SimulationError(fmt::format("{}: {}", name(), failure_));
  }
  if (!uncut_scene_) {
    uncut_scene_ = scene_;
    uncut_model_ = engine_.model;
  }
  engine_.model = std::move(cut_model);
  scene_ = std::move(cut_scene);
  box_ = scene::mesh_box(scene_->nodes);
  fields_.reset();
  out.cut = std::move(d.cut);
  return out;
}

const Fields& Session::fields() {
  if (!fields_) fields_ = engine_.backend->download();
  return *fields_;
}

}  // namespace tissue
