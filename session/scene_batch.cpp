#include "session/scene_batch.hpp"

#include <fmt/format.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <chrono>
#include <exception>
#include <mutex>
#include <fstream>
#include <sstream>
#include <stdexcept>

#include "backends/registry.hpp"
#include "scene/validate.hpp"

namespace tissue {
namespace {

bool same_material(const MaterialParams& a, const MaterialParams& b) {
  if (a.mu != b.mu || a.K != b.K || a.rho != b.rho || a.fibre_eta != b.fibre_eta || a.prony_terms != b.prony_terms ||
      a.fibre_dir.x != b.fibre_dir.x || a.fibre_dir.y != b.fibre_dir.y || a.fibre_dir.z != b.fibre_dir.z)
    return false;
  for (int k = 0; k < kMaxProny; ++k)
    if (a.prony_g[k] != b.prony_g[k] || a.prony_tau[k] != b.prony_tau[k]) return false;
  return true;
}

/// One mesh: nodes, elements, element sets, supports and fibre directions.
bool same_mesh(const ModelInput& a, const ModelInput& b) {
  return a.nodes == b.nodes && a.tets == b.tets && a.elem_material == b.elem_material && a.fixed == b.fixed &&
         a.fixed_axes == b.fixed_axes && a.fibre_dirs == b.fibre_dirs;
}

/// True when build_model would build the same model from both inputs. The
/// settings and materials are compared before the mesh: a sweep's inputs
/// differ there, and a batch compares each new input with every model built.
bool same_input(const ModelInput& a, const ModelInput& b) {
  if (a.dt != b.dt || a.dt_safety != b.dt_safety || a.damping != b.damping || a.ianp != b.ianp ||
      a.mass_scaling != b.mass_scaling || a.tick != b.tick || a.materials.size() != b.materials.size())
    return false;
  for (std::size_t k = 0; k < a.materials.size(); ++k)
    if (!same_material(a.materials[k], b.materials[k])) return false;
  return same_mesh(a, b);
}

/// True when scenes of these models can share a group's launch (docs/batch.md,
/// "One launch per pass"): one mesh, supports, fibre directions and IANP, the
/// same step (dt, so the same steps a tick), and materials that differ at most
/// in their values (moduli, density, damping, mass scaling: the arrays each
/// scene reads from its own slot, cuda ModelView::materials_moved), not in
/// their laws.
bool same_group(const ModelInput& a, const TissueModel<double>& ma, const ModelInput& b,
                const TissueModel<double>& mb) {
  if (&ma == &mb) return true;
  if (ma.dt != mb.dt || a.ianp != b.ianp || a.tick != b.tick || a.materials.size() != b.materials.size()) return false;
  for (std::size_t k = 0; k < a.materials.size(); ++k)
    if ((a.materials[k].fibre_eta > 0) != (b.materials[k].fibre_eta > 0) ||
        a.materials[k].prony_terms != b.materials[k].prony_terms)
      return false;
  return same_mesh(a, b);
}

/// MemAvailable of /proc/meminfo (bytes), -1 where unknown.
std::int64_t host_available_bytes() {
  std::ifstream f("/proc/meminfo");
  std::string line;
  while (std::getline(f, line))
    if (line.rfind("MemAvailable:", 0) == 0) {
      std::istringstream in(line.substr(13));
      long kb = 0;
      if (in >> kb) return std::int64_t(kb) * 1024;
    }
  return -1;
}

/// Bytes of a model's arrays in double (the host's shared copy).
std::int64_t model_bytes(const TissueModel<double>& m) {
  const std::int64_t n = m.n_nodes, ne = m.n_elems, nt = m.n_tris;
  return 8 * (7 * n + 15 * ne) + 4 * (13 * ne + n + 7 * nt + 2 * std::int64_t(m.n_surf)) + n;
}

/// Bytes of a host backend's own store of the model (core/model.hpp and
/// core/state.hpp in the backend's scalar): per node 30 scalars (positions,
/// masses, the central difference's constants, the displacements and their
/// targets, forces, contact normals and grasp offsets, pressure and its
/// divisor) and 6 flag bytes; per element 38 scalars (gradients, volume,
/// moduli, the pass arrays, F and the corner forces) and 13 ids; per surface
/// triangle 7 ids.
std::int64_t host_store_bytes(const TissueModel<double>& m, Precision p) {
  const std::int64_t s = p == Precision::Float ? 4 : 8;
  const std::int64_t n = m.n_nodes, ne = m.n_elems, nt = m.n_tris;
  return s * (30 * n + 38 * ne) + 4 * (13 * ne + n + 7 * nt + 2 * std::int64_t(m.n_surf)) + 6 * n;
}

std::string gib(std::int64_t bytes) {
  return fmt::format("{:.2f} GiB", double(bytes) / (1024.0 * 1024.0 * 1024.0));
}

}  // namespace

void check_batch_memory(std::size_t scenes, const BatchMemory& m, const std::string& device) {
  const std::int64_t rest = std::int64_t(scenes) - 1;  // the first is built
  if (m.host_available >= 0 && rest * m.per_scene_host > m.host_available * 9 / 10)
    throw std::runtime_error(fmt::format(
        "a batch of {} scenes needs about {} of host memory ({} a scene, measured on the first), more than 90 % of "
        "the {} available: use fewer scenes",
        scenes, gib(std::int64_t(scenes) * m.per_scene_host), gib(m.per_scene_host), gib(m.host_available)));
  if (m.device_free >= 0 && rest * m.per_scene_device > m.device_free * 9 / 10)
    throw std::runtime_error(fmt::format(
        "a batch of {} scenes needs about {} of device memory ({} a scene, measured on the first), more than 90 % of "
        "the {} free on {}: use fewer scenes",
        scenes, gib(std::int64_t(scenes) * m.per_scene_device), gib(m.per_scene_device), gib(m.device_free), device));
}

void check_batch_size(std::size_t scenes) {
  const std::int64_t available = host_available_bytes();
  if (available < 0 || double(scenes) * double(kMinSceneHostBytes) <= double(available)) return;
  throw std::invalid_argument(fmt::format(
      "a batch of {} scenes needs at least {} of host memory ({} KiB a scene before its mesh), more than the {} "
      "available: use fewer scenes",
      scenes, gib(std::int64_t(double(scenes) * double(kMinSceneHostBytes))), kMinSceneHostBytes / 1024,
      gib(available)));
}

struct SceneBatch::BuiltModel {
  ModelInput input;
  std::shared_ptr<const TissueModel<double>> model;
};

SceneBatch::SceneBatch(const std::vector<std::shared_ptr<const scene::Scene>>& scenes, const std::string& backend,
                       Precision precision)
    : backend_(backend), precision_(precision) {
  if (scenes.empty()) throw std::invalid_argument("a batch needs at least one scene");
  const std::size_t n = scenes.size();
  std::vector<Prepared> prepared;
  prepared.reserve(n);
  for (std::size_t i = 0; i < n; ++i) prepared.push_back(prepare(scenes[i], i));
  const int max_group = max_group_scenes(backend_);
  // each scene's group class: the first earlier scene whose model can share a launch with its (same_group)
  std::vector<std::size_t> cls(n);
  std::vector<std::size_t> firsts;
  for (std::size_t i = 0; i < n && max_group > 0; ++i) {
    cls[i] = i;
    for (std::size_t f : firsts)
      if (groupable(prepared[f].model, prepared[i].model)) {
        cls[i] = f;
        break;
      }
    if (cls[i] == i) firsts.push_back(i);
  }
  sessions_.reserve(n);
  member_.assign(n, {});
  for (std::size_t i = 0; i < n; ++i) {
    Membership slot;
    if (max_group > 0) {  // the scenes of one class in groups of up to max_group, in order
      auto open = std::find_if(groups_.begin(), groups_.end(), [&](const Group& g) {
        return g.model == prepared[cls[i]].model && g.filled < g.slots;
      });
      if (open == groups_.end()) {
        const auto rest = std::count(cls.begin() + std::ptrdiff_t(i), cls.end(), cls[i]);
        const int slots = int(std::min<std::ptrdiff_t>(rest, max_group));
        if (slots >= 2) {
          // a scene's device bytes, measured on a scene built alone (also the memory check's first scene)
          std::int64_t bytes = 0;
          std::unique_ptr<Session> alone = build(prepared[i], i, {}, &bytes);
          if (i == 0) measure_first(*alone, n, bytes);
          alone.reset();
          // room for each array's alignment in the slot (256 bytes an array)
          const std::size_t slot_bytes = std::size_t(bytes) + std::size_t(bytes) / 32 + (std::size_t(1) << 18);
          groups_.push_back(
              {prepared[cls[i]].model, make_backend_group(backend_, precision_, slots, slot_bytes), slots, 0});
          open = groups_.end() - 1;
        }
      }
      if (open != groups_.end()) slot = {open->group, open->filled++};
    }
    std::int64_t bytes = 0;
    sessions_.push_back(build(prepared[i], i, slot, &bytes));
    member_[i] = slot;
    if (i == 0 && !slot.group) measure_first(*sessions_[0], n, bytes);
  }
  set_threads();
}

void SceneBatch::measure_first(const Session& first, std::size_t scenes, std::int64_t device_bytes) {
  const Backend& b = first.backend();
  const TissueModel<double>& m = first.model();
  memory_.shared_host = model_bytes(m);
  memory_.per_scene_host = b.asynchronous_ticks() ? 0 : host_store_bytes(m, b.precision());
  memory_.per_scene_device = std::max<std::int64_t>(device_bytes, 0);
  memory_.device_free = b.device_memory().free;
  memory_.host_available = host_available_bytes();
  check_batch_memory(scenes, memory_, b.device_name());
}

bool SceneBatch::groupable(const std::shared_ptr<const TissueModel<double>>& a,
                           const std::shared_ptr<const TissueModel<double>>& b) const {
  if (a == b) return true;
  const ModelInput *ia = nullptr, *ib = nullptr;
  for (const auto& m : models_) {
    if (m->model == a) ia = &m->input;
    if (m->model == b) ib = &m->input;
  }
  return ia && ib && same_group(*ia, *a, *ib, *b);
}

std::shared_ptr<const TissueModel<double>> SceneBatch::model_for(const scene::Scene& scene) {
  ModelInput input = scene::to_model_input(scene);
  for (const auto& b : models_)
    if (same_input(b->input, input)) return b->model;
  auto built = std::make_shared<BuiltModel>();
  built->input = std::move(input);
  built->model = std::make_shared<const TissueModel<double>>(scene::load_model(scene));
  models_.push_back(built);
  return built->model;
}

SceneBatch::Prepared SceneBatch::prepare(const std::shared_ptr<const scene::Scene>& given, std::size_t index) {
  if (!given) throw std::invalid_argument(fmt::format("batch scene {}: no scene given", index));
  for (const scene::Tool& t : given->tools)
    if (t.kind == scene::Tool::Kind::Blade)
      throw std::invalid_argument(fmt::format(
          "batch scene {} ({}): tool '{}' is a blade; a blade cuts its scene's mesh, which a batch's scenes "
          "share, so blades run in a Simulation, not a Batch",
          index, given->source, t.name));
  try {
    // the scene on the batch's backend and precision, one copy per scene given
    std::shared_ptr<const scene::Scene> scene;
    for (const auto& [in, run] : run_scenes_)
      if (in == given) scene = run;
    if (!scene) {
      if (given->solver.backend == backend_ && given->solver.precision == precision_) {
        scene = given;
      } else {
        auto copy = std::make_shared<scene::Scene>(*given);
        copy->solver.backend = backend_;
        copy->solver.precision = precision_;
        scene = std::move(copy);
      }
      run_scenes_.emplace_back(given, scene);
    }
    std::shared_ptr<const TissueModel<double>> model = model_for(*scene);
    return {std::move(scene), std::move(model)};
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(fmt::format("batch scene {}: {}", index, e.what()));
  } catch (const std::exception& e) {
    throw std::runtime_error(fmt::format("batch scene {}: {}", index, e.what()));
  }
}

std::unique_ptr<Session> SceneBatch::build(const Prepared& p, std::size_t index, const Membership& slot,
                                           std::int64_t* device_bytes) {
  try {
    std::unique_ptr<Backend> backend = create_backend(backend_, precision_);
    if (slot.group) join_backend_group(*backend, slot.group, slot.slot);
    const std::int64_t before = backend->device_memory().held;
    auto session = std::make_unique<Session>(p.scene, p.model, std::move(backend));
    // the device bytes its backend took (held counts every backend of the process)
    if (device_bytes) *device_bytes = session->backend().device_memory().held - before;
    return session;
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(fmt::format("batch scene {}: {}", index, e.what()));
  } catch (const std::exception& e) {
    throw std::runtime_error(fmt::format("batch scene {}: {}", index, e.what()));
  }
}

void SceneBatch::set_threads() {
  if (sessions_.front()->backend().asynchronous_ticks()) return;
  const std::size_t threads = std::size_t(std::max(1, tbb::this_task_arena::max_concurrency()));
  // a batch of one keeps the backend's own team; more scenes share the threads
  const int each = size() == 1 ? 0 : int(std::max<std::size_t>(1, threads / size()));
  for (auto& s : sessions_) s->backend().set_worker_threads(each);
}

int SceneBatch::max_tools() const {
  int most = 0;
  for (const auto& s : sessions_) most = std::max(most, s->n_tools());
  return most;
}

std::size_t SceneBatch::distinct_models() const {
  std::vector<const TissueModel<double>*> seen;
  for (const auto& s : sessions_)
    if (std::find(seen.begin(), seen.end(), &s->model()) == seen.end()) seen.push_back(&s->model());
  return seen.size();
}

namespace {

/// Ticks scenes [first, last) of a device backend: every tick started (each on its scene's stream) before any
/// is waited for. A failure other than the simulation's own is rethrown once every started tick has ended.
void tick_started_together(std::vector<std::unique_ptr<Session>>& sessions, std::size_t first, std::size_t last) {
  std::vector<char> started(last - first, 0);
  std::exception_ptr error;
  for (std::size_t i = first; i < last && !error; ++i) {
    Session& s = *sessions[i];
    if (s.failed()) continue;
    try {
      s.begin_tick();
      started[i - first] = 1;
    } catch (const SimulationError&) {
    } catch (...) {
      error = std::current_exception();
    }
  }
  for (std::size_t i = first; i < last; ++i) {
    if (!started[i - first]) continue;
    try {
      sessions[i]->end_tick();
    } catch (const SimulationError&) {
    } catch (...) {
      if (!error) error = std::current_exception();
    }
  }
  if (error) std::rethrow_exception(error);
}

}  // namespace

std::size_t SceneBatch::tick() {
  const std::size_t n = size();
  if (!groups_.empty()) {
    tick_in_groups();
  } else if (sessions_.front()->backend().asynchronous_ticks()) {
    // one host thread per kScenesPerLauncher scenes (at most one per core) starts and ends their ticks: the
    // launches, not the device, bound a tick of many small scenes
    const std::size_t threads = std::size_t(std::max(1, tbb::this_task_arena::max_concurrency()));
    const std::size_t chunks = std::clamp<std::size_t>((n + kScenesPerLauncher - 1) / kScenesPerLauncher, 1, threads);
    if (chunks == 1) {
      tick_started_together(sessions_, 0, n);
    } else {
      tbb::parallel_for(std::size_t(0), chunks,
                        [&](std::size_t c) { tick_started_together(sessions_, c * n / chunks, (c + 1) * n / chunks); });
    }
  } else {
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, 1), [&](const tbb::blocked_range<std::size_t>& r) {
      for (std::size_t i = r.begin(); i != r.end(); ++i) {
        Session& s = *sessions_[i];
        if (s.failed()) continue;
        try {
          s.tick();
        } catch (const SimulationError&) {
        }
      }
    });
  }
  return n - failed().size();
}

