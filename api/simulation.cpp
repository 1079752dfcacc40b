// The embedding facade (api/include/tissue/simulation.hpp): scene -> model ->
// backend -> Scheduler, with one host-driven device per tool.
#include "tissue/simulation.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <stdexcept>

#include "backends/registry.hpp"
#include "core/backend.hpp"
#include "core/device.hpp"
#include "core/scheduler.hpp"
#include "io/kidney.hpp"
#include "io/mesh_quality.hpp"
#include "io/organ_mesher.hpp"
#include "io/scene_xml.hpp"
#include "io/surface_import.hpp"
#include "scene/checks.hpp"
#include "scene/text.hpp"
#include "scene/validate.hpp"

#ifndef TISSUE_VERSION
#error "the build defines TISSUE_VERSION (api/CMakeLists.txt)"
#endif

namespace tissue {
namespace {

Vec3<double> vec(const Vector3& a) { return {a[0], a[1], a[2]}; }
Vector3 arr(const Vec3<double>& v) { return {v.x, v.y, v.z}; }

/// An interleaved copy (x y z per item) of a component-major array (all x, then all y, ...).
template <class T>
std::vector<T> interleave(const std::vector<T>& soa, std::size_t components) {
  const std::size_t n = soa.size() / components;
  std::vector<T> out(soa.size());
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t c = 0; c < components; ++c) out[components * i + c] = soa[c * n + i];
  return out;
}

bool finite3(const Vector3& a) { return std::isfinite(a[0]) && std::isfinite(a[1]) && std::isfinite(a[2]); }

/// A tool's device: the scene's scripted path until the host sets a pose,
/// the host's pose from then on. The grasp button is the path's or the
/// host's (either held).
class HostDevice final : public Device {
 public:
  explicit HostDevice(std::vector<Waypoint> path) : script_(std::move(path)) {}

  ToolInput read(double t) override {
    if (!host_) {
      ToolInput in = script_.read(t);
      in.grasp = in.grasp || grasp_;
      return in;
    }
    return {tip_, axis_, grasp_};
  }
  void send_force(const Vec3<double>&) override {}  // the Scheduler's report carries it

  void set_pose(Vec3<double> tip, Vec3<double> axis) {
    tip_ = tip;
    axis_ = axis;
    host_ = true;
  }
  void set_grasp(bool down) { grasp_ = down; }
  void follow_path() { host_ = false; }

 private:
  ScriptedDevice script_;
  bool host_ = false;
  bool grasp_ = false;
  Vec3<double> tip_ = {}, axis_ = {};
};

void apply(scene::Scene& s, const SimulationOptions& o) {
  if (!o.backend.empty()) s.solver.backend = o.backend;
  if (!o.precision.empty()) s.solver.precision = scene::parse_precision(o.precision);
  if (!o.depth.empty()) s.solver.depth = scene::parse_depth(o.depth);
}

/// The scene of a host's mesh: one material on every element, the fixed
/// nodes, and each tool parked above the body (one waypoint) until the host
/// moves it.
scene::Scene mesh_scene(const MeshScene& m) {
  scene::Scene s;
  s.source = m.name;
  if (m.nodes.size() % 3 != 0)
    throw std::invalid_argument(fmt::format("{}: {} node coordinates is not 3 per node", m.name, m.nodes.size()));
  if (m.tets.size() % 4 != 0)
    throw std::invalid_argument(fmt::format("{}: {} tet corner ids is not 4 per tetrahedron", m.name, m.tets.size()));
  if (m.tool_radii.empty() || m.tool_radii.size() > std::size_t(kMaxTools))
    throw std::invalid_argument(
        fmt::format("{}: {} tools given; a scene has 1 to {} tools", m.name, m.tool_radii.size(), kMaxTools));
  s.nodes = m.nodes;
  s.tets.assign(m.tets.begin(), m.tets.end());
  s.materials.push_back({.name = "tissue", .form = scene::Material::Form::YoungPoisson, .a = m.youngs_modulus,
                         .b = m.poisson_ratio, .rho = m.density});
  s.sets.push_back({.name = "all", .material = "tissue", .all = true, .elements = {}, .line = 0});
  if (!m.fixed_nodes.empty()) {
    scene::Constraint c;
    c.kind = scene::Constraint::Kind::Nodes;
    c.nodes.assign(m.fixed_nodes.begin(), m.fixed_nodes.end());
    s.constraints.push_back(c);
  }
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (std::size_t i = 0; i < m.nodes.size(); ++i) {
    lo[i % 3] = std::min(lo[i % 3], m.nodes[i]);
    hi[i % 3] = std::max(hi[i % 3], m.nodes[i]);
  }
  const double size = m.nodes.empty() ? 0 : std::hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
  for (std::size_t k = 0; k < m.tool_radii.size(); ++k) {
    scene::Tool t;
    t.name = fmt::format("tool{}", k);
    t.radius = m.tool_radii[k];
    t.shaft = m.tool_shaft;
    Waypoint park;  // held for a second, then the path holds its last point
    if (!m.nodes.empty())
      park.p = {0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), hi[2] + size + 2 * m.tool_radii[k] * (k + 1)};
    Waypoint still = park;
    still.t = 1;
    t.path = {park, still};
    s.tools.push_back(t);
  }
  return s;
}

}  // namespace

