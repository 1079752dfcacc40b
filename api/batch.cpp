// The batch facade (api/include/tissue/batch.hpp) over the engine's
// SceneBatch (session/scene_batch.hpp).
#include "tissue/batch.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <optional>
#include <stdexcept>

#include "api/facade.hpp"
#include "backends/registry.hpp"
#include "io/kidney.hpp"
#include "io/scene_xml.hpp"
#include "scene/checks.hpp"
#include "scene/text.hpp"
#include "scene/validate.hpp"
#include "session/scene_batch.hpp"

namespace tissue {
namespace {

using facade::finite3;
using facade::set_tick_result;
using facade::vec;

scene::Scene read_any(const std::string& path) {
  std::optional<scene::Scene> builtin = io::builtin_scene(path);
  return builtin ? std::move(*builtin) : io::read_scene(path);
}

/// Applies a material change to the scene (validated later with the scene).
void change_material(scene::Scene& s, const MaterialChange& c) {
  bool found = false;
  for (scene::Material& m : s.materials) {
    if (!c.material.empty() && m.name != c.material) continue;
    found = true;
    if (c.youngs_modulus || c.poisson_ratio) {
      if (m.form != scene::Material::Form::YoungPoisson) {  // the material's (E, nu), from its (mu, K)
        const MaterialParams p = m.params();
        m.a = youngs_modulus(p);
        m.b = poisson_ratio(p);
        m.form = scene::Material::Form::YoungPoisson;
      }
      m.a = c.youngs_modulus.value_or(m.a);
      m.b = c.poisson_ratio.value_or(m.b);
    }
    if (c.density) m.rho = *c.density;
    if (c.fibre_stiffness) {
      const bool has_fibre = m.fibre_eta > 0 || m.fibre_line > 0 || m.fibre_field != scene::Material::FibreField::Uniform;
      if (!has_fibre && *c.fibre_stiffness != 0)
        throw std::invalid_argument(fmt::format("{}: material '{}' has no <fibre>: a fibre stiffness needs the "
                                                "fibres' directions, which only the scene gives",
                                                s.source, m.name));
      m.fibre_eta = *c.fibre_stiffness;
    }
    for (const PronyChange& p : c.prony) {
      const int n = int(m.prony.size());
      if (p.term < 1 || p.term > n + 1)
        throw std::invalid_argument(fmt::format("{}: material '{}': Prony term {} does not exist (it has {}; "
                                                "term {} would add one)",
                                                s.source, m.name, p.term, n, n + 1));
      if (p.term == n + 1) {
        if (!p.g || !p.tau)
          throw std::invalid_argument(fmt::format("{}: material '{}': the new Prony term {} needs both g and tau",
                                                  s.source, m.name, p.term));
        m.prony.push_back({*p.g, *p.tau, 0});
      } else {
        scene::Material::Prony& t = m.prony[std::size_t(p.term - 1)];
        t.g = p.g.value_or(t.g);
        t.tau = p.tau.value_or(t.tau);
      }
    }
    scene::validate_material(s, m);
  }
  if (!found) {
    std::vector<std::string> names;
    for (const scene::Material& m : s.materials) names.push_back("'" + m.name + "'");
    throw std::invalid_argument(
        fmt::format("{}: no material '{}' (the scene has {})", s.source, c.material, fmt::join(names, ", ")));
  }
}

}  // namespace

struct Batch::Impl {
  std::unique_ptr<SceneBatch> batch;
  std::vector<std::shared_ptr<const scene::Scene>> scenes;  ///< each scene as loaded, before its material changes
  std::vector<std::vector<MaterialChange>> changes;         ///< each scene's changes so far
  std::vector<TickResult> last;
  std::vector<std::optional<std::vector<std::string>>> warnings;   ///< on the first request
  std::map<const TissueModel<double>*, std::vector<double>> rest;  ///< interleaved reference positions per model

