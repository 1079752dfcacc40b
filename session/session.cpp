#include "session/session.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <stdexcept>
#include <tbb/task_arena.h>
#ifdef __linux__
#include <sys/resource.h>
#include <unistd.h>
#endif

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
  for (const scene::Tool& t : scene_->tools) {
    if (!t.path.empty()) {
      devices_.emplace_back(t.path);
      continue;
    }
    // a host-driven device (mouse, phantom) with no path: parked above the body until the host sets a pose
    const Vec3<double> park = {0.5 * (box_.lo.x + box_.hi.x), 0.5 * (box_.lo.y + box_.hi.y),
                               box_.hi.z + box_.size + 2 * t.radius * double(devices_.size() + 1)};
    devices_.emplace_back(std::vector<Waypoint>{{0, park}});
  }
  for (HostDevice& d : devices_) device_ptrs_.push_back(&d);
  restart();
}

void Session::restart() {
  if (pending_) {
    pending_->job.wait();  // its copies only: dropped
    pending_.reset();
  }
  if (uncut_scene_) {
    scene_ = std::move(uncut_scene_);
    engine_.model = std::move(uncut_model_);
    box_ = scene::mesh_box(scene_->nodes);
  }
  start_engine(engine_, *scene_, settings_, loads_ ? &*loads_ : nullptr);
  last_ = TickReport{};
  last_.n_tools = n_tools();
  fields_.reset();
  share_cores();
  failure_.clear();
  blades_.assign(std::size_t(n_tools()), BladeState{});
  cuts_ = 0;
}

void Session::drive_with(std::vector<Device*> devices) {
  if (devices.empty()) {
    device_ptrs_.clear();
    for (HostDevice& d : devices_) device_ptrs_.push_back(&d);
    return;
  }
  if (devices.size() != devices_.size())
    throw std::invalid_argument(fmt::format("{}: drive_with: {} devices for the scene's {} tools (one per tool)", name(),
                                            devices.size(), devices_.size()));
  for (std::size_t t = 0; t < devices.size(); ++t)
    if (devices[t] == nullptr) throw std::invalid_argument(fmt::format("{}: drive_with: tool {}'s device is null", name(), t));
  device_ptrs_ = std::move(devices);
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
  cut_with_blades();
  share_cores();
  return last_;
}

void Session::share_cores() {
  const auto running = [](const auto& job) {
    return job.valid() && job.wait_for(std::chrono::seconds(0)) != std::future_status::ready;
  };
  const bool busy = (pending_ && running(pending_->job)) || running(retiring_);
  if (busy == cores_lent_) return;
  backend().lend_cores(busy ? 1 : 0);
  cores_lent_ = busy;
}

namespace {

/// The mean length of the edges at `nodes` (reference), 0 for none: the
/// mesh's size where a blade touches it.
double edge_size(const TissueModel<double>& m, const std::vector<index_t>& nodes) {
  double sum = 0;
  long count = 0;
  const std::size_t ne = std::size_t(m.n_elems);
  for (index_t a : nodes)
    for (index_t k = m.node_elem_start[a]; k < m.node_elem_start[a + 1]; ++k) {
      const std::size_t e = std::size_t(m.node_elem[k] / 4);
      for (int c = 0; c < 4; ++c) {
        const index_t b = m.elem_nodes[std::size_t(c) * ne + e];
        if (b == a) continue;
        sum += norm(reference_position(m, b) - reference_position(m, a));
        ++count;
      }
    }
  return count ? sum / double(count) : 0;
}

}  // namespace

