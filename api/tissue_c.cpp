// The C interface (api/include/tissue/tissue_c.h) over the Simulation facade:
// every exception becomes a status and a per-thread message.
#include "tissue/tissue_c.h"

#include <cmath>
#include <exception>
#include <new>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/scheduler.hpp"
#include "tissue/batch.hpp"
#include "tissue/simulation.hpp"

struct tissue_simulation {
  tissue::Simulation sim;
  std::vector<tissue::BodyRange> bodies = sim.bodies();  ///< tissue_body_name's strings live here
};

struct tissue_batch {
  tissue::Batch batch;
  std::string failure;  ///< tissue_batch_failure's answer
};

static_assert(int(tissue::Field::Displacement) == TISSUE_FIELD_DISPLACEMENT &&
              int(tissue::Field::Position) == TISSUE_FIELD_POSITION &&
              int(tissue::Field::Pressure) == TISSUE_FIELD_PRESSURE &&
              int(tissue::Field::InternalForce) == TISSUE_FIELD_INTERNAL_FORCE &&
              int(tissue::Field::Jacobian) == TISSUE_FIELD_JACOBIAN);

namespace {

thread_local std::string g_error;

tissue_status fail(tissue_status s, std::string message) {
  g_error = std::move(message);
  return s;
}

/// Runs f, turning what it throws into a status and g_error.
template <class F>
tissue_status guarded(F&& f) {
  try {
    g_error.clear();
    f();
    return TISSUE_OK;
  } catch (const tissue::SimulationError& e) {
    return fail(TISSUE_UNSTABLE, e.what());
  } catch (const std::invalid_argument& e) {
    return fail(TISSUE_BAD_ARGUMENT, e.what());
  } catch (const std::bad_alloc&) {
    return fail(TISSUE_ERROR, "out of memory");
  } catch (const std::exception& e) {
    return fail(TISSUE_ERROR, e.what());
  } catch (...) {
    return fail(TISSUE_ERROR, "unknown error");
  }
}

std::string text(const char* s) { return s == nullptr ? std::string() : std::string(s); }

tissue_status null_argument(const char* function, const char* argument) {
  return fail(TISSUE_BAD_ARGUMENT, std::string(function) + ": " + argument + " is NULL");
}

}  // namespace