  Session& at(int scene) {
    check(scene);
    return (*batch)[std::size_t(scene)];
  }
  const Session& at(int scene) const {
    check(scene);
    return (*batch)[std::size_t(scene)];
  }
  void check(int scene) const {
    if (scene < 0 || std::size_t(scene) >= batch->size())
      throw std::invalid_argument(fmt::format("scene {} does not exist (the batch has {} scene{}: 0..{})", scene,
                                              batch->size(), batch->size() == 1 ? "" : "s", batch->size() - 1));
  }
  void check_tool(int scene, int tool) const { at(scene).check_tool(tool); }
  void update(std::size_t i) {
    Session& s = (*batch)[i];
    set_tick_result(last[i], s.last(), s.scheduler().ticks());
  }
  const std::vector<double>& rest_of(const Session& s) {
    auto it = rest.find(&s.model());
    if (it == rest.end()) it = rest.emplace(&s.model(), facade::interleave(s.model().X, 3)).first;
    return it->second;
  }
};

Batch::Batch(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}
Batch::Batch(Batch&&) noexcept = default;
Batch& Batch::operator=(Batch&&) noexcept = default;
Batch::~Batch() = default;

Batch Batch::load(const std::vector<BatchScene>& list, const SimulationOptions& options) {
  if (list.empty()) throw std::invalid_argument("Batch::load: no scenes given (a batch needs at least one)");
  check_batch_size(list.size());
  auto impl = std::make_unique<Impl>();
  std::map<std::string, std::shared_ptr<scene::Scene>> read;  // each file read once, its scene shared
  std::vector<std::shared_ptr<const scene::Scene>> ready;
  for (std::size_t i = 0; i < list.size(); ++i) {
    std::shared_ptr<scene::Scene> s;
    try {
      if (list[i].mesh) {
        s = std::make_shared<scene::Scene>(facade::mesh_scene(*list[i].mesh));
      } else {
        auto it = read.find(list[i].scene);
        if (it == read.end())
          it = read.emplace(list[i].scene, std::make_shared<scene::Scene>(read_any(list[i].scene))).first;
        s = it->second;
      }
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(fmt::format("batch scene {}: {}", i, e.what()));
    }
    if (!options.depth.empty()) s->solver.depth = scene::parse_depth(options.depth);
    impl->scenes.push_back(s);
    impl->changes.push_back(list[i].materials);
    if (list[i].materials.empty()) {
      ready.push_back(s);
      continue;
    }
    auto changed = std::make_shared<scene::Scene>(*s);
    try {
      for (const MaterialChange& c : list[i].materials) change_material(*changed, c);
    } catch (const std::exception& e) {
      throw std::invalid_argument(fmt::format("batch scene {}: {}", i, e.what()));
    }
    ready.push_back(std::move(changed));
  }
  const scene::Solver& first = ready.front()->solver;
  const std::string backend = options.backend.empty() ? first.backend : options.backend;
  const Precision precision = options.precision.empty() ? first.precision : scene::parse_precision(options.precision);
  impl->batch = std::make_unique<SceneBatch>(ready, backend, precision);
  const std::size_t n = impl->batch->size();
  impl->last.resize(n);
  impl->warnings.resize(n);
  for (std::size_t i = 0; i < n; ++i) impl->update(i);
  return Batch(std::move(impl));
}

Batch Batch::load(const std::string& scene, int copies, const SimulationOptions& options) {
  if (copies < 1) throw std::invalid_argument(fmt::format("Batch::load: copies = {} must be >= 1", copies));
  check_batch_size(std::size_t(copies));  // before a list of that many is made
  return load(std::vector<BatchScene>(std::size_t(copies), BatchScene{scene, {}, {}}), options);
}

std::size_t Batch::size() const {
  return impl_->batch->size();
}
std::string Batch::backend() const {
  return impl_->batch->backend_name();
}
std::string Batch::precision() const {
  return to_string(impl_->batch->precision());
}
std::string Batch::device_name() const {
  return (*impl_->batch)[0].backend().device_name();
}
int Batch::max_tools() const {
  return impl_->batch->max_tools();
}
std::size_t Batch::distinct_models() const {
  return impl_->batch->distinct_models();
}
std::int64_t Batch::scene_host_bytes() const {
  return impl_->batch->memory().per_scene_host;
}
std::int64_t Batch::scene_device_bytes() const {
  return impl_->batch->memory().per_scene_device;
}
std::size_t Batch::groups() const {
  return impl_->batch->groups();
}
std::int64_t Batch::ticks_together() const {
  return impl_->batch->ticks_together();
}

std::string Batch::name(int scene) const {
  return impl_->at(scene).name();
}
std::size_t Batch::n_nodes(int scene) const {
  return std::size_t(impl_->at(scene).model().n_nodes);
}
std::size_t Batch::n_elements(int scene) const {
  return std::size_t(impl_->at(scene).model().n_elems);
}
std::vector<BodyRange> Batch::bodies(int scene) const {
  return facade::body_ranges(impl_->at(scene).scene(), n_nodes(scene), n_elements(scene));
}
std::vector<BodyContact> Batch::body_contacts(int scene) const {
  Session& s = impl_->at(scene);
  return facade::body_contacts(s.backend(), s.model(), bodies(scene));
}
int Batch::n_tools(int scene) const {
  return impl_->at(scene).n_tools();
}
int Batch::steps_per_tick(int scene) const {
  return impl_->at(scene).scheduler().steps_per_tick();
}
double Batch::dt(int scene) const {
  return impl_->at(scene).model().dt;
}
double Batch::tick_seconds(int scene) const {
  return impl_->at(scene).settings().tick;
}

double Batch::path_end(int scene) const {
  double end = 0;
  for (const scene::Tool& t : impl_->at(scene).scene().tools)
    if (!t.path.empty()) end = std::max(end, t.path.back().t);
  return end;
}

const std::vector<std::string>& Batch::warnings(int scene) const {
  const Session& s = impl_->at(scene);
  auto& w = impl_->warnings[std::size_t(scene)];
  if (!w) w = scene::scene_warnings(s.scene(), s.model());
  return *w;
}

void Batch::set_material(int scene, const MaterialChange& change) {
  impl_->check(scene);
  const std::size_t i = std::size_t(scene);
  auto s = std::make_shared<scene::Scene>(*impl_->scenes[i]);
  std::vector<MaterialChange> changes = impl_->changes[i];
  changes.push_back(change);
  try {
    for (const MaterialChange& c : changes) change_material(*s, c);
  } catch (const std::exception& e) {
    throw std::invalid_argument(fmt::format("batch scene {}: {}", scene, e.what()));
  }
  impl_->batch->replace(i, std::move(s));
  impl_->changes[i] = std::move(changes);
  impl_->warnings[i].reset();
  impl_->update(i);
}

void Batch::set_tool_friction(int scene, int tool, double mu) { impl_->at(scene).set_tool_friction(tool, mu); }

double Batch::tool_friction(int scene, int tool) const { return impl_->at(scene).tool_friction(tool); }

void Batch::set_tool_pose(int scene, int tool, const Vector3& tip, const Vector3& axis) {
  impl_->at(scene).set_tool_pose(tool, vec(tip), vec(axis));
}

void Batch::set_tool_poses_from_device(std::uintptr_t tips, std::size_t count, bool single) {
  const std::size_t need = size() * std::size_t(max_tools()) * 3;
  if (count != need)
    throw std::invalid_argument(fmt::format(
        "set_tool_poses: the device array holds {} values; the batch needs {} ({} scenes x {} tools x 3)", count, need,
        size(), max_tools()));
  std::vector<double> host(need);
  if (single) {
    std::vector<float> f(need);
    copy_from_device(reinterpret_cast<const void*>(tips), f.data(), need * sizeof(float));
    std::copy(f.begin(), f.end(), host.begin());
  } else {
    copy_from_device(reinterpret_cast<const void*>(tips), host.data(), need * sizeof(double));
  }
  set_tool_poses(host);
}

Batch::DeviceView Batch::device_field(int scene, Field f) {
  impl_->check(scene);
  if (f != Field::Displacement && f != Field::InternalForce)
    throw std::invalid_argument("device_field: only the displacement and the internal force lie on the device "
                                "per node (read the others with read_field)");
  Session& s = (*impl_->batch)[std::size_t(scene)];
  const DeviceField d = tissue::device_field(
      s.backend(), f == Field::Displacement ? NodeField::Displacement : NodeField::InternalForce);
  if (!d.data)
    throw std::invalid_argument(fmt::format("device_field: the {} backend keeps its fields on the host; read them with "
                                            "read_field or fields()",
                                            backend()));
  DeviceView v;
  v.data = reinterpret_cast<std::uintptr_t>(d.data);
  v.shape = {d.nodes, 3};
  v.strides = {d.node_stride, d.scalar_bytes};
  v.scalar_bytes = d.scalar_bytes;
  v.device = d.device;
  return v;
}

Batch::DeviceView Batch::device_field(Field f) {
  DeviceView first = device_field(0, f);
  const std::int64_t n = std::int64_t(size());
  std::int64_t stride = 0;
  if (n > 1) {
    const DeviceView second = device_field(1, f);
    stride = std::int64_t(second.data) - std::int64_t(first.data);
  }
  for (std::int64_t i = 1; i < n; ++i) {
    const DeviceView v = device_field(int(i), f);
    if (v.shape != first.shape || stride <= 0 || std::int64_t(v.data) != std::int64_t(first.data) + i * stride)
      throw std::invalid_argument(fmt::format(
          "device_field: scene {}'s field does not lie one stride after scene {}'s ({}); every scene's at once "
          "needs scenes of one model stepped in one group (docs/batch.md); read scenes one by one with "
          "device_field(scene, field)",
          i, i - 1, v.shape != first.shape ? "another mesh" : "another model, or a scene outside the group"));
  }
  first.shape.insert(first.shape.begin(), n);
  first.strides.insert(first.strides.begin(), n > 1 ? stride : first.shape[1] * first.strides[0]);
  return first;
}

void Batch::set_tool_poses(std::span<const double> tips, std::span<const double> axes) {
  const std::size_t n = size(), t = std::size_t(max_tools()), need = n * t * 3;
  if (tips.size() != need)
    throw std::invalid_argument(
        fmt::format("set_tool_poses: tips hold {} values; the batch needs {} ({} scenes x {} "
                    "tools x 3)",
                    tips.size(), need, n, t));
  if (!axes.empty() && axes.size() != need)
    throw std::invalid_argument(
        fmt::format("set_tool_poses: axes hold {} values; the batch needs {} ({} scenes x {} "
                    "tools x 3) or none",
                    axes.size(), need, n, t));
  // every pose checked before any is set: a refused array changes nothing
  auto pose = [&](std::size_t i, int k) {
    const std::size_t o = 3 * (i * t + std::size_t(k));
    const Vec3<double> axis = axes.empty() ? Vec3<double>{0, 0, 0} : Vec3<double>{axes[o], axes[o + 1], axes[o + 2]};
    return std::pair(Vec3<double>{tips[o], tips[o + 1], tips[o + 2]}, axis);
  };
  for (std::size_t i = 0; i < n; ++i) {
    const Session& s = (*impl_->batch)[i];
    for (int k = 0; k < s.n_tools(); ++k) try {
        const auto [tip, axis] = pose(i, k);
        s.check_tool_pose(k, tip, axis);
      } catch (const std::invalid_argument& e) {
        throw std::invalid_argument(fmt::format("set_tool_poses: scene {}: {}", i, e.what()));
      }
  }
  for (std::size_t i = 0; i < n; ++i) {
    Session& s = (*impl_->batch)[i];
    for (int k = 0; k < s.n_tools(); ++k) {
      const auto [tip, axis] = pose(i, k);
      s.device(k).set_pose(tip, axis);
    }
  }
}

void Batch::set_grasp(int scene, int tool, bool down) {
  impl_->check_tool(scene, tool);
  impl_->at(scene).device(tool).set_grasp(down);
}

void Batch::set_tool_path(int scene, int tool, const std::vector<PathPoint>& path) {
  impl_->check_tool(scene, tool);
  std::vector<Waypoint> w;
  for (const PathPoint& p : path) w.push_back({p.t, vec(p.tip), p.grasp, vec(p.axis)});
  try {
    impl_->at(scene).device(tool).set_path(std::move(w));
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(fmt::format("scene {} tool {}: {}", scene, tool, e.what()));
  }
}

void Batch::follow_scene_path(int scene, int tool) {
  impl_->check_tool(scene, tool);
  impl_->at(scene).device(tool).follow_path();
}

void Batch::set_loads(int scene, std::span<const std::int32_t> nodes, std::span<const double> forces) {
  impl_->at(scene).set_loads({nodes.begin(), nodes.end()}, {forces.begin(), forces.end()});
}

std::size_t Batch::step(long ticks) {
  if (ticks < 1) throw std::invalid_argument(fmt::format("Batch::step({}): the tick count must be >= 1", ticks));
  std::size_t running = 0;
  for (long k = 0; k < ticks; ++k) running = impl_->batch->tick();
  for (std::size_t i = 0; i < size(); ++i) impl_->update(i);
  return running;
}

bool Batch::failed(int scene) const {
  return impl_->at(scene).failed();
}
std::string Batch::failure(int scene) const {
  return impl_->at(scene).failure();
}

std::vector<int> Batch::failed_scenes() const {
  std::vector<int> out;
  for (std::size_t i : impl_->batch->failed()) out.push_back(int(i));
  return out;
}

const TickResult& Batch::last(int scene) const {
  impl_->check(scene);
  return impl_->last[std::size_t(scene)];
}

long Batch::ticks(int scene) const {
  return impl_->at(scene).scheduler().ticks();
}

void Batch::reset(int scene) {
  impl_->check(scene);
  impl_->batch->restart(std::size_t(scene));
  impl_->update(std::size_t(scene));
}

void Batch::reset() {
  for (std::size_t i = 0; i < size(); ++i) {
    impl_->batch->restart(i);
    impl_->update(i);
  }
}

std::vector<std::string> Batch::take_notes(int scene) {
  return impl_->at(scene).scheduler().take_notes();
}

namespace {

/// One vector of each tool's last result, size() x max_tools x 3, zero past a scene's own tools.
void read_tool_vectors(const std::vector<TickResult>& last, std::size_t tools, Vector3 ToolResult::*member,
                       const char* what, std::span<double> out) {
  const std::size_t need = last.size() * tools * 3;
  if (out.size() != need)
    throw std::invalid_argument(fmt::format("{}: the buffer holds {} values; the batch has {} ({} scenes x {} "
                                            "tools x 3)",
                                            what, out.size(), need, last.size(), tools));
  std::fill(out.begin(), out.end(), 0.0);
  for (std::size_t i = 0; i < last.size(); ++i)
    for (std::size_t k = 0; k < last[i].tools.size(); ++k)
      for (std::size_t c = 0; c < 3; ++c) out[3 * (i * tools + k) + c] = (last[i].tools[k].*member)[c];
}

}  // namespace

void Batch::read_forces(std::span<double> out) const {
  read_tool_vectors(impl_->last, std::size_t(max_tools()), &ToolResult::force, "read_forces", out);
}

void Batch::read_tips(std::span<double> out) const {
  read_tool_vectors(impl_->last, std::size_t(max_tools()), &ToolResult::tip, "read_tips", out);
}

std::vector<double> Batch::forces() const {
  std::vector<double> out(size() * std::size_t(max_tools()) * 3);
  read_forces(out);
  return out;
}

void Batch::read_field(int scene, Field f, std::span<double> out) {
  Session& s = impl_->at(scene);
  const std::size_t n = facade::field_size(f, std::size_t(s.model().n_nodes), std::size_t(s.model().n_elems));
  if (out.size() != n)
    throw std::invalid_argument(
        fmt::format("scene {} ({}): the field needs {} values, the buffer holds {}", scene, s.name(), n, out.size()));
  facade::copy_field(s.fields(), impl_->rest_of(s), f, out);
}

void Batch::read_fields(Field f, std::span<double> out) {
  const std::size_t each = facade::field_size(f, n_nodes(0), n_elements(0));
  for (std::size_t i = 1; i < size(); ++i)
    if (facade::field_size(f, n_nodes(int(i)), n_elements(int(i))) != each)
      throw std::invalid_argument(fmt::format(
          "read_fields: scenes 0 ({} nodes, {} elements) and {} ({} nodes, {} elements) differ in size; read each "
          "scene's field with read_field",
          n_nodes(0), n_elements(0), i, n_nodes(int(i)), n_elements(int(i))));
  if (out.size() != each * size())
    throw std::invalid_argument(
        fmt::format("read_fields: the buffer holds {} values; the batch's field has {} ({} "
                    "scenes x {})",
                    out.size(), each * size(), size(), each));
  for (std::size_t i = 0; i < size(); ++i) read_field(int(i), f, out.subspan(i * each, each));
}

std::vector<double> Batch::fields(Field f) {
  std::vector<double> out(facade::field_size(f, n_nodes(0), n_elements(0)) * size());
  read_fields(f, out);
  return out;
}

}  // namespace tissue