void Session::open_lips(const SessionCut& made, Vec3<double> tip, Vec3<double> axis, double length, double radius,
                        Vec3<double> across) {
  // the nodes of the faces the cut opened lie on the blade's plane, inside it: each goes to the blade's
  // surface on the side of its own elements (the contact would push it along the plane, not apart)
  const TissueModel<double>& m = model();
  const std::size_t n = std::size_t(m.n_nodes), ne = std::size_t(m.n_elems);
  const Vec3<double> normal = (1 / norm(across)) * across;
  std::vector<double> u = backend().download().u, u_prev = backend().previous_displacements();
  const auto place = [&](std::size_t a) {
    return reference_position(m, index_t(a)) + Vec3<double>{u[a], u[n + a], u[2 * n + a]};
  };
  std::vector<std::uint8_t> lip(n, 0);
  for (std::size_t i = std::size_t(made.nodes_before); i < n; ++i) {
    const auto [a, b] = made.cut.from[i];
    if (a != b) continue;  // a node made on an edge, not a copy
    lip[i] = lip[std::size_t(a)] = 1;
  }
  bool moved = false;
  for (std::size_t a = 0; a < n; ++a) {
    if (!lip[a] || fixed_axes(m.node_flags[a]) != 0) continue;
    const Vec3<double> x = place(a);
    const double s = std::clamp(dot(x - tip, axis), 0.0, length);
    const Vec3<double> off = x - (tip + s * axis);
    if (!(norm(off) < radius)) continue;
    // its side: where the centroids of its elements lie
    double side = 0;
    for (index_t k = m.node_elem_start[a]; k < m.node_elem_start[a + 1]; ++k) {
      const std::size_t e = std::size_t(m.node_elem[k] / 4);
      Vec3<double> c = {0, 0, 0};
      for (int j = 0; j < 4; ++j) c = c + 0.25 * place(std::size_t(m.elem_nodes[std::size_t(j) * ne + e]));
      side += dot(c - x, normal);
    }
    if (side == 0) continue;
    const double to = (side > 0 ? 1 : -1) * radius - dot(off, normal);
    for (int c = 0; c < 3; ++c) {
      u[std::size_t(c) * n + a] += to * normal[c];
      u_prev[std::size_t(c) * n + a] += to * normal[c];
    }
    moved = true;
  }
  if (moved) backend().set_motion(u, u_prev);
  fields_.reset();
}

void Session::land_cut(int blade, Vec3<double> ahead, const std::function<SessionCut()>& make) {
  const auto start = std::chrono::steady_clock::now();
  try {
    const SessionCut made = make();
    if (blade >= 0) {
      const scene::Tool& b = scene_->tools[std::size_t(blade)];
      ToolReport& r = last_.tools[std::size_t(blade)];
      open_lips(made, r.tip, r.axis, b.shaft, b.radius, cross(r.axis, ahead));
      r.cut = true;
    }
    last_cut_seconds_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    ++cuts_;
  } catch (const CutError& e) {
    if (blade < 0) throw;  // the host's (begin_cut): refused, as cut() refuses it
    // a blade's: the tissue gave, but its crack, at rest, meets no element (a blade that has pressed the
    // surface down deeper than its crack, docs/cutting.md "What it does not do"); said once a stroke
    BladeState& state = blades_[std::size_t(blade)];
    if (!std::exchange(state.refusal_noted, true))
      scheduler().note(fmt::format(
          "tick {}: blade '{}': the tissue gave, but the cut it makes meets no element of the body at rest ({}); "
          "a blade that has carried the surface down deeper than its crack passes through uncut",
          last_.tick, scene_->tools[std::size_t(blade)].name, e.what()));
  } catch (const ModelError& e) {
    if (blade < 0) throw;
    scheduler().note(fmt::format("tick {}: blade '{}' did not cut: the cut mesh was refused: {}", last_.tick,
                                 scene_->tools[std::size_t(blade)].name, e.what()));
  }
}

void Session::take_pending_cut() {
  land_cut(pending_->blade, pending_->ahead, [this] { return finish_cut(); });
}