void SceneBatch::tick_in_groups() {
  // every running scene's tick started (a group's scene only stages it), then each group's launched, then
  // every started tick ended; the threads share the starts and the ends
  const std::size_t n = size();
  std::vector<char> started(n, 0);
  std::mutex error_mutex;
  std::exception_ptr error;
  const auto keep = [&] {
    std::lock_guard<std::mutex> lock(error_mutex);
    if (!error) error = std::current_exception();
  };
  using Clock = std::chrono::steady_clock;
  const auto t0 = Clock::now();
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, kScenesPerLauncher), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      Session& s = *sessions_[i];
      if (s.failed()) continue;
      try {
        s.begin_tick();
        started[i] = 1;
      } catch (const SimulationError&) {
      } catch (...) {
        keep();
      }
    }
  });
  const auto t1 = Clock::now();
  for (const Group& g : groups_) {
    try {
      g.group->launch();
    } catch (...) {
      keep();
    }
  }
  const auto t2 = Clock::now();
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, kScenesPerLauncher), [&](const tbb::blocked_range<std::size_t>& r) {
    for (std::size_t i = r.begin(); i != r.end(); ++i) {
      if (!started[i]) continue;
      try {
        sessions_[i]->end_tick();
      } catch (const SimulationError&) {
      } catch (...) {
        keep();
      }
    }
  });
  const auto t3 = Clock::now();
  const auto seconds = [](Clock::duration d) { return std::chrono::duration<double>(d).count(); };
  phases_ = {seconds(t1 - t0), seconds(t2 - t1), seconds(t3 - t2)};
  if (error) std::rethrow_exception(error);
}

