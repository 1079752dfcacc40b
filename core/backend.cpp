#include "core/backend.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "core/step_guard.hpp"
#include "core/tet.hpp"

namespace tissue {
namespace {

bool finite3(const Vec3<double>& v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

std::string str(const Vec3<double>& v) { return fmt::format("({}, {}, {})", v.x, v.y, v.z); }

/// The pose with a unit axis; throws naming the tool and the rule broken.
ToolPose checked_pose(const ToolPose& p, const ToolShape& s, const char* which) {
  if (!finite3(p.tip))
    throw std::invalid_argument(fmt::format("move_tools: tool '{}': {} tip {} is not finite", s.name, which, str(p.tip)));
  const double n = norm(p.axis);
  if (!(n > 0) || !std::isfinite(n))
    throw std::invalid_argument(fmt::format("move_tools: tool '{}': {} axis {} must be a non-zero finite direction",
                                            s.name, which, str(p.axis)));
  return {p.tip, (1.0 / n) * p.axis};
}

}  // namespace

void Backend::require_upload(const char* what) const {
  if (!uploaded_) throw std::logic_error(fmt::format("{} backend: {}() called before upload()", name(), what));
  if (tick_pending_)
    throw std::logic_error(fmt::format("{} backend: {}() called between start_tick() and finish_tick()", name(), what));
}

void Backend::upload(const TissueModel<double>& m) {
  if (m.n_nodes <= 0 || m.n_elems <= 0)
    throw std::invalid_argument(fmt::format("upload: the model has {} nodes and {} elements (needs at least one of each)",
                                            m.n_nodes, m.n_elems));
  // every array of the store's lists (core/store.hpp) at its declared shape
#define TISSUE_STORE_CHECK(name, type, per, components, unit, what)                                               \
  if (m.name.size() != store_entries(Per::per, m) * (components))                                                 \
    throw std::invalid_argument(fmt::format("upload: the model's {} holds {} values; {} a {} needs {} (build it " \
                                            "with build_model)",                                                  \
                                            #name, m.name.size(), components, to_string(Per::per),                \
                                            store_entries(Per::per, m) * (components)));
  TISSUE_MODEL_ARRAYS(TISSUE_STORE_CHECK)
#undef TISSUE_STORE_CHECK
  if (!(m.dt > 0) || !std::isfinite(m.dt))
    throw std::invalid_argument(fmt::format("upload: the model's time step {} s must be > 0", m.dt));
#define TISSUE_LAW_CHECK(kind, name, len)                                                                    \
  if (m.name.size() != (len))                                                                                 \
    throw std::invalid_argument(fmt::format("upload: the model's law array {} holds {} values; it needs {}", #name, \
                                            m.name.size(), std::size_t(len)));
  TISSUE_LAW_MODEL_FIELDS(TISSUE_LAW_CHECK)
#undef TISSUE_LAW_CHECK
  if (m.n_prony < 0 || m.n_prony > kMaxProny || (m.n_prony > 0) != (m.n_visco > 0))
    throw std::invalid_argument(fmt::format("upload: the model has {} Prony terms per slot for {} viscoelastic "
                                            "elements; it needs 1..{} terms with elements, 0 without",
                                            m.n_prony, m.n_visco, kMaxProny));
  for (index_t e = 0, next = 0; e < index_t(m.visco_slot.size()); ++e) {  // slots count up in element order
    const index_t v = m.visco_slot[e];
    if (v != -1 && v != next)
      throw std::invalid_argument(fmt::format("upload: element {} has Prony slot {}; slots must be -1 (elastic) or "
                                              "count up 0, 1, 2, ... in element order (expected {})",
                                              e, v, next));
    next += v >= 0;
  }
  if (!m.visco_slot.empty() && m.visco_slot.size() == std::size_t(m.n_elems)) {
    index_t count = 0;
    for (index_t v : m.visco_slot) count += v >= 0;
    if (count != m.n_visco)
      throw std::invalid_argument(fmt::format("upload: {} elements have a Prony slot but the model counts {}", count,
                                              m.n_visco));
  }
  uploaded_ = false;
  do_upload(m);
  n_nodes_ = m.n_nodes;
  n_elems_ = m.n_elems;
  uploaded_ = true;
  pass3_forces_ = false;
  body_spec_ = {};  // a new model: its bodies are set again (do_upload dropped the old lists)
  shapes_.clear();
  motion_.clear();
  grasp_pose_.clear();
  grasping_.clear();
  loaded_.clear();
}

namespace {

/// Refuses a motion array that is not 3 x n finite values, naming the call, the node and the value.
void check_motion(const char* call, const char* what, std::span<const double> values, index_t n) {
  if (values.size() != 3 * std::size_t(n))
    throw std::invalid_argument(fmt::format("{}: {} {} values for {} nodes (need 3 x n_nodes = {})", call,
                                            values.size(), what, n, 3 * size_t(n)));
  for (std::size_t k = 0; k < values.size(); ++k)
    if (!std::isfinite(values[k]))
      throw std::invalid_argument(
          fmt::format("{}: node {}: {} {} = {} is not finite", call, k % n, what, "xyz"[k / n], values[k]));
}

}  // namespace

void Backend::set_displacements(std::span<const double> u) {
  require_upload("set_displacements");
  check_motion("set_displacements", "displacement", u, n_nodes_);
  do_set_motion(u, u);
}

void Backend::set_motion(std::span<const double> u, std::span<const double> u_prev) {
  require_upload("set_motion");
  check_motion("set_motion", "displacement", u, n_nodes_);
  check_motion("set_motion", "previous displacement", u_prev, n_nodes_);
  do_set_motion(u, u_prev);
}

void Backend::set_masses(std::span<const double> mass, double dt, double damping) {
  require_upload("set_masses");
  if (mass.size() != std::size_t(n_nodes_))
    throw std::invalid_argument(
        fmt::format("set_masses: {} masses for the {} nodes uploaded", mass.size(), n_nodes_));
  NodeMasses k;
  k.mass.assign(mass.begin(), mass.end());
  k.cd_A.resize(mass.size());
  k.cd_B.resize(mass.size());
  k.cd_C.resize(mass.size());
  for (index_t a = 0; a < n_nodes_; ++a) {
    if (!(mass[a] > 0) || !std::isfinite(mass[a]))
      throw std::invalid_argument(
          fmt::format("set_masses: node {} has mass {} kg (must be finite and > 0)", a, mass[a]));
    const auto c = central_difference_constants(mass[a], dt, damping);
    k.cd_A[a] = c.A;
    k.cd_B[a] = c.B;
    k.cd_C[a] = c.C;
  }
  do_set_masses(k);
}

std::vector<double> Backend::deformed_altitudes(const TissueModel<double>& model, std::span<const index_t> elems) {
  require_upload("deformed_altitudes");
  if (model.n_nodes != n_nodes_ || model.n_elems != n_elems_)
    throw std::invalid_argument(fmt::format("deformed_altitudes: a model of {} nodes and {} elements for the {} and {} "
                                            "uploaded",
                                            model.n_nodes, model.n_elems, n_nodes_, n_elems_));
  for (const index_t e : elems)
    if (e < 0 || e >= n_elems_)
      throw std::out_of_range(fmt::format("deformed_altitudes: element {} out of range (0..{})", e, n_elems_ - 1));
  return do_deformed_altitudes(model, elems);
}

std::vector<double> Backend::do_deformed_altitudes(const TissueModel<double>& model, std::span<const index_t> elems) {
  const std::vector<double> u = download().u;
  if (u.size() != 3 * std::size_t(n_nodes_))
    throw std::logic_error(fmt::format("{} backend: download() gave {} displacements for {} nodes", name(), u.size(),
                                       n_nodes_));
  std::vector<double> out(elems.size());
  for (std::size_t k = 0; k < elems.size(); ++k) out[k] = deformed_altitude(model, std::span<const double>(u), elems[k]);
  return out;
}

void Backend::warm_up() {
  require_upload("warm_up");
  do_warm_up();
}

std::vector<double> Backend::previous_displacements() {
  require_upload("previous_displacements");
  return do_previous_displacements();
}

RegionSizes Backend::build_region(std::span<const index_t> seeds, int depth) {
  require_upload("build_region");
  if (depth != kDepthAll && depth < 0)
    throw std::invalid_argument(fmt::format("build_region: depth {} must be >= 0 or 'all'", depth));
  if (depth != kDepthAll)
    for (index_t a : seeds)
      if (a < 0 || a >= n_nodes_)
        throw std::out_of_range(fmt::format("build_region: seed node {} out of range (0..{})", a, n_nodes_ - 1));
  return do_build_region(seeds, depth);
}

Region Backend::region() {
  require_upload("region");
  return do_region();
}

void Backend::set_driven(std::span<const index_t> nodes, std::span<const double> u) {
  const std::vector<std::uint8_t> all(nodes.size(), kAllAxes);
  set_driven_axes(nodes, u, all);
}

void Backend::set_driven_axes(std::span<const index_t> nodes, std::span<const double> u,
                              std::span<const std::uint8_t> axes) {
  require_upload("set_driven");
  if (u.size() != 3 * nodes.size())
    throw std::invalid_argument(
        fmt::format("set_driven: {} displacement values for {} nodes (need 3 per node)", u.size(), nodes.size()));
  if (axes.size() != nodes.size())
    throw std::invalid_argument(
        fmt::format("set_driven: {} axis masks for {} nodes (need one per node)", axes.size(), nodes.size()));
  for (std::size_t k = 0; k < nodes.size(); ++k) {
    const index_t a = nodes[k];
    if (a < 0 || a >= n_nodes_)
      throw std::invalid_argument(fmt::format("set_driven: node {} out of range (0..{})", a, n_nodes_ - 1));
    if (axes[k] == 0 || axes[k] > kAllAxes)
      throw std::invalid_argument(
          fmt::format("set_driven: node {}: axis mask {} must be 1..7 (bit 0 = x, 1 = y, 2 = z)", a, int(axes[k])));
    for (int c = 0; c < 3; ++c)
      if (!std::isfinite(u[3 * k + c]))
        throw std::invalid_argument(
            fmt::format("set_driven: node {}: displacement {} = {} is not finite", a, "xyz"[c], u[3 * k + c]));
  }
  const std::vector<std::uint8_t> roles = do_roles(nodes);
  for (std::size_t k = 0; k < nodes.size(); ++k)
    if (roles[k] == kOutside)
      throw std::invalid_argument(fmt::format(
          "set_driven: node {} is outside the deformation region (build_region from it first)", nodes[k]));
  // merge repeated nodes: the union of their masks, each component at its last target
  std::vector<index_t> ids;
  std::vector<std::uint8_t> masks;
  std::vector<double> values;
  for (std::size_t k = 0; k < nodes.size(); ++k) {
    const auto it = std::find(ids.begin(), ids.end(), nodes[k]);
    const std::size_t j = std::size_t(it - ids.begin());
    if (it == ids.end()) {
      ids.push_back(nodes[k]);
      masks.push_back(0);
      values.insert(values.end(), 3, 0.0);
    }
    masks[j] |= axes[k];
    for (int c = 0; c < 3; ++c)
      if (axes[k] >> c & 1) values[3 * j + c] = u[3 * k + c];
  }
  do_set_driven(ids, values, masks);
}

void Backend::clear_driven() {
  require_upload("clear_driven");
  do_clear_driven();
}

void Backend::set_loads(std::span<const index_t> nodes, std::span<const double> force) {
  require_upload("set_loads");
  if (force.size() != 3 * nodes.size())
    throw std::invalid_argument(
        fmt::format("set_loads: {} force values for {} nodes (need 3 per node)", force.size(), nodes.size()));
  const index_t n = n_nodes_;
  std::vector<double> load;
  std::vector<index_t> loaded;
  if (!nodes.empty()) load.assign(3 * std::size_t(n), 0.0);
  for (std::size_t k = 0; k < nodes.size(); ++k) {
    const index_t a = nodes[k];
    if (a < 0 || a >= n) throw std::invalid_argument(fmt::format("set_loads: node {} out of range (0..{})", a, n - 1));
    for (int c = 0; c < 3; ++c) {
      if (!std::isfinite(force[3 * k + c]))
        throw std::invalid_argument(
            fmt::format("set_loads: node {}: force {} = {} N is not finite", a, "xyz"[c], force[3 * k + c]));
      load[c * std::size_t(n) + a] += force[3 * k + c];
    }
    loaded.push_back(a);
  }
  for (std::size_t k = 0; k < load.size(); ++k)
    if (!std::isfinite(load[k]))
      throw std::invalid_argument(fmt::format("set_loads: node {}: the forces given for it sum to {} N in {}",
                                              k % n, load[k], "xyz"[k / n]));
  std::sort(loaded.begin(), loaded.end());
  loaded.erase(std::unique(loaded.begin(), loaded.end()), loaded.end());
  do_set_loads(load);
  loaded_ = std::move(loaded);
}

void Backend::set_tools(std::span<const ToolShape> tools, const ContactOptions& options) {
  require_upload("set_tools");
  if (tools.size() > std::size_t(kMaxTools))
    throw std::invalid_argument(fmt::format("set_tools: {} tools; a scene holds at most {}", tools.size(), kMaxTools));
  for (const ToolShape& t : tools)
    if (const std::string e = tool_shape_error(t); !e.empty()) throw std::invalid_argument("set_tools: " + e);
  if (!(options.max_travel > 0) || !std::isfinite(options.max_travel))
    throw std::invalid_argument(
        fmt::format("set_tools: contact check spacing {} radii must be > 0", options.max_travel));
  do_reset_contacts();
  shapes_.assign(tools.begin(), tools.end());
  contact_options_ = options;
  motion_.assign(tools.size(), ToolMotion{});
  grasp_pose_.assign(tools.size(), ToolPose{});
  grasping_.assign(tools.size(), 0);
}

void Backend::set_body_contact(const BodyContactSpec& spec) {
  require_upload("set_body_contact");
  check_body_contact(spec, n_nodes_);
  do_set_body_contact(spec);
  body_spec_ = spec;
}

std::vector<BodyContactNode> Backend::body_contacts() {
  require_upload("body_contacts");
  return do_body_contacts();
}

void Backend::do_set_body_contact(const BodyContactSpec& spec) {
  if (!spec.empty()) throw std::invalid_argument(fmt::format("set_body_contact: the {} backend has no contact between bodies", name()));
}

void Backend::set_tool_friction(int tool, double friction) {
  require_upload("set_tool_friction");
  if (tool < 0 || tool >= n_tools())
    throw std::invalid_argument(fmt::format("set_tool_friction: tool {} of {} (set_tools first)", tool, n_tools()));
  if (const std::string e = tool_friction_error(shapes_[std::size_t(tool)].name, friction); !e.empty())
    throw std::invalid_argument("set_tool_friction: " + e);
  shapes_[std::size_t(tool)].friction = friction;
}

void Backend::move_tools(std::span<const ToolMotion> motion) {
  require_upload("move_tools");
  if (motion.size() != shapes_.size())
    throw std::invalid_argument(
        fmt::format("move_tools: {} motions for {} tools (set_tools first; one motion per tool)", motion.size(),
                    shapes_.size()));
  std::vector<ToolMotion> next(motion.size());
  for (std::size_t t = 0; t < motion.size(); ++t)
    next[t] = {checked_pose(motion[t].from, shapes_[t], "start"), checked_pose(motion[t].to, shapes_[t], "end"),
               motion[t].grasp};
  for (std::size_t t = 0; t < motion.size(); ++t) {
    if (next[t].grasp && !grasping_[t]) {
      grasp_pose_[t] = next[t].from;
      do_begin_grasp(static_cast<int>(t), next[t].from);
    } else if (!next[t].grasp && grasping_[t]) {
      do_end_grasp(static_cast<int>(t));
    }
    grasping_[t] = next[t].grasp;
  }
  motion_ = std::move(next);
}

ContactTools<double> Backend::contact_tools(int steps) const {
  ContactTools<double> c{};
  c.n_tools = static_cast<int>(shapes_.size());
  c.steps = std::max(steps, 1);
  c.face = contact_options_.face ? 1 : 0;
  for (int t = 0; t < c.n_tools; ++t) {
    const ToolMotion& m = motion_[t];
    ToolStep<double>& s = c.tool[t];
    s.tip0 = m.from.tip;
    s.axis0 = m.from.axis;
    s.tip1 = m.to.tip;
    s.axis1 = m.to.axis;
    s.radius = shapes_[t].radius;
    s.shaft = shapes_[t].shaft;
    s.substeps = contact_substeps(m.from, m.to, s.radius, s.shaft, c.steps, contact_options_.max_travel);
    c.sweep_substeps[t] = contact_substeps(m.from, m.to, s.radius, s.shaft, 1, contact_options_.max_travel);
    s.grasping = grasping_[t];
    s.grasp_tip = grasp_pose_[t].tip;
    s.grasp_axis = grasp_pose_[t].axis;
    s.friction = shapes_[t].friction;
  }
  return c;
}

std::vector<index_t> Backend::contact_candidates() {
  require_upload("contact_candidates");
  if (shapes_.empty()) return {};
  return do_contact_candidates(contact_tools(1));
}

std::vector<ContactNode> Backend::contacts() {
  require_upload("contacts");
  return do_contacts();
}

void Backend::element_pressure() {
  require_upload("element_pressure");
  do_element_pressure();
}

void Backend::nodal_pressure() {
  require_upload("nodal_pressure");
  do_nodal_pressure();
}

void Backend::element_forces() {
  require_upload("element_forces");
  do_element_forces();
  pass3_forces_ = true;
}

void Backend::node_update() {
  require_upload("node_update");
  if (!pass3_forces_)
    throw std::logic_error(fmt::format("{} backend: node_update() (pass 4) needs the element forces of a pass 3: call "
                                       "element_forces() first (after upload, a step or the previous node_update)",
                                       name()));
  do_node_update();
  pass3_forces_ = false;
}

void Backend::check_steps(const char* what, int steps) const {
  require_upload(what);
  if (steps < 0) throw std::invalid_argument(fmt::format("{}: step count {} must be >= 0", what, steps));
}

void Backend::steps_taken() {
  for (ToolMotion& m : motion_) m.from = m.to;
  pass3_forces_ = false;  // the steps' own passes 3 need not leave their forces for a pass 4
}

void Backend::advance(int steps) {
  check_steps("advance", steps);
  if (steps == 0) return;
  do_advance(steps, contact_tools(steps));
  steps_taken();
}

Reductions Backend::reduce() {
  require_upload("reduce");
  return do_reduce();
}

Reductions Backend::advance_reduce(int steps) {
  check_steps("advance_reduce", steps);
  if (steps == 0) return do_reduce();
  const Reductions r = do_advance_reduce(steps, contact_tools(steps));
  steps_taken();
  return r;
}

Reductions Backend::do_advance_reduce(int steps, const ContactTools<double>& tools) {
  do_advance(steps, tools);
  return do_reduce();
}

std::optional<Reductions> Backend::advance_reduce_in_region(int steps) {
  check_steps("advance_reduce_in_region", steps);
  if (shapes_.empty() || steps == 0) return advance_reduce(steps);
  std::optional<Reductions> r = do_advance_reduce_in_region(steps, contact_tools(steps));
  if (r) steps_taken();
  return r;
}

std::optional<Reductions> Backend::do_advance_reduce_in_region(int steps, const ContactTools<double>& tools) {
  if (!do_contact_candidates(contact_tools(1)).empty()) return std::nullopt;
  return do_advance_reduce(steps, tools);
}

void Backend::start_tick(int steps, bool in_region) {
  check_steps("start_tick", steps);
  in_region = in_region && !shapes_.empty();
  if (steps == 0) {
    pending_ = do_reduce();
  } else {
    do_start_tick(steps, contact_tools(steps), in_region);
  }
  pending_steps_ = steps > 0;
  tick_pending_ = true;
}

std::optional<Reductions> Backend::finish_tick() {
  if (!tick_pending_) throw std::logic_error(fmt::format("{} backend: finish_tick() without start_tick()", name()));
  tick_pending_ = false;
  std::optional<Reductions> r;
  if (pending_steps_) {
    r = do_finish_tick();
    if (r) steps_taken();
  } else {
    r = pending_;
  }
  pending_.reset();
  return r;
}

void Backend::do_start_tick(int steps, const ContactTools<double>& tools, bool in_region) {
  pending_ = in_region ? do_advance_reduce_in_region(steps, tools) : std::optional(do_advance_reduce(steps, tools));
}

std::optional<Reductions> Backend::do_finish_tick() { return pending_; }

Fields Backend::download() {
  require_upload("download");
  return do_download();
}

void Backend::write_positions(float* dst) {
  require_upload("write_positions");
  if (dst == nullptr)
    throw std::invalid_argument(fmt::format("write_positions: dst is null (need n_nodes x 3 floats of {} memory)",
                                            positions_on_device() ? "device" : "host"));
  do_write_positions(dst);
}

}  // namespace tissue