void Session::cut_with_blades() {
  if (pending_ && engine_.scheduler->ticks() >= pending_->due) take_pending_cut();
  // the lips touch but while a blade's button is down
  bool stroke = false;
  for (int t = 0; t < n_tools(); ++t)
    stroke = stroke || (scene_->tools[std::size_t(t)].kind == scene::Tool::Kind::Blade && last_.tools[std::size_t(t)].grasp);
  scheduler().suspend_lip_contact(stroke);
  for (int t = 0; t < n_tools(); ++t) {
    if (scene_->tools[std::size_t(t)].kind != scene::Tool::Kind::Blade) continue;
    const scene::Tool blade = scene_->tools[std::size_t(t)];  // a copy: a cut replaces the scene
    const ToolReport& report = last_.tools[std::size_t(t)];
    BladeState& state = blades_[std::size_t(t)];
    const Vec3<double> tip = report.tip, axis = report.axis;
    if (!report.grasp) {
      state = {};
      continue;
    }
    if (!state.down) {  // the button went down: a stroke starts where the edge is
      state = {};
      state.down = true;
      state.down_tip = state.last_tip = tip;
      continue;
    }
    // the direction the edge cuts in: its motion across itself this tick
    Vec3<double> motion = tip - state.last_tip;
    motion = motion - dot(motion, axis) * axis;
    state.last_tip = tip;
    if (!(norm(motion) > 1e-9 * blade.radius) || report.contact_nodes == 0) continue;
    const Vec3<double> ahead = (1 / norm(motion)) * motion;
    // the force against the motion per metre of edge in contact (the edge's span over its contact nodes)
    const double against = -dot(report.force, ahead);
    const Fields& f = fields();
    const TissueModel<double>& m = model();
    const index_t n = m.n_nodes;
    std::vector<index_t> touching;
    double lo = INFINITY, hi = -INFINITY;
    for (const ContactNode& c : backend().contacts()) {
      if (c.tool != t) continue;
      touching.push_back(c.node);
      const std::size_t a = std::size_t(c.node);
      const Vec3<double> x = reference_position(m, c.node) + Vec3<double>{f.u[a], f.u[n + a], f.u[2 * std::size_t(n) + a]};
      const double s = std::clamp(dot(x - tip, axis), 0.0, blade.shaft);
      lo = std::min(lo, s);
      hi = std::max(hi, s);
    }
    if (touching.empty()) continue;
    const double in_contact = std::max(hi - lo, 2 * blade.radius);
    if (!(against >= blade.cut_resistance * in_contact)) continue;
    // the tissue gives: the crack grows by the work done against it since it last grew over the cutting
    // resistance (Mahvash and Hayward), W = J_c L da, on the stroke's plane in the reference configuration
    const std::span<const double> X(scene_->nodes);
    const std::span<const index_t> tets(scene_->tets);
    const double h = edge_size(m, touching);
    if (!state.started) {  // the first cut: from the edge where the button went down to a lead beyond it
      state.lead = 2 * blade.radius + h;
      state.start0 = state.front0 = pull_back(X, tets, f.u, state.down_tip);
      state.edge = pull_back(X, tets, f.u, state.down_tip + blade.shaft * axis) - state.start0;
      const Vec3<double> g0 = pull_back(X, tets, f.u, tip + state.lead * ahead);
      const Vec3<double> across = cross(state.edge, g0 - state.start0);
      if (!(norm(across) > 0)) continue;
      state.normal = (1 / norm(across)) * across;
      state.onward = (1 / norm(state.edge)) * cross(state.normal, state.edge);
      state.front0 = state.start0 + dot(g0 - state.start0, state.onward) * state.onward;
      state.started = true;
    } else {
      // no faster than the blade moves: the blade drives the crack (the force past the resistance includes
      // the lips' wedge on the blade, which does not open the crack's tip)
      const double grown = std::min(against * norm(motion) / (blade.cut_resistance * in_contact + 1e-300), norm(motion));
      state.front0 = state.front0 + grown * state.onward;
    }
    // and at least a lead beyond the furthest material point the edge presses (the blade is where it
    // touches the tissue, which its press carries along)
    double furthest = -INFINITY;
    for (index_t a : touching) furthest = std::max(furthest, dot(reference_position(m, a) - state.start0, state.onward));
    if (const double run = dot(state.front0 - state.start0, state.onward); furthest + state.lead > run)
      state.front0 = state.front0 + (furthest + state.lead - run) * state.onward;
    // and through the far side where less than a third of an element is left of the tissue ahead of it in
    // the crack's strip (the mesh holds no thinner ligament)
    const double span = norm(state.edge);
    const Vec3<double> along = (1 / span) * state.edge;
    double far = -INFINITY;
    for (index_t a = 0; a < n; ++a) {
      const Vec3<double> d = reference_position(m, a) - state.start0;
      if (std::fabs(dot(d, state.normal)) < h && dot(d, along) > -h && dot(d, along) < span + h)
        far = std::max(far, dot(d, state.onward));
    }
    if (const double run = dot(state.front0 - state.start0, state.onward); run < far && run > far - h / 3)
      state.front0 = state.front0 + (far + h - run) * state.onward;
    const double run = dot(state.front0 - state.start0, state.onward);
    if (state.cut_at > 0 && run - state.cut_at < h / 3) continue;  // not yet a third of an element on
    if (pending_) continue;  // a cut in preparation: the crack grows on, and the next cut takes it
    state.cut_at = run;
    const CutSurface crack{state.start0, state.edge, state.front0 - state.start0};
    const long delay = std::lround(std::ceil(blade.cut_delay / settings_.tick - 1e-9));
    if (delay > 0) {  // prepared while the ticks run on; it takes effect `delay` ticks from now
      begin_cut(crack, {}, CutSpace::Reference, engine_.scheduler->ticks() + delay);
      pending_->blade = t;
      pending_->ahead = ahead;
      continue;
    }
    land_cut(t, ahead, [&] { return cut(crack, {}, CutSpace::Reference); });
  }
}

