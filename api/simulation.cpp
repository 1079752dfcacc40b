// The embedding facade (api/include/tissue/simulation.hpp): scene -> model ->
// backend -> Scheduler, with one host-driven device per tool.
#include "tissue/simulation.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <stdexcept>
#include <string_view>

#include "api/facade.hpp"
#include "backends/registry.hpp"
#include "core/backend.hpp"
#include "core/scheduler.hpp"
#include "io/kidney.hpp"
#include "io/mesh_quality.hpp"
#include "io/organ_mesher.hpp"
#include "core/cut.hpp"
#include "io/scene_xml.hpp"
#include "io/surface_import.hpp"
#include "scene/checks.hpp"
#include "scene/text.hpp"
#include "scene/validate.hpp"
#include "session/session.hpp"

#ifndef TISSUE_VERSION
#error "the build defines TISSUE_VERSION (api/CMakeLists.txt)"
#endif

namespace tissue {
namespace {

using facade::finite3;
using facade::interleave;
using facade::set_tick_result;
using facade::vec;

void apply(scene::Scene& s, const SimulationOptions& o) {
  if (!o.backend.empty()) s.solver.backend = o.backend;
  if (!o.precision.empty()) s.solver.precision = scene::parse_precision(o.precision);
  if (!o.depth.empty()) s.solver.depth = scene::parse_depth(o.depth);
}

}  // namespace

namespace facade {

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

}  // namespace facade

const char* version() { return TISSUE_VERSION; }

std::vector<std::string> available_backends() {
  std::vector<std::string> out;
  for (const BackendInfo& b : list_backends())
    if (b.available) out.push_back(b.name);
  return out;
}

int field_components(Field f) {
  switch (f) {
#define TISSUE_FIELD_COMPONENTS(c_name, cpp_name, python, per, components, unit, what) \
  case Field::cpp_name:                                                                \
    return components;
    TISSUE_FIELD_LIST(TISSUE_FIELD_COMPONENTS)
#undef TISSUE_FIELD_COMPONENTS
  }
  throw std::invalid_argument(fmt::format("field {} is not a tissue::Field", int(f)));
}

bool field_per_element(Field f) {
  switch (f) {
#define TISSUE_FIELD_PER(c_name, cpp_name, python, per, components, unit, what) \
  case Field::cpp_name:                                                         \
    return std::string_view(#per) == "ELEMENT";
    TISSUE_FIELD_LIST(TISSUE_FIELD_PER)
#undef TISSUE_FIELD_PER
  }
  throw std::invalid_argument(fmt::format("field {} is not a tissue::Field", int(f)));
}

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

namespace facade {

CutOptions cut_options(const std::string& method) {
  CutOptions o;
  if (method == "snap")
    o.method = CutMethod::Snap;
  else if (method == "split")
    o.method = CutMethod::Split;
  else if (method != "snap-split")
    throw std::invalid_argument(fmt::format("cut: method '{}': expected snap-split, snap or split", method));
  return o;
}

}  // namespace facade

CutMeshResult cut_mesh(std::span<const double> nodes, std::span<const std::int32_t> tets, const Vector3& origin,
                       const Vector3& edge, const Vector3& sweep, const std::string& method) {
  const CutOptions o = facade::cut_options(method);
  const CutResult r = tissue::cut_along(nodes, tets, {facade::vec(origin), facade::vec(edge), facade::vec(sweep)}, o);
  CutMeshResult out;
  out.nodes = r.nodes;
  out.tets.assign(r.tets.begin(), r.tets.end());
  for (const auto& [a, b] : r.from) out.node_from.insert(out.node_from.end(), {a, b});
  out.weight = r.weight;
  out.element_from.assign(r.element_from.begin(), r.element_from.end());
  out.pieces_split = r.split;
  out.nodes_snapped = r.snapped;
  out.nodes_copied = r.copies;
  out.faces_opened = r.cut_faces;
  out.left_whole = r.unresolved;
  return out;
}

struct Simulation::Impl {
  Session session;
  std::vector<std::string> warnings;
  TickResult last;
  // The reference mesh interleaved (the model stores it component-major).
  std::vector<double> rest;
  std::vector<std::int32_t> tets, tris;

  explicit Impl(scene::Scene s) : session(std::move(s)) {
    warnings = scene::scene_warnings(session.scene(), session.model());
    mesh_changed();
    set_tick_result(last, session.last(), 0);
  }

  std::uint64_t mesh_version = 0;

  /// The interleaved copies of the model's mesh (after loading, each cut and a reset after one).
  void mesh_changed() {
    ++mesh_version;
    const TissueModel<double>& model = session.model();
    rest = interleave(model.X, 3);
    tets = interleave(model.elem_nodes, 4);
    tris = interleave(model.tris, 3);
  }

  void tick() {
    const long cuts = session.cuts();
    session.tick();
    if (session.cuts() != cuts) mesh_changed();  // a blade cut the tissue
    set_tick_result(last, session.last(), session.scheduler().ticks());
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
  scene::Scene s = facade::mesh_scene(mesh);
  apply(s, options);
  return Simulation(std::make_unique<Impl>(std::move(s)));
}

std::string Simulation::name() const { return impl_->session.name(); }
std::string Simulation::backend() const { return impl_->session.backend().name(); }
std::string Simulation::precision() const { return to_string(impl_->session.backend().precision()); }
std::string Simulation::device_name() const { return impl_->session.backend().device_name(); }
std::size_t Simulation::n_nodes() const { return std::size_t(impl_->session.model().n_nodes); }
std::size_t Simulation::n_elements() const { return std::size_t(impl_->session.model().n_elems); }
std::vector<BodyRange> Simulation::bodies() const {
  return facade::body_ranges(impl_->session.scene(), n_nodes(), n_elements());
}
std::vector<BodyContact> Simulation::body_contacts() const {
  return facade::body_contacts(impl_->session.backend(), impl_->session.model(), bodies());
}
std::size_t Simulation::n_surface_triangles() const { return std::size_t(impl_->session.model().n_tris); }
int Simulation::n_tools() const { return impl_->session.n_tools(); }
double Simulation::tick_seconds() const { return impl_->session.settings().tick; }
int Simulation::steps_per_tick() const { return impl_->session.scheduler().steps_per_tick(); }
double Simulation::dt() const { return impl_->session.model().dt; }
const std::vector<std::string>& Simulation::warnings() const { return impl_->warnings; }

std::span<const double> Simulation::rest_positions() const { return impl_->rest; }
std::uint64_t Simulation::mesh_version() const { return impl_->mesh_version; }
std::span<const std::int32_t> Simulation::tetrahedra() const { return impl_->tets; }
std::span<const std::int32_t> Simulation::surface_triangles() const { return impl_->tris; }

void Simulation::set_tool_pose(int tool, const Vector3& tip, const Vector3& axis) {
  impl_->session.set_tool_pose(tool, vec(tip), vec(axis));
}

void Simulation::set_grasp(int tool, bool down) {
  impl_->session.check_tool(tool);
  impl_->session.device(tool).set_grasp(down);
}

void Simulation::set_loads(std::span<const std::int32_t> nodes, std::span<const double> forces) {
  impl_->session.set_loads({nodes.begin(), nodes.end()}, {forces.begin(), forces.end()});
}

double Simulation::dissipated_energy() const { return impl_->session.last().dissipated; }
double Simulation::viscous_stored_energy() const { return impl_->session.last().visco_stored; }

void Simulation::follow_scene_path(int tool) {
  impl_->session.check_tool(tool);
  impl_->session.device(tool).follow_path();
}

double Simulation::tool_radius(int tool) const {
  impl_->session.check_tool(tool);
  return impl_->session.scene().tools[tool].radius;
}

double Simulation::tool_shaft(int tool) const {
  impl_->session.check_tool(tool);
  return impl_->session.scene().tools[tool].shaft;
}

double Simulation::tool_friction(int tool) const { return impl_->session.tool_friction(tool); }

void Simulation::set_tool_friction(int tool, double mu) { impl_->session.set_tool_friction(tool, mu); }

TickResult Simulation::step(long ticks) {
  if (ticks < 1) throw std::invalid_argument(fmt::format("{}: step({}): the tick count must be >= 1", name(), ticks));
  for (long k = 0; k < ticks; ++k) impl_->tick();
  return impl_->last;
}

const TickResult& Simulation::last() const { return impl_->last; }

Vector3 Simulation::force(int tool) const {
  impl_->session.check_tool(tool);
  return impl_->last.tools[tool].force;
}

long Simulation::ticks() const { return impl_->session.scheduler().ticks(); }
double Simulation::time() const { return impl_->session.scheduler().time(); }

CutStats Simulation::cut(const Vector3& origin, const Vector3& edge, const Vector3& sweep, const std::string& method) {
  if (!finite3(origin) || !finite3(edge) || !finite3(sweep))
    throw std::invalid_argument(fmt::format("{}: cut: origin, edge and sweep must be finite (m)", name()));
  SessionCut c;
  try {
    c = impl_->session.cut({vec(origin), vec(edge), vec(sweep)}, facade::cut_options(method));
  } catch (const CutError& e) {
    throw std::invalid_argument(fmt::format("{}: {}", name(), e.what()));
  } catch (const scene::SceneError& e) {
    throw std::invalid_argument(e.what());
  } catch (const ModelError& e) {
    throw std::invalid_argument(fmt::format("{}: the cut mesh is refused: {}", name(), e.what()));
  }
  impl_->mesh_changed();
  CutStats out;
  out.nodes_before = std::size_t(c.nodes_before);
  out.elements_before = std::size_t(c.elements_before);
  out.nodes = n_nodes();
  out.elements = n_elements();
  out.pieces_split = c.cut.split;
  out.nodes_snapped = c.cut.snapped;
  out.nodes_copied = c.cut.copies;
  out.faces_opened = c.cut.cut_faces;
  out.left_whole = c.cut.unresolved;
  out.dt_before = c.dt_before;
  out.dt_after = c.dt_after;
  return out;
}

void Simulation::reset() {
  const bool cut = impl_->session.was_cut();
  impl_->session.restart();
  if (cut) impl_->mesh_changed();
  set_tick_result(impl_->last, impl_->session.last(), 0);
}

std::vector<std::string> Simulation::take_notes() { return impl_->session.scheduler().take_notes(); }

void Simulation::read_field(Field f, std::span<double> out) {
  const std::size_t n = facade::field_size(f, n_nodes(), n_elements());
  if (out.size() != n)
    throw std::invalid_argument(fmt::format("{}: the field needs {} values ({} {} x {}), the buffer holds {}", name(), n,
                                            field_per_element(f) ? n_elements() : n_nodes(),
                                            field_per_element(f) ? "elements" : "nodes", field_components(f),
                                            out.size()));
  facade::copy_field(impl_->session.fields(), impl_->rest, f, out);
}

std::vector<double> Simulation::field(Field f) {
  std::vector<double> out(facade::field_size(f, n_nodes(), n_elements()));
  read_field(f, out);
  return out;
}

void Simulation::write_positions(float* dst) {
  if (dst == nullptr) throw std::invalid_argument(name() + ": write_positions: the destination is null");
  impl_->session.backend().write_positions(dst);
}

bool Simulation::positions_on_device() const { return impl_->session.backend().positions_on_device(); }

}  // namespace tissue