std::int64_t SceneBatch::ticks_together() const {
  std::int64_t t = 0;
  for (const Group& g : groups_) t += g.group->ticks_together();
  return t;
}

std::int64_t SceneBatch::ticks_alone() const {
  std::int64_t t = 0;
  for (const Group& g : groups_) t += g.group->ticks_alone();
  return t;
}

std::vector<std::size_t> SceneBatch::failed() const {
  std::vector<std::size_t> out;
  for (std::size_t i = 0; i < size(); ++i)
    if (sessions_[i]->failed()) out.push_back(i);
  return out;
}

void SceneBatch::restart(std::size_t i) {
  sessions_.at(i)->restart();
}

void SceneBatch::replace(std::size_t i, std::shared_ptr<const scene::Scene> scene) {
  if (i >= size()) throw std::out_of_range(fmt::format("batch scene {} does not exist (0..{})", i, size() - 1));
  const Prepared p = prepare(scene, i);
  // a model that can share its group's launch: the new scene takes the old one's slot; otherwise it runs alone
  Membership slot;
  for (const Group& g : groups_)
    if (member_[i].group == g.group && groupable(g.model, p.model)) slot = member_[i];
  sessions_[i].reset();  // (leaves its slot first)
  sessions_[i] = build(p, i, slot);
  member_[i] = slot;
  // forget what no scene uses any more
  models_.erase(std::remove_if(models_.begin(), models_.end(), [](const auto& b) { return b->model.use_count() == 1; }),
                models_.end());
  auto unused = [&](const auto& p) {
    return std::none_of(sessions_.begin(), sessions_.end(),
                        [&](const auto& s) { return &s->scene() == p.second.get(); });
  };
  run_scenes_.erase(std::remove_if(run_scenes_.begin(), run_scenes_.end(), unused), run_scenes_.end());
  set_threads();
}

}  // namespace tissue