extern "C" {

const char* tissue_last_error(void) { return g_error.c_str(); }
const char* tissue_version(void) { return tissue::version(); }

tissue_status tissue_open_scene(const char* scene, const char* backend, const char* precision, const char* depth,
                                tissue_simulation** out) {
  if (out == nullptr) return null_argument("tissue_open_scene", "out");
  *out = nullptr;
  if (scene == nullptr) return null_argument("tissue_open_scene", "scene");
  return guarded([&] {
    *out = new tissue_simulation{tissue::Simulation::load(scene, {text(backend), text(precision), text(depth)})};
  });
}

tissue_status tissue_open_mesh(const tissue_mesh* mesh, const char* backend, const char* precision,
                               tissue_simulation** out) {
  if (out == nullptr) return null_argument("tissue_open_mesh", "out");
  *out = nullptr;
  if (mesh == nullptr) return null_argument("tissue_open_mesh", "mesh");
  if (mesh->n_nodes < 0 || mesh->n_tets < 0 || mesh->n_fixed < 0)
    return fail(TISSUE_BAD_ARGUMENT, "tissue_open_mesh: a negative count (n_nodes " + std::to_string(mesh->n_nodes) +
                                         ", n_tets " + std::to_string(mesh->n_tets) + ", n_fixed " +
                                         std::to_string(mesh->n_fixed) + ")");
  if ((mesh->n_nodes > 0 && mesh->nodes == nullptr) || (mesh->n_tets > 0 && mesh->tets == nullptr) ||
      (mesh->n_fixed > 0 && mesh->fixed_nodes == nullptr))
    return null_argument("tissue_open_mesh", "an array with a non-zero count");
  return guarded([&] {
    tissue::MeshScene m;
    m.name = "<tissue_open_mesh>";
    m.nodes.assign(mesh->nodes, mesh->nodes + 3 * std::size_t(mesh->n_nodes));
    m.tets.assign(mesh->tets, mesh->tets + 4 * std::size_t(mesh->n_tets));
    m.youngs_modulus = mesh->youngs_modulus;
    m.poisson_ratio = mesh->poisson_ratio;
    m.density = mesh->density;
    if (mesh->n_fixed > 0) m.fixed_nodes.assign(mesh->fixed_nodes, mesh->fixed_nodes + mesh->n_fixed);
    m.tool_radii = {mesh->tool_radius};
    *out = new tissue_simulation{tissue::Simulation::from_mesh(m, {text(backend), text(precision), ""})};
  });
}

void tissue_close(tissue_simulation* sim) { delete sim; }

size_t tissue_node_count(const tissue_simulation* sim) { return sim ? sim->sim.n_nodes() : 0; }
size_t tissue_element_count(const tissue_simulation* sim) { return sim ? sim->sim.n_elements() : 0; }
int tissue_tool_count(const tissue_simulation* sim) { return sim ? sim->sim.n_tools() : 0; }
double tissue_tick_seconds(const tissue_simulation* sim) { return sim ? sim->sim.tick_seconds() : 0; }

int tissue_body_count(const tissue_simulation* sim) { return sim ? int(sim->bodies.size()) : 0; }
const char* tissue_body_name(const tissue_simulation* sim, int body) {
  if (sim == nullptr || body < 0 || std::size_t(body) >= sim->bodies.size()) return nullptr;
  return sim->bodies[std::size_t(body)].name.c_str();
}
tissue_status tissue_body_range(const tissue_simulation* sim, int body, size_t* first_node, size_t* n_nodes,
                                size_t* first_element, size_t* n_elements) {
  if (sim == nullptr) return null_argument("tissue_body_range", "sim");
  if (body < 0 || std::size_t(body) >= sim->bodies.size())
    return fail(TISSUE_BAD_ARGUMENT, "tissue_body_range: body " + std::to_string(body) + " is out of range (the scene has " +
                                         std::to_string(sim->bodies.size()) + " bodies)");
  g_error.clear();
  const tissue::BodyRange& b = sim->bodies[std::size_t(body)];
  if (first_node) *first_node = b.first_node;
  if (n_nodes) *n_nodes = b.n_nodes;
  if (first_element) *first_element = b.first_element;
  if (n_elements) *n_elements = b.n_elements;
  return TISSUE_OK;
}
tissue_status tissue_body_contact_count(const tissue_simulation* sim, int32_t* count) {
  if (sim == nullptr) return null_argument("tissue_body_contact_count", "sim");
  if (count == nullptr) return null_argument("tissue_body_contact_count", "count");
  return guarded([&] { *count = int32_t(sim->sim.body_contacts().size()); });
}
tissue_status tissue_body_contacts(const tissue_simulation* sim, int32_t* nodes, int32_t* triangles, int32_t* bodies,
                                   double* depths, size_t capacity, size_t* written) {
  if (written) *written = 0;
  if (sim == nullptr) return null_argument("tissue_body_contacts", "sim");
  return guarded([&] {
    const std::vector<tissue::BodyContact> contacts = sim->sim.body_contacts();
    if (contacts.size() > capacity)
      throw std::invalid_argument("tissue_body_contacts: capacity " + std::to_string(capacity) + " is below the " +
                                  std::to_string(contacts.size()) +
                                  " contacts after the last tick (tissue_body_contact_count)");
    for (std::size_t i = 0; i < contacts.size(); ++i) {
      const tissue::BodyContact& c = contacts[i];
      if (nodes) nodes[i] = c.node;
      if (triangles)
        for (std::size_t k = 0; k < 3; ++k) triangles[3 * i + k] = c.triangle[k];
      if (bodies) {
        bodies[2 * i] = c.body;
        bodies[2 * i + 1] = c.other_body;
      }
      if (depths) depths[i] = c.depth;
    }
    if (written) *written = contacts.size();
  });
}
double tissue_time(const tissue_simulation* sim) { return sim ? sim->sim.time() : 0; }
double tissue_dissipated_energy(const tissue_simulation* sim) { return sim ? sim->sim.dissipated_energy() : 0; }

tissue_status tissue_set_tool_pose(tissue_simulation* sim, int tool, const double tip[3], const double axis[3]) {
  if (sim == nullptr) return null_argument("tissue_set_tool_pose", "sim");
  if (tip == nullptr) return null_argument("tissue_set_tool_pose", "tip");
  return guarded([&] {
    const tissue::Vector3 a = axis ? tissue::Vector3{axis[0], axis[1], axis[2]} : tissue::Vector3{0, 0, 0};
    sim->sim.set_tool_pose(tool, {tip[0], tip[1], tip[2]}, a);
  });
}

tissue_status tissue_set_grasp(tissue_simulation* sim, int tool, int down) {
  if (sim == nullptr) return null_argument("tissue_set_grasp", "sim");
  return guarded([&] { sim->sim.set_grasp(tool, down != 0); });
}

tissue_status tissue_set_tool_friction(tissue_simulation* sim, int tool, double mu) {
  if (sim == nullptr) return null_argument("tissue_set_tool_friction", "sim");
  return guarded([&] { sim->sim.set_tool_friction(tool, mu); });
}

double tissue_tool_friction(const tissue_simulation* sim, int tool) {
  if (sim == nullptr || tool < 0 || tool >= sim->sim.n_tools()) return std::nan("");
  return sim->sim.tool_friction(tool);
}

tissue_status tissue_set_loads(tissue_simulation* sim, const int32_t* nodes, const double* forces, size_t count) {
  if (sim == nullptr) return null_argument("tissue_set_loads", "sim");
  if (count > 0 && nodes == nullptr) return null_argument("tissue_set_loads", "nodes");
  if (count > 0 && forces == nullptr) return null_argument("tissue_set_loads", "forces");
  return guarded([&] {
    sim->sim.set_loads(std::span<const std::int32_t>(nodes, count), std::span<const double>(forces, 3 * count));
  });
}

tissue_status tissue_step(tissue_simulation* sim, long ticks) {
  if (sim == nullptr) return null_argument("tissue_step", "sim");
  return guarded([&] { sim->sim.step(ticks); });
}

tissue_status tissue_reset(tissue_simulation* sim) {
  if (sim == nullptr) return null_argument("tissue_reset", "sim");
  return guarded([&] { sim->sim.reset(); });
}

tissue_status tissue_cut(tissue_simulation* sim, const double origin[3], const double edge[3], const double sweep[3],
                         const char* method) {
  if (sim == nullptr) return null_argument("tissue_cut", "sim");
  if (origin == nullptr) return null_argument("tissue_cut", "origin");
  if (edge == nullptr) return null_argument("tissue_cut", "edge");
  if (sweep == nullptr) return null_argument("tissue_cut", "sweep");
  return guarded([&] {
    const std::string m = text(method);
    sim->sim.cut({origin[0], origin[1], origin[2]}, {edge[0], edge[1], edge[2]}, {sweep[0], sweep[1], sweep[2]},
                 m.empty() ? "snap-split" : m);
  });
}

tissue_status tissue_tool_force(const tissue_simulation* sim, int tool, double force[3]) {
  if (sim == nullptr) return null_argument("tissue_tool_force", "sim");
  if (force == nullptr) return null_argument("tissue_tool_force", "force");
  return guarded([&] {
    const tissue::Vector3 f = sim->sim.force(tool);
    for (int c = 0; c < 3; ++c) force[c] = f[c];
  });
}

tissue_status tissue_tool_contact_count(const tissue_simulation* sim, int tool, int32_t* count) {
  if (sim == nullptr) return null_argument("tissue_tool_contact_count", "sim");
  if (count == nullptr) return null_argument("tissue_tool_contact_count", "count");
  return guarded([&] {
    sim->sim.force(tool);  // checks the index
    *count = sim->sim.last().tools[tool].contact_nodes;
  });
}

tissue_status tissue_read_field(tissue_simulation* sim, tissue_field field, double* out, size_t count) {
  if (sim == nullptr) return null_argument("tissue_read_field", "sim");
  if (out == nullptr) return null_argument("tissue_read_field", "out");
  if (field < 0 || field >= TISSUE_FIELD_COUNT)
    return fail(TISSUE_BAD_ARGUMENT, "tissue_read_field: field " + std::to_string(int(field)) + " is not a tissue_field");
  return guarded([&] { sim->sim.read_field(static_cast<tissue::Field>(field), {out, count}); });
}

tissue_status tissue_batch_open(const char* const* scenes, size_t count, const char* backend, const char* precision,
                                const char* depth, tissue_batch** out) {
  if (out == nullptr) return null_argument("tissue_batch_open", "out");
  *out = nullptr;
  if (scenes == nullptr) return null_argument("tissue_batch_open", "scenes");
  std::vector<tissue::BatchScene> list;
  for (size_t i = 0; i < count; ++i) {
    if (scenes[i] == nullptr)
      return fail(TISSUE_BAD_ARGUMENT, "tissue_batch_open: scenes[" + std::to_string(i) + "] is NULL");
    list.push_back({scenes[i], {}, {}});
  }
  return guarded([&] {
    *out = new tissue_batch{tissue::Batch::load(list, {text(backend), text(precision), text(depth)}), {}};
  });
}

void tissue_batch_close(tissue_batch* batch) { delete batch; }

size_t tissue_batch_size(const tissue_batch* batch) { return batch == nullptr ? 0 : batch->batch.size(); }
int tissue_batch_max_tools(const tissue_batch* batch) { return batch == nullptr ? 0 : batch->batch.max_tools(); }

size_t tissue_batch_node_count(const tissue_batch* batch, int scene) {
  if (batch == nullptr || scene < 0 || size_t(scene) >= batch->batch.size()) return 0;
  return batch->batch.n_nodes(scene);
}

tissue_status tissue_batch_set_material(tissue_batch* batch, int scene, const char* material, double youngs_modulus,
                                        double poisson_ratio, double density) {
  if (batch == nullptr) return null_argument("tissue_batch_set_material", "batch");
  auto given = [](double v) { return std::isnan(v) ? std::nullopt : std::optional<double>(v); };
  return guarded([&] {
    batch->batch.set_material(scene, {text(material), given(youngs_modulus), given(poisson_ratio), given(density)});
  });
}

tissue_status tissue_batch_set_tool_pose(tissue_batch* batch, int scene, int tool, const double tip[3],
                                         const double axis[3]) {
  if (batch == nullptr) return null_argument("tissue_batch_set_tool_pose", "batch");
  if (tip == nullptr) return null_argument("tissue_batch_set_tool_pose", "tip");
  return guarded([&] {
    const tissue::Vector3 a = axis == nullptr ? tissue::Vector3{0, 0, 0} : tissue::Vector3{axis[0], axis[1], axis[2]};
    batch->batch.set_tool_pose(scene, tool, {tip[0], tip[1], tip[2]}, a);
  });
}

tissue_status tissue_batch_set_tool_friction(tissue_batch* batch, int scene, int tool, double mu) {
  if (batch == nullptr) return null_argument("tissue_batch_set_tool_friction", "batch");
  return guarded([&] { batch->batch.set_tool_friction(scene, tool, mu); });
}

tissue_status tissue_batch_set_tool_poses(tissue_batch* batch, const double* tips, const double* axes, size_t count) {
  if (batch == nullptr) return null_argument("tissue_batch_set_tool_poses", "batch");
  if (tips == nullptr) return null_argument("tissue_batch_set_tool_poses", "tips");
  return guarded([&] {
    batch->batch.set_tool_poses({tips, count}, axes == nullptr ? std::span<const double>() : std::span(axes, count));
  });
}

tissue_status tissue_batch_set_grasp(tissue_batch* batch, int scene, int tool, int down) {
  if (batch == nullptr) return null_argument("tissue_batch_set_grasp", "batch");
  return guarded([&] { batch->batch.set_grasp(scene, tool, down != 0); });
}

tissue_status tissue_batch_step(tissue_batch* batch, long ticks, size_t* running) {
  if (batch == nullptr) return null_argument("tissue_batch_step", "batch");
  return guarded([&] {
    const size_t r = batch->batch.step(ticks);
    if (running != nullptr) *running = r;
  });
}

tissue_status tissue_batch_scene_failed(const tissue_batch* batch, int scene, int* failed) {
  if (batch == nullptr) return null_argument("tissue_batch_scene_failed", "batch");
  if (failed == nullptr) return null_argument("tissue_batch_scene_failed", "failed");
  return guarded([&] { *failed = batch->batch.failed(scene) ? 1 : 0; });
}

const char* tissue_batch_failure(tissue_batch* batch, int scene) {
  if (batch == nullptr) return "";
  const tissue_status s = guarded([&] { batch->failure = batch->batch.failure(scene); });
  return s == TISSUE_OK ? batch->failure.c_str() : "";
}

tissue_status tissue_batch_reset(tissue_batch* batch, int scene) {
  if (batch == nullptr) return null_argument("tissue_batch_reset", "batch");
  return guarded([&] {
    if (scene == -1)
      batch->batch.reset();
    else
      batch->batch.reset(scene);
  });
}

tissue_status tissue_batch_forces(const tissue_batch* batch, double* out, size_t count) {
  if (batch == nullptr) return null_argument("tissue_batch_forces", "batch");
  if (out == nullptr) return null_argument("tissue_batch_forces", "out");
  return guarded([&] { batch->batch.read_forces({out, count}); });
}

tissue_status tissue_batch_read_field(tissue_batch* batch, int scene, tissue_field field, double* out, size_t count) {
  if (batch == nullptr) return null_argument("tissue_batch_read_field", "batch");
  if (out == nullptr) return null_argument("tissue_batch_read_field", "out");
  if (field < 0 || field >= TISSUE_FIELD_COUNT)
    return fail(TISSUE_BAD_ARGUMENT,
                "tissue_batch_read_field: field " + std::to_string(int(field)) + " is not a tissue_field");
  return guarded([&] { batch->batch.read_field(scene, static_cast<tissue::Field>(field), {out, count}); });
}

tissue_status tissue_batch_device_field(tissue_batch* batch, int scene, tissue_field field, tissue_device_view* out) {
  if (batch == nullptr) return null_argument("tissue_batch_device_field", "batch");
  if (out == nullptr) return null_argument("tissue_batch_device_field", "out");
  if (field < 0 || field >= TISSUE_FIELD_COUNT)
    return fail(TISSUE_BAD_ARGUMENT,
                "tissue_batch_device_field: field " + std::to_string(int(field)) + " is not a tissue_field");
  return guarded([&] {
    const tissue::Field f = static_cast<tissue::Field>(field);
    const tissue::Batch::DeviceView v = scene < 0 ? batch->batch.device_field(f) : batch->batch.device_field(scene, f);
    *out = {};
    out->data = v.data;
    out->ndim = int(v.shape.size());
    for (std::size_t k = 0; k < v.shape.size() && k < 3; ++k) {
      out->shape[k] = v.shape[k];
      out->strides[k] = v.strides[k];
    }
    out->scalar_bytes = v.scalar_bytes;
    out->device = v.device;
  });
}

tissue_status tissue_batch_set_tool_poses_from_device(tissue_batch* batch, uintptr_t tips, size_t count, int single) {
  if (batch == nullptr) return null_argument("tissue_batch_set_tool_poses_from_device", "batch");
  return guarded([&] { batch->batch.set_tool_poses_from_device(tips, count, single != 0); });
}

}  // extern "C"