const char* version() { return TISSUE_VERSION; }

std::vector<std::string> available_backends() {
  std::vector<std::string> out;
  for (const BackendInfo& b : list_backends())
    if (b.available) out.push_back(b.name);
  return out;
}

int field_components(Field f) { return f == Field::Pressure || f == Field::Jacobian ? 1 : 3; }

VolumeMeshResult mesh_surface(const std::string& path, const std::string& unit, int target_tets) {
  if (target_tets < 0)
    throw std::invalid_argument(fmt::format("{}: target_tets = {} must be >= 0 (0 = the mesher's sizing)", path,
                                            target_tets));
  io::NamedSurface organ{io::load_surface(path, io::parse_unit(unit)), path};
  io::OrganMeshOptions o;
  o.meshing.min_dihedral = io::kDefaultMinDihedral;
  o.meshing.optimise = io::kDefaultOptimise;
  o.meshing.target_tets = target_tets;
  const io::OrganMesh r = io::mesh_organ(std::move(organ), {}, o);
  const MeshScene defaults;
  const scene::Solver solver;
  const MaterialParams params = scene::Material{.name = "tissue", .form = scene::Material::Form::YoungPoisson,
                                                .a = defaults.youngs_modulus, .b = defaults.poisson_ratio,
                                                .rho = defaults.density}
                                    .params();
  const io::QualityReport q = io::mesh_quality(r.mesh, {params}, std::vector<index_t>(r.mesh.n_tets(), 0), solver.tick,
                                               solver.dt_safety, solver.mass_scaling);
  return {r.mesh.nodes, {r.mesh.tets.begin(), r.mesh.tets.end()}, q.summary()};
}

struct Simulation::Impl {
  scene::Scene scene;
  TissueModel<double> model;
  std::unique_ptr<Backend> backend;
  std::unique_ptr<Scheduler> scheduler;
  SchedulerSettings settings;
  std::vector<HostDevice> devices;
  std::vector<Device*> device_ptrs;
  std::vector<std::string> warnings;
  TickResult last;
  std::optional<Fields> fields;  ///< this tick's download, on the first read
  std::string failure;           ///< why the last step threw; steps refused until reset()
  std::optional<std::pair<std::vector<index_t>, std::vector<double>>> loads;  ///< set_loads' (else the scene's)
  double dissipated = 0, visco_stored = 0;  ///< the last tick's TickReport
  // The reference mesh interleaved (the model stores it component-major).
  std::vector<double> rest;
  std::vector<std::int32_t> tets, tris;

  explicit Impl(scene::Scene s) : scene(std::move(s)), model(scene::load_model(scene)) {
    if (scene.tools.empty()) throw std::runtime_error(scene.source + ": the scene has no tool to drive");
    settings = scene::scheduler_settings(scene);
    warnings = scene::scene_warnings(scene, model);
    rest = interleave(model.X, 3);
    tets = interleave(model.elem_nodes, 4);
    tris = interleave(model.tris, 3);
    for (const scene::Tool& t : scene.tools) devices.emplace_back(t.path);
    for (HostDevice& d : devices) device_ptrs.push_back(&d);
    backend = create_backend(scene.solver.backend, scene.solver.precision);
    start();
  }