void Session::set_loads(std::vector<index_t> nodes, std::vector<double> forces) {
  try {
    engine_.scheduler->set_loads(nodes, forces);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(fmt::format("{}: {}", name(), e.what()));
  }
  loads_ = scene::SceneLoads{std::move(nodes), std::move(forces)};
}

Session::PreparedCut Session::prepare_cut(CutInput in) {
  const auto start = std::chrono::steady_clock::now();
  PreparedCut p;
  p.made = cut_moving(in.scene->nodes, in.scene->tets, in.u, in.u_prev, in.surface, in.options, in.space);
  p.scene = std::make_shared<const scene::Scene>(scene::scene_after_cut(*in.scene, p.made.cut));
  p.model = std::make_shared<const TissueModel<double>>(scene::load_model(*p.scene));
  p.tick = in.tick;
  if (!in.backend.empty()) {
    // the backend it runs on, ready to step: uploaded, its region built, its surface BVH made (one thread: the
    // ticks' cores are the ticks')
    tbb::task_arena one(1);
    one.execute([&] {
      p.backend = create_backend(in.backend, in.precision);
      p.backend->upload(*p.model);
      p.region.seeds = Scheduler::seeds_after(in.seeds, p.made.cut.from);
      p.region.depth = in.depth;
      p.region.sizes = p.backend->build_region(p.region.seeds, in.depth);
      p.region.surface_edge = median_surface_edge(*p.model);
      p.backend->set_motion(p.made.u, p.made.u_prev);
      p.backend->warm_up();
    });
  }
  p.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return p;
}

void Session::check_cut_now() const {
  check_running();
  scene::check_cuttable(*scene_);
  const TissueModel<double>& m = model();
  if (scene_->nodes.size() != 3 * std::size_t(m.n_nodes) || scene_->tets.size() != 4 * std::size_t(m.n_elems))
    throw std::logic_error(fmt::format("{}: the scene's mesh ({} nodes, {} elements) is not its model's", name(),
                                       scene_->nodes.size() / 3, scene_->tets.size() / 4));
}

SessionCut Session::cut(const CutSurface& surface, const CutOptions& options, CutSpace space) {
  if (pending_) take_pending_cut();  // a blade's, made first
  check_cut_now();
  return commit_cut(prepare_cut(cut_input(surface, options, space)));
}

Session::CutInput Session::cut_input(const CutSurface& surface, const CutOptions& options, CutSpace space) {
  CutInput in;
  in.scene = scene_;
  in.u = backend().download().u;
  in.u_prev = backend().previous_displacements();
  in.surface = surface;
  in.options = options;
  in.space = space;
  in.tick = engine_.scheduler->ticks();
  return in;
}

namespace {

/// The calling thread (a cut's preparation) runs at the lowest priority: the haptic ticks come first. (Nice 19,
/// not SCHED_IDLE: idle-class preparation took 2-3 times as long on a 2-core machine, past its delay, and
/// the ticks were no faster.)
void yield_to_the_ticks() {
#ifdef __linux__
  setpriority(PRIO_PROCESS, static_cast<id_t>(gettid()), 19);  // refused: it runs as the others do
#endif
}

}  // namespace

