#include "core/scheduler.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "core/tet.hpp"

namespace tissue {
namespace {

/// Distance from p to the nearest surface node of the reference configuration (m).
double nearest_surface_node(const TissueModel<double>& m, Vec3<double> p) {
  double best = INFINITY;
  for (index_t a : m.surf_nodes) best = std::min(best, norm(reference_position(m, a) - p));
  return best;
}

void check_settings(const SchedulerSettings& s, const TissueModel<double>& m) {
  if (!(s.tick > 0) || !std::isfinite(s.tick))
    throw std::invalid_argument(fmt::format("haptic tick {} s must be > 0", s.tick));
  if (s.tools.size() > std::size_t(kMaxTools))
    throw std::invalid_argument(fmt::format("{} tools: a scene holds at most {}", s.tools.size(), kMaxTools));
  const double extent = body_extent(m);
  for (const ToolSetting& t : s.tools) {
    if (const std::string e = tool_shape_error(t.shape, extent); !e.empty()) throw std::invalid_argument(e);
    if (!(norm(t.axis) > 0) || !std::isfinite(norm(t.axis)))
      throw std::invalid_argument(fmt::format("tool '{}': direction ({}, {}, {}) must be a non-zero vector",
                                              t.shape.name, t.axis.x, t.axis.y, t.axis.z));
  }
}

}  // namespace

double body_extent(const TissueModel<double>& m) {
  double ext = 0;
  for (int c = 0; c < 3; ++c) {
    const auto first = m.X.begin() + long(c) * m.n_nodes;
    const auto [lo, hi] = std::minmax_element(first, first + m.n_nodes);
    if (m.n_nodes > 0) ext = std::max(ext, *hi - *lo);
  }
  return ext;
}

bool inside_surface(const TissueModel<double>& m, std::span<const double> u, Vec3<double> p) {
  // a direction no mesh axis or edge is likely to share, long enough to leave the body
  const Vec3<double> dir = unit_or(Vec3<double>{1.0, 0.0137, 0.0071}, Vec3<double>{1, 0, 0});
  const index_t n = m.n_nodes;
  const auto at = [&](index_t a) {
    const Vec3<double> X = reference_position(m, a);
    return u.empty() ? X : X + Vec3<double>{u[a], u[n + a], u[2 * std::size_t(n) + a]};
  };
  double largest_u = 0;
  for (double v : u) largest_u = std::max(largest_u, std::fabs(v));
  const double extent = body_extent(m) + 2 * largest_u;
  const Vec3<double> far = p + (4 * extent + 1.0) * dir;
  int crossings = 0;
  const index_t nt = m.n_tris;
  for (index_t t = 0; t < nt; ++t) {
    double bary[2];
    if (segment_triangle(p, far, at(m.tris[t]), at(m.tris[nt + t]), at(m.tris[2 * nt + t]), bary) > 0) ++crossings;
  }
  return crossings % 2 == 1;
}

bool inside_reference_surface(const TissueModel<double>& m, Vec3<double> p) { return inside_surface(m, {}, p); }

bool touches_reference_surface(const TissueModel<double>& m, const ToolShape& shape, const ToolPose& pose) {
  const index_t nt = m.n_tris;
  const Capsule<double> cap{pose.tip, pose.tip + shape.shaft * pose.axis, shape.radius};
  for (index_t t = 0; t < nt; ++t) {
    const Vec3<double> P[3] = {reference_position(m, m.tris[t]), reference_position(m, m.tris[nt + t]),
                               reference_position(m, m.tris[2 * std::size_t(nt) + t])};
    double w[3];
    Vec3<double> c;
    if (norm(triangle_deepest_point(cap, P, w, c) - c) < shape.radius) return true;
  }
  return false;
}

std::optional<ToolPose> retracted_from_reference_surface(const TissueModel<double>& m, const ToolShape& shape,
                                                         ToolPose pose, Vec3<double> dir, double step) {
  for (int k = 0; k <= kMaxRetractSteps; ++k) {
    if (!touches_reference_surface(m, shape, pose)) return pose;
    pose.tip = pose.tip + step * dir;
  }
  return std::nullopt;
}

Scheduler::Scheduler(Backend& backend, const TissueModel<double>& model, SchedulerSettings settings)
    : backend_(&backend), model_(&model), settings_(std::move(settings)) {
  check_settings(settings_, model);
  steps_per_tick_ = std::max(1, static_cast<int>(std::lround(settings_.tick / model.dt)));
  depth_ = settings_.depth;
  if (settings_.depth == kDepthAuto) {
    if (settings_.auto_start < 0)
      throw std::invalid_argument(fmt::format("depth auto: start depth {} must be >= 0", settings_.auto_start));
    if (!(settings_.auto_tol > 0) || !std::isfinite(settings_.auto_tol))
      throw std::invalid_argument(fmt::format("depth auto: tolerance {} must be > 0", settings_.auto_tol));
    auto_depth_ = true;
    depth_ = settings_.auto_start;
  }
  for (ToolSetting& t : settings_.tools) t.axis = (1.0 / norm(t.axis)) * t.axis;
  if (!settings_.body_contact.pairs.empty() && settings_.depth != kDepthAll)
    throw std::invalid_argument(fmt::format("depth {}: bodies that touch each other need the whole mesh (depth all): "
                                            "a region of rings does not reach across to the other body",
                                            settings_.depth == kDepthAuto ? std::string("auto")
                                                                          : std::to_string(settings_.depth)));
  give_backend_tools();
  prev_.assign(settings_.tools.size(), ToolPose{});
  entering_.assign(settings_.tools.size(), 0);
  motion_.assign(settings_.tools.size(), ToolMotion{});
  rigid_reported_.assign(settings_.tools.size(), 0);
  last_contact_.assign(settings_.tools.size(), 0);
  last_force_.assign(settings_.tools.size(), 0.0);
  through_reported_.assign(settings_.tools.size(), 0);
  fast_reported_.assign(settings_.tools.size(), 0);
  // a contact carries the surface it meets with the tool within each step: beyond half an edge per step
  // the elements under it deform by a large fraction of their size in one step (and invert at a few edges)
  follow_step_ = 0.5 * median_surface_edge(*model_);
  // depth N: an empty region (nothing moves) until the first contact seeds it
  region_ = backend_->build_region({}, depth_);
  guard_ = StepGuard(*model_, settings_.step_guard);
  if (guard_.watching()) guard_mass_ = model_->mass;  // held from the start: a lift allocates nothing
}

void Scheduler::give_backend_tools() {
  std::vector<ToolShape> shapes;
  for (const ToolSetting& t : settings_.tools) shapes.push_back(t.shape);
  backend_->set_tools(shapes, settings_.contact);
  backend_->set_body_contact(settings_.body_contact);
}

std::vector<index_t> Scheduler::seeds_after(std::span<const index_t> seeds,
                                            std::span<const std::array<index_t, 2>> node_from) {
  std::vector<index_t> out;
  for (std::size_t i = 0; i < node_from.size(); ++i)
    if (std::binary_search(seeds.begin(), seeds.end(), node_from[i][0]) ||
        std::binary_search(seeds.begin(), seeds.end(), node_from[i][1]))
      out.push_back(index_t(i));
  return out;
}

void Scheduler::remesh(const TissueModel<double>& model, std::span<const std::array<index_t, 2>> node_from) {
  remesh_onto(model, node_from, *backend_, nullptr);
}

void Scheduler::remesh(const TissueModel<double>& model, std::span<const std::array<index_t, 2>> node_from,
                       Backend& fresh, const PreparedRemesh& prepared) {
  remesh_onto(model, node_from, fresh, &prepared);
}

void Scheduler::remesh_onto(const TissueModel<double>& model, std::span<const std::array<index_t, 2>> node_from,
                            Backend& backend, const PreparedRemesh* prepared) {
  if (pending_) throw std::logic_error("Scheduler::remesh: a tick was begun and not ended (end_tick)");
  if (node_from.size() != std::size_t(model.n_nodes) || backend.n_nodes() != model.n_nodes)
    throw std::invalid_argument(fmt::format("Scheduler::remesh: {} node origins and a backend of {} nodes for {} "
                                            "nodes",
                                            node_from.size(), backend.n_nodes(), model.n_nodes));
  check_settings(settings_, model);
  const int depth = depth_after_cut();
  if (depth == kDepthAll) {
    depth_ = kDepthAll;
    auto_depth_ = false;
  }
  backend_ = &backend;
  model_ = &model;
  steps_per_tick_ = std::max(1, static_cast<int>(std::lround(settings_.tick / model.dt)));
  // a cut's lips touch (a node outside the region is still: the lip inside it gives way)
  remeshed_ = true;
  settings_.body_contact.lips = lips_on();
  settings_.body_contact.lip_friction = settings_.lip_friction;
  give_backend_tools();
  follow_step_ = 0.5 * (prepared ? prepared->surface_edge : median_surface_edge(model));
  seeds_ = seeds_after(seeds_, node_from);
  guard_ = StepGuard(model, settings_.step_guard);  // the new model's masses, built for its own mesh
  guard_mass_.assign(model.mass.begin(), guard_.watching() ? model.mass.end() : model.mass.begin());
  guard_lifts_ = 0;
  guard_after_remesh_ = true;  // the cut mesh's masses are its own at rest: checked after its first tick
  if (prepared && seeds_ == prepared->seeds && depth == prepared->depth) {
    region_ = prepared->sizes;
  } else {
    rebuild_region(depth);
  }
}

void Scheduler::rebuild_region(int depth) {
  region_ = backend_->build_region(seeds_, depth);
  ++region_rebuilds_;
}

void Scheduler::suspend_lip_contact(bool suspend) {
  if (suspend == lips_suspended_) return;
  lips_suspended_ = suspend;
  if (settings_.body_contact.lips == lips_on()) return;
  settings_.body_contact.lips = lips_on();
  backend_->set_body_contact(settings_.body_contact);
}

std::vector<std::string> Scheduler::take_notes() {
  std::vector<std::string> out;
  out.swap(notes_);
  return out;
}

void Scheduler::set_tool_friction(int t, double friction) {
  backend_->set_tool_friction(t, friction);
  settings_.tools[std::size_t(t)].shape.friction = friction;
}

void Scheduler::set_loads(std::span<const index_t> nodes, std::span<const double> force) {
  backend_->set_loads(nodes, force);
  if (region_.whole()) return;
  const std::vector<index_t>& loaded = backend_->loaded_nodes();
  std::vector<index_t> seeds;
  std::set_union(seeds_.begin(), seeds_.end(), loaded.begin(), loaded.end(), std::back_inserter(seeds));
  if (seeds == seeds_) return;
  seeds_ = std::move(seeds);
  rebuild_region(depth_);
}

void Scheduler::seed_region() {
  if (region_.whole()) return;
  const std::vector<index_t> cand = backend_->contact_candidates();
  if (cand.empty()) return;
  std::vector<index_t> seeds;
  std::set_union(seeds_.begin(), seeds_.end(), cand.begin(), cand.end(), std::back_inserter(seeds));
  seeds_ = std::move(seeds);
  rebuild_region(depth_);
}

bool Scheduler::grow_region(const Reductions& r) {
  if (!auto_depth_ || seeds_.empty() || region_.whole()) return false;
  if (r.front_disp < 0)
    throw SimulationError(fmt::format("depth auto: the {} backend does not report the front ring's displacement "
                                      "(Reductions::front_disp); use a fixed depth",
                                      backend_->name()));
  if (!(r.front_disp > settings_.auto_tol * r.max_disp)) return false;
  ++depth_;
  rebuild_region(depth_);
  return true;
}

double Scheduler::tick_move(std::size_t t) const {
  // the farther of the tip's path and the shaft end's this tick
  const ToolMotion& m = motion_[t];
  const double l = settings_.tools[t].shape.shaft;
  return std::max(norm(m.to.tip - m.from.tip), norm((m.to.tip + l * m.to.axis) - (m.from.tip + l * m.from.axis)));
}

std::string Scheduler::fast_tools(bool in_contact_only, const Reductions& r) const {
  std::string out;
  for (std::size_t t = 0; t < settings_.tools.size(); ++t) {
    const double move = tick_move(t), per_step = move / steps_per_tick_;
    if (!(per_step > follow_step_)) continue;
    if (in_contact_only && r.tools[t].contact + r.tools[t].rigid + r.tools[t].outside == 0) continue;
    out += fmt::format("{}tool '{}' moved {:.3g} mm per TLED step ({:.3g} m/s)", out.empty() ? "" : "; ",
                       settings_.tools[t].shape.name, 1e3 * per_step, move / settings_.tick);
  }
  if (!out.empty())
    out += fmt::format(
        ": a contact carries the surface it meets along with the tool within each step (checked every r / 2 of "
        "its path), and more than {:.3g} mm (half the surface's median edge) a step deforms the elements under it "
        "by a large part of their size; slow the tool or shorten the step",
        1e3 * follow_step_);
  return out;
}

void Scheduler::note_fast_tools(const Reductions& r) {
  for (std::size_t t = 0; t < settings_.tools.size(); ++t) {
    const ToolReduction& tr = r.tools[t];
    const bool touching = tr.contact + tr.rigid + tr.outside > 0;
    if (!touching) {
      fast_reported_[t] = 0;
      continue;
    }
    if (fast_reported_[t]) continue;
    const double move = tick_move(t);
    if (!(move / steps_per_tick_ > follow_step_)) continue;
    fast_reported_[t] = 1;
    notes_.push_back(fmt::format("tick {}: tool '{}' moved {:.3g} mm per TLED step ({:.3g} m/s) in contact: a contact "
                                 "carries the surface it meets along with the tool within each step, and more than "
                                 "{:.3g} mm (half the surface's median edge) a step deforms the elements under it by a "
                                 "large part of their size; slow the tool or shorten the step",
                                 tick_, settings_.tools[t].shape.name, 1e3 * move / steps_per_tick_,
                                 move / settings_.tick, 1e3 * follow_step_));
  }
}

void Scheduler::note_passed_through(const Reductions& r) {
  std::vector<double> u;  // downloaded once, only where a contact ended
  for (std::size_t t = 0; t < settings_.tools.size(); ++t) {
    const ToolReduction& tr = r.tools[t];
    const index_t before = last_contact_[t];
    const double force = last_force_[t];
    last_contact_[t] = tr.contact;
    last_force_[t] = norm(tr.reaction);
    if (tr.contact > 0) through_reported_[t] = 0;
    if (before == 0 || tr.contact > 0 || tr.rigid > 0 || through_reported_[t]) continue;
    // the tip, the shaft's middle and its end: the part that went through
    const ToolMotion& m = motion_[t];
    const double l = settings_.tools[t].shape.shaft;
    // a tool lifted off ends its contact outside the undeformed body: only one inside it costs a download
    // (the haptic tick's traffic stays fixed)
    if (!inside_reference_surface(*model_, m.to.tip) &&
        !(l > 0 && inside_reference_surface(*model_, m.to.tip + 0.5 * l * m.to.axis)))
      continue;
    if (u.empty()) u = backend_->download().u;
    const char* part = nullptr;
    if (inside_surface(*model_, u, m.to.tip))
      part = "tip";
    else if (l > 0 && inside_surface(*model_, u, m.to.tip + 0.5 * l * m.to.axis))
      part = "shaft";
    if (part == nullptr) continue;
    through_reported_[t] = 1;
    notes_.push_back(fmt::format(
        "tick {}: tool '{}' lost contact with its {} inside the tissue (it pushed with {:.3g} N the tick before): it "
        "went through the surface, so it feels nothing until it comes out. The tissue pushed a face more than about "
        "the tool's radius into it in one TLED step (the contact's limit, docs/contact.md); reduce the indentation "
        "or the time step",
        tick_, settings_.tools[t].shape.name, part, force));
  }
}

namespace {

/// " (its centroid at (x, y, z) mm, D mm from tool 'a', inside tool 'b')": where a stop's element lies against
/// the tools at the end of the tick (`to`: each tool's pose), telling a far-field blow-up from an inversion
/// under a tool.
std::string element_place(const TissueModel<double>& model, const SchedulerSettings& settings,
                          const std::vector<ToolMotion>& motion, index_t e) {
  if (e < 0 || e >= model.n_elems) return "";
  Vec3<double> c{0, 0, 0};
  for (int a = 0; a < 4; ++a) c = c + 0.25 * reference_position(model, model.elem_nodes[a * model.n_elems + e]);
  std::string out = fmt::format(" (its centroid at ({:.4g}, {:.4g}, {:.4g}) mm", 1e3 * c.x, 1e3 * c.y, 1e3 * c.z);
  for (std::size_t t = 0; t < settings.tools.size() && t < motion.size(); ++t) {
    // the distance to the tool's capsule (its tip and shaft)
    const ToolPose& p = motion[t].to;
    const double l = settings.tools[t].shape.shaft;
    const double s = l > 0 ? std::clamp(dot(c - p.tip, p.axis), 0.0, l) : 0.0;
    const double d = norm(c - (p.tip + s * p.axis)) - settings.tools[t].shape.radius;
    out += d <= 0 ? fmt::format(", inside tool '{}'", settings.tools[t].shape.name)
                  : fmt::format(", {:.3g} mm from tool '{}'", 1e3 * d, settings.tools[t].shape.name);
  }
  return out + ")";
}

}  // namespace

void Scheduler::check_health(const Reductions& r, long first_step) const {
  if (r.bad_elem >= 0) {
    const std::string fast = fast_tools(false, r);
    throw SimulationError(fmt::format(
        "tick {} (TLED steps {}..{}): element {}{} has J = {:.4g} (inverted or degenerate); stopping. "
        "Reduce the indentation or the time step{}",
        tick_, first_step, total_steps_ - 1, r.bad_elem, element_place(*model_, settings_, motion_, r.bad_elem),
        r.bad_J, fast.empty() ? "" : ". " + fast));
  }
  if (!r.finite)
    throw SimulationError(fmt::format("tick {} (TLED steps {}..{}): non-finite displacement or force; stopping",
                                      tick_, first_step, total_steps_ - 1));
}

void Scheduler::note_contacts(const Reductions& r) {
  for (std::size_t t = 0; t < settings_.tools.size(); ++t) {
    const ToolReduction& tr = r.tools[t];
    if (tr.rigid == 0) {
      rigid_reported_[t] = 0;
      continue;
    }
    if (rigid_reported_[t] > 0) continue;  // once per episode of rigid contact
    rigid_reported_[t] = tr.rigid;
    std::vector<index_t> named;
    for (const ContactNode& c : backend_->contacts())
      if (c.tool == int(t) && c.kind == kRigidContact && named.size() < 8) named.push_back(c.node);
    notes_.push_back(fmt::format(
        "tick {}: tool '{}' presses {} node(s) that the scene fixes (a rigid support): node(s) {}{}; they do not "
        "move and their support force is not part of the tool's force ({} other node(s) in contact)",
        tick_, settings_.tools[t].shape.name, tr.rigid, fmt::join(named, ", "), tr.rigid > index_t(named.size()) ? ", ..." : "",
        tr.contact));
  }
}

TickReport Scheduler::tick(Device& device) {
  Device* one[] = {&device};
  return tick(one);
}

TickReport Scheduler::tick(std::span<Device* const> devices) {
  begin_tick(devices);
  return end_tick();
}

void Scheduler::begin_tick(std::span<Device* const> devices) {
  if (pending_) throw std::logic_error("Scheduler::begin_tick: the last tick was begun and not ended (end_tick)");
  const std::size_t n_tools = settings_.tools.size();
  if (devices.size() != n_tools)
    throw std::invalid_argument(fmt::format("Scheduler::tick: {} devices for {} tools (one device per tool)",
                                            devices.size(), n_tools));
  const double t_end = (tick_ + 1) * settings_.tick;
  TickReport& rep = pending_report_;
  rep = TickReport{};
  rep.n_tools = static_cast<int>(n_tools);
  for (std::size_t t = 0; t < n_tools; ++t) {
    const ToolInput in = devices[t]->read(t_end);
    if (!(std::isfinite(in.tip.x) && std::isfinite(in.tip.y) && std::isfinite(in.tip.z)))
      throw SimulationError(fmt::format("tick {}: the device of tool '{}' reported a non-finite position", tick_,
                                        settings_.tools[t].shape.name));
    ToolPose pose{in.tip, unit_or(in.axis, settings_.tools[t].axis)};
    const ToolShape& shape = settings_.tools[t].shape;
    if (!has_prev_) {
      prev_[t] = pose;
      const double gap = nearest_surface_node(*model_, pose.tip);
      if (inside_reference_surface(*model_, pose.tip) && gap > shape.radius)
        notes_.push_back(fmt::format(
            "tool '{}' starts inside the body, {:.3g} mm from its nearest surface node: contact acts on the surface, "
            "so the tool feels nothing until its surface meets the tissue's",
            shape.name, 1e3 * (gap - shape.radius)));
      else if (const std::optional<ToolPose> out = retracted_from_reference_surface(
                   *model_, shape, pose, pose.axis, 0.05 * shape.radius);
               out && norm(out->tip - pose.tip) > kEntryDepth * shape.radius) {
        prev_[t] = *out;
        entering_[t] = 1;
        notes_.push_back(fmt::format(
            "tool '{}' starts in contact with the tissue: it is brought in from {:.3g} mm back along its axis at "
            "{:.3g} mm/s, its device's pose reached in {:.3g} s",
            shape.name, 1e3 * norm(out->tip - pose.tip), 1e3 * kEntrySpeed, norm(out->tip - pose.tip) / kEntrySpeed));
      }
    }
    if (entering_[t]) {  // at most kEntrySpeed toward the device's pose, until it is reached
      const Vec3<double> gap = pose.tip - prev_[t].tip;
      const double reach = kEntrySpeed * settings_.tick;
      if (norm(gap) > reach) pose.tip = prev_[t].tip + (reach / norm(gap)) * gap;
      else entering_[t] = 0;
    }
    motion_[t] = {prev_[t], pose, in.grasp && !settings_.tools[t].blade};  // a blade's button cuts
    rep.tools[t].tip = pose.tip;
    rep.tools[t].axis = pose.axis;
    rep.tools[t].grasp = in.grasp;
  }
  has_prev_ = true;
  backend_->move_tools(motion_);
  pending_first_step_ = total_steps_;
  pending_devices_.assign(devices.begin(), devices.end());
  // a limited region grows first where the tools' motion reaches beyond it (the cuda backend checks that
  // inside the tick's own graph: no round trip when the region holds)
  backend_->start_tick(steps_per_tick_, !region_.whole());
  pending_ = true;
}

TickReport Scheduler::end_tick() {
  if (!pending_) throw std::logic_error("Scheduler::end_tick: no tick was begun (begin_tick)");
  pending_ = false;
  std::optional<Reductions> ran = backend_->finish_tick();
  if (!ran) {
    seed_region();
    ran = backend_->advance_reduce(steps_per_tick_);
  }
  const std::size_t n_tools = settings_.tools.size();
  const long first_step = pending_first_step_;
  const double t_end = (tick_ + 1) * settings_.tick;
  TickReport& rep = pending_report_;
  const Reductions& r = *ran;
  total_steps_ += steps_per_tick_;
  check_health(r, first_step);
  note_contacts(r);
  note_fast_tools(r);
  note_passed_through(r);

  rep.tick = tick_;
  rep.time = t_end;
  in_contact_ = false;
  for (std::size_t t = 0; t < n_tools; ++t) {
    const ToolReduction& tr = r.tools[t];
    ToolReport& tool = rep.tools[t];
    tool.force = -1.0 * tr.reaction;
    tool.contact_nodes = tr.contact;
    tool.grasped = tr.grasped;
    tool.rigid_nodes = tr.rigid;
    rep.contact_nodes += tr.contact;
    in_contact_ = in_contact_ || tr.contact > 0;
    prev_[t] = motion_[t].to;
  }
  rep.tool = rep.tools[0].tip;
  rep.force = rep.tools[0].force;
  rep.internal = r.internal;
  rep.region_nodes = region_.nodes();
  rep.region_elems = region_.n_elems;
  const double held = std::sqrt(r.held_force2);
  rep.residual = std::sqrt(r.free_force2) / std::max(held, settings_.force_floor);
  rep.kinetic = r.kinetic;
  rep.strain_energy = r.strain_energy;
  rep.visco_power = r.visco_power;
  rep.visco_stored = r.visco_stored;
  dissipated_ += 0.5 * (visco_power_ + r.visco_power) * (steps_per_tick_ * model_->dt);  // the tick's simulated time
  visco_power_ = r.visco_power;
  rep.dissipated = dissipated_;
  rep.max_disp = r.max_disp;
  rep.front_disp = r.front_disp;
  const double energy_scale = std::max(0.5 * held * r.max_disp, 1e-18);
  rep.kinetic_rel = r.kinetic / energy_scale;
  rep.equilibrium = rep.residual < settings_.residual_tol && rep.kinetic_rel < settings_.kinetic_tol;
  if (grow_region(r)) {  // the next tick runs on the larger region
    rep.equilibrium = false;
    rep.region_nodes = region_.nodes();
    rep.region_elems = region_.n_elems;
  }
  rep.depth = depth_;
  rep.steps = steps_per_tick_;
  for (std::size_t t = 0; t < n_tools; ++t) pending_devices_[t]->send_force(rep.tools[t].force);
  guard_steps(r);  // after the forces went out: its check delays the next tick, not this force
  ++tick_;
  return rep;
}

void Scheduler::guard_steps(const Reductions& r) {
  if (!in_contact_ || !guard_.watching()) return;
  if (!guard_after_remesh_ && tick_ % settings_.step_guard.interval != 0) return;
  guard_after_remesh_ = false;
  std::vector<ToolShape> shapes;
  std::vector<ToolPose> poses;
  double radius = 0;
  for (std::size_t t = 0; t < settings_.tools.size(); ++t)
    if (r.tools[t].contact > 0) {
      shapes.push_back(settings_.tools[t].shape);
      poses.push_back(prev_[t]);  // where this tick left it
      radius = std::max(radius, settings_.tools[t].shape.radius);
    }
  // a corner within a radius of a tool now lies within that plus how far the tissue moved at its place at rest
  const std::vector<index_t> elems = guard_.near(shapes, poses, radius + r.max_disp);
  if (elems.empty()) return;
  const std::vector<double> altitude = backend_->deformed_altitudes(*model_, elems);
  const StepGuardLift lift = guard_.lift(*model_, guard_mass_, elems, altitude);
  if (lift.refused > 0 && !guard_refused_noted_) {
    guard_refused_noted_ = true;
    notes_.push_back(fmt::format(
        "tick {}: the step guard's budget (the mass-scaling budget, {:.3g} % of the mass) is spent: {} crushed "
        "element(s) get no more mass, and may ring until they invert (docs/accuracy.md, \"The step guard\")",
        tick_, 100 * settings_.step_guard.budget, lift.refused));
  }
  if (lift.elements == 0) return;
  backend_->set_masses(guard_mass_, model_->dt, model_->damping);
  if (guard_lifts_ == 0)
    notes_.push_back(fmt::format(
        "tick {}: the tools crush elements whose step falls below {:.2g} of dt (element {}: {:.3g}); the step guard "
        "gives them mass ({:.3g} mg so far) so that dt stays stable (docs/accuracy.md, \"The step guard\")",
        tick_, settings_.step_guard.trigger, lift.worst_elem, lift.worst, 1e6 * guard_.added_mass()));
  guard_lifts_ += lift.elements;
}

}  // namespace tissue