  void start() {
    scheduler.reset();
    backend->upload(model);
    scheduler = std::make_unique<Scheduler>(*backend, model, settings);
    if (loads)
      scheduler->set_loads(loads->first, loads->second);
    else
      scene::apply_loads(scene, model, *scheduler);
    dissipated = visco_stored = 0;
    last = TickResult{};
    last.tools.resize(devices.size());
    fields.reset();
    failure.clear();
  }

  void check_tool(int tool) const {
    if (tool < 0 || tool >= int(devices.size()))
      throw std::invalid_argument(fmt::format("{}: tool {} does not exist (the scene has {} tool{}: 0..{})",
                                              scene.source, tool, devices.size(), devices.size() == 1 ? "" : "s",
                                              devices.size() - 1));
  }

  void tick() {
    TickReport r;
    try {
      r = scheduler->tick(device_ptrs);
    } catch (const SimulationError& e) {
      failure = e.what();
      throw;
    }
    last.tick = scheduler->ticks();
    last.time = r.time;
    last.steps = r.steps;
    for (int k = 0; k < r.n_tools; ++k) {
      const ToolReport& t = r.tools[k];
      last.tools[k] = {arr(t.tip), arr(t.axis), arr(t.force), int(t.contact_nodes), int(t.grasped), t.grasp};
    }
    last.max_displacement = r.max_disp;
    last.residual = r.residual;
    last.equilibrium = r.equilibrium;
    last.region_nodes = int(r.region_nodes);
    last.region_elements = int(r.region_elems);
    dissipated = r.dissipated;
    visco_stored = r.visco_stored;
  }

  const Fields& snapshot() {
    if (!fields) fields = backend->download();
    return *fields;
  }
};