void Session::begin_cut(const CutSurface& surface, const CutOptions& options, CutSpace space, long due) {
  if (pending_) throw std::logic_error(fmt::format("{}: begin_cut: a cut is already in preparation", name()));
  check_cut_now();
  CutInput in = cut_input(surface, options, space);
  in.backend = backend().name();
  in.precision = backend().precision();
  in.seeds = scheduler().seeds();
  in.depth = scheduler().depth_after_cut();
  pending_.emplace();
  pending_->due = due;
  pending_->job = std::async(std::launch::async, [in = std::move(in)]() mutable {
    yield_to_the_ticks();
    return prepare_cut(std::move(in));
  });
  share_cores();
}

SessionCut Session::finish_cut() {
  if (!pending_) throw std::logic_error(fmt::format("{}: no cut is in preparation", name()));
  std::future<PreparedCut> job = std::move(pending_->job);
  pending_.reset();
  PreparedCut p = job.get();  // rethrows the preparation's CutError, SceneError or ModelError
  last_cut_prepare_seconds_ = p.seconds;
  check_cut_now();
  return commit_cut(std::move(p));
}

SessionCut Session::commit_cut(PreparedCut&& p) {
  const TissueModel<double>& before = model();
  SessionCut out;
  out.dt_before = before.dt;
  out.dt_crit_before = before.dt_crit_physical;
  out.added_mass_before = before.added_mass;
  out.nodes_before = before.n_nodes;
  out.elements_before = before.n_elems;
  MovingCut& d = p.made;
  CommitTimes times;
  auto lap = std::chrono::steady_clock::now();
  const auto took = [&lap](double& part) {
    const auto now = std::chrono::steady_clock::now();
    part = std::chrono::duration<double>(now - lap).count();
    lap = now;
  };
  if (p.tick != engine_.scheduler->ticks()) {  // prepared ticks ago: the motion of now, at the same material points
    const std::vector<double> u = backend().download().u, u_prev = backend().previous_displacements();
    took(times.download);
    d.u = d.transfer(u);
    d.u_prev = d.transfer(u_prev);
  }
  std::shared_ptr<const TissueModel<double>> cut_model = std::move(p.model);
  std::shared_ptr<const scene::Scene> cut_scene = std::move(p.scene);
  out.dt_after = cut_model->dt;
  out.dt_crit_after = cut_model->dt_crit_physical;
  out.added_mass_after = cut_model->added_mass;
  // the same velocity at the new step: u - u_prev scales with dt
  const double ratio = cut_model->dt / before.dt;
  if (ratio != 1)
    for (std::size_t k = 0; k < d.u.size(); ++k) d.u_prev[k] = d.u[k] - ratio * (d.u[k] - d.u_prev[k]);
  took(times.transfer);
  // the host's loads on the nodes that keep their ids (a copy takes none: the total is kept)
  std::optional<scene::SceneLoads> loads = loads_;
  try {
    if (p.backend) {  // prepared on it: it takes over, the old one is let go on another thread
      std::unique_ptr<Backend> old = std::exchange(engine_.backend, std::move(p.backend));
      engine_.backend->adopt_graphs(*old);  // (its graphs updated in place are no instantiations in the ticks on)
      scheduler().remesh(*cut_model, d.cut.from, *engine_.backend, p.region);
      if (retiring_.valid()) retiring_.wait();
      retiring_ = std::async(std::launch::async, [old = std::move(old)]() mutable {
        yield_to_the_ticks();
        old.reset();
      });
      cores_lent_ = false;  // the new backend's own
    } else {
      backend().upload(*cut_model);
      scheduler().remesh(*cut_model, d.cut.from);
    }
    took(times.swap);
    if (loads)
      scheduler().set_loads(loads->nodes, loads->force);
    else
      scene::apply_loads(*cut_scene, *cut_model, scheduler());
    took(times.loads);
    backend().set_motion(d.u, d.u_prev);
    took(times.upload);
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
  last_commit_times_ = times;
  return out;
}

const Fields& Session::fields() {
  if (!fields_) fields_ = engine_.backend->download();
  return *fields_;
}

}  // namespace tissue