Simulation::Simulation(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Simulation::Simulation(Simulation&&) noexcept = default;
Simulation& Simulation::operator=(Simulation&&) noexcept = default;
Simulation::~Simulation() = default;

Simulation Simulation::load(const std::string& path, const SimulationOptions& options) {
  std::optional<scene::Scene> builtin = io::builtin_scene(path);
  scene::Scene s = builtin ? std::move(*builtin) : io::read_scene(path);
  apply(s, options);
  return Simulation(std::make_unique<Impl>(std::move(s)));
}

Simulation Simulation::from_mesh(const MeshScene& mesh, const SimulationOptions& options) {
  scene::Scene s = mesh_scene(mesh);
  apply(s, options);
  return Simulation(std::make_unique<Impl>(std::move(s)));
}

std::string Simulation::name() const { return impl_->scene.source; }
std::string Simulation::backend() const { return impl_->backend->name(); }
std::string Simulation::precision() const { return to_string(impl_->backend->precision()); }
std::string Simulation::device_name() const { return impl_->backend->device_name(); }
std::size_t Simulation::n_nodes() const { return std::size_t(impl_->model.n_nodes); }
std::size_t Simulation::n_elements() const { return std::size_t(impl_->model.n_elems); }
std::size_t Simulation::n_surface_triangles() const { return std::size_t(impl_->model.n_tris); }
int Simulation::n_tools() const { return int(impl_->devices.size()); }
double Simulation::tick_seconds() const { return impl_->settings.tick; }
int Simulation::steps_per_tick() const { return impl_->scheduler->steps_per_tick(); }
double Simulation::dt() const { return impl_->model.dt; }
const std::vector<std::string>& Simulation::warnings() const { return impl_->warnings; }

std::span<const double> Simulation::rest_positions() const { return impl_->rest; }
std::span<const std::int32_t> Simulation::tetrahedra() const { return impl_->tets; }
std::span<const std::int32_t> Simulation::surface_triangles() const { return impl_->tris; }

void Simulation::set_tool_pose(int tool, const Vector3& tip, const Vector3& axis) {
  impl_->check_tool(tool);
  if (!finite3(tip) || !finite3(axis))
    throw std::invalid_argument(fmt::format("{}: tool {} pose tip ({}, {}, {}) m axis ({}, {}, {}) is not finite",
                                            name(), tool, tip[0], tip[1], tip[2], axis[0], axis[1], axis[2]));
  impl_->devices[tool].set_pose(vec(tip), vec(axis));
}

void Simulation::set_grasp(int tool, bool down) {
  impl_->check_tool(tool);
  impl_->devices[tool].set_grasp(down);
}

void Simulation::set_loads(std::span<const std::int32_t> nodes, std::span<const double> forces) {
  std::vector<index_t> ids(nodes.begin(), nodes.end());
  std::vector<double> f(forces.begin(), forces.end());
  try {
    impl_->scheduler->set_loads(ids, f);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(fmt::format("{}: {}", name(), e.what()));
  }
  impl_->loads.emplace(std::move(ids), std::move(f));
}

double Simulation::dissipated_energy() const { return impl_->dissipated; }
double Simulation::viscous_stored_energy() const { return impl_->visco_stored; }

void Simulation::follow_scene_path(int tool) {
  impl_->check_tool(tool);
  impl_->devices[tool].follow_path();
}

double Simulation::tool_radius(int tool) const {
  impl_->check_tool(tool);
  return impl_->scene.tools[tool].radius;
}

double Simulation::tool_shaft(int tool) const {
  impl_->check_tool(tool);
  return impl_->scene.tools[tool].shaft;
}

TickResult Simulation::step(long ticks) {
  if (ticks < 1) throw std::invalid_argument(fmt::format("{}: step({}): the tick count must be >= 1", name(), ticks));
  if (!impl_->failure.empty())
    throw SimulationError(fmt::format("{}: the simulation stopped at tick {} ({}); call reset() to start again",
                                      name(), impl_->last.tick, impl_->failure));
  impl_->fields.reset();
  for (long k = 0; k < ticks; ++k) impl_->tick();
  return impl_->last;
}

const TickResult& Simulation::last() const { return impl_->last; }

Vector3 Simulation::force(int tool) const {
  impl_->check_tool(tool);
  return impl_->last.tools[tool].force;
}

long Simulation::ticks() const { return impl_->scheduler->ticks(); }
double Simulation::time() const { return impl_->scheduler->time(); }
void Simulation::reset() { impl_->start(); }
std::vector<std::string> Simulation::take_notes() { return impl_->scheduler->take_notes(); }

void Simulation::read_field(Field f, std::span<double> out) {
  const std::size_t n = (f == Field::Jacobian ? n_elements() : n_nodes()) * std::size_t(field_components(f));
  if (out.size() != n)
    throw std::invalid_argument(fmt::format("{}: the field needs {} values ({} {} x {}), the buffer holds {}", name(), n,
                                            f == Field::Jacobian ? n_elements() : n_nodes(),
                                            f == Field::Jacobian ? "elements" : "nodes", field_components(f),
                                            out.size()));
  const Fields& s = impl_->snapshot();
  const std::size_t nn = n_nodes();
  auto nodal3 = [&](const std::vector<double>& soa, const double* base) {  // component-major -> x y z per node
    for (std::size_t i = 0; i < nn; ++i)
      for (std::size_t c = 0; c < 3; ++c) out[3 * i + c] = soa[c * nn + i] + (base ? base[3 * i + c] : 0.0);
  };
  switch (f) {
    case Field::Displacement: nodal3(s.u, nullptr); break;
    case Field::Position: nodal3(s.u, impl_->rest.data()); break;
    case Field::Pressure: std::copy(s.node_p.begin(), s.node_p.end(), out.begin()); break;
    case Field::InternalForce: nodal3(s.f, nullptr); break;
    case Field::Jacobian: std::copy(s.elem_J.begin(), s.elem_J.end(), out.begin()); break;
  }
}

std::vector<double> Simulation::field(Field f) {
  std::vector<double> out((f == Field::Jacobian ? n_elements() : n_nodes()) * std::size_t(field_components(f)));
  read_field(f, out);
  return out;
}

void Simulation::write_positions(float* dst) {
  if (dst == nullptr) throw std::invalid_argument(name() + ": write_positions: the destination is null");
  impl_->backend->write_positions(dst);
}

bool Simulation::positions_on_device() const { return impl_->backend->positions_on_device(); }

}  // namespace tissue
