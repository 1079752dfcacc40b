// Many scenes stepped together on one backend (docs/batch.md): the engine
// under the facade's tissue::Batch and `tissue bench --batch`.
//
// Each scene is a Session of its own: its own model parameters, tools,
// loads, paths, region, contact, reductions and health checks. Scenes whose
// model input is the same (one mesh, one set of materials and solver
// settings) share one model on the host. A tick runs every running scene:
// - on a device backend (Backend::asynchronous_ticks) every scene's tick is
//   started on its own stream before any is waited for, so the GPU runs
//   them side by side; host threads share the launching, one per
//   kScenesPerLauncher scenes up to one per core;
// - on a host backend the scenes run on TBB's threads, one scene per thread,
//   each backend stepping on one thread (Backend::set_worker_threads(1))
//   once there are at least as many scenes as threads.
// A scene whose tick fails (an inverted element, a non-finite value) stops
// alone: it keeps its failure and its last good report, the others go on,
// and restart(i) starts it again. Results equal the same scene run alone.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "core/hd.hpp"
#include "scene/scene.hpp"
#include "session/session.hpp"

namespace tissue {

/// Memory a batch of scenes needs (bytes), taken from its first scene
/// before the others are built, and what the machine has.
struct BatchMemory {
  std::int64_t per_scene_host = 0;    ///< a host backend's store of one scene (its arrays counted; 0 for
                                      ///< device backends, whose host side per scene is small)
  std::int64_t per_scene_device = 0;  ///< device bytes one scene's backend holds, measured (0 for host backends)
  std::int64_t shared_host = 0;       ///< host bytes of each distinct model (shared by its scenes)
  std::int64_t host_available = -1;   ///< MemAvailable (/proc/meminfo); -1 unknown
  std::int64_t device_free = -1;      ///< free device memory; -1 for host backends
};

/// Throws std::runtime_error, naming the sizes, when `scenes` scenes of the
/// measured size would take more than 90 % of the host's available or the
/// device's free memory (unknown amounts, -1, are not checked). `device`
/// names the device in the message.
void check_batch_memory(std::size_t scenes, const BatchMemory& m, const std::string& device);

/// The least host memory one scene of a batch takes whatever its mesh (its
/// session, scheduler, tools and facade state): kMinSceneHostBytes.
inline constexpr std::int64_t kMinSceneHostBytes = 64 * 1024;
/// Refuses, before anything is built, a batch of more scenes than the
/// host's available memory could hold at kMinSceneHostBytes each, naming
/// the count and the memory (check_batch_memory then checks the measured
/// bytes once the first scene is built).
void check_batch_size(std::size_t scenes);

class SceneBatch {
 public:
  /// On a device backend, scenes whose ticks one host thread starts and ends.
  static constexpr std::size_t kScenesPerLauncher = 4;

  /// Builds and uploads one session per scene, all on `backend` at
  /// `precision` (the scenes' own solver backend and precision are
  /// replaced). Measures the first scene's memory and throws
  /// std::runtime_error, naming the sizes, before building the others
  /// when the whole batch would not fit in the host's available memory or
  /// the device's free memory. Throws what Session throws for a bad scene,
  /// naming its index.
  /// Scenes given by the same pointer share one copy.
  SceneBatch(const std::vector<std::shared_ptr<const scene::Scene>>& scenes, const std::string& backend,
             Precision precision);

  std::size_t size() const { return sessions_.size(); }
  Session& operator[](std::size_t i) { return *sessions_.at(i); }
  const Session& operator[](std::size_t i) const { return *sessions_.at(i); }
  const std::string& backend_name() const { return backend_; }
  Precision precision() const { return precision_; }
  /// The most tools any scene has.
  int max_tools() const;
  /// Distinct models held on the host (scenes of one model input share one).
  std::size_t distinct_models() const;
  const BatchMemory& memory() const { return memory_; }

  /// One haptic tick of every running scene (those not failed). Returns
  /// how many still run after it.
  std::size_t tick();
  /// Scene ticks run as one launch per pass in a group (BackendGroup), and
  /// ticks of grouped scenes run alone (a tick the group could not take).
  std::int64_t ticks_together() const;
  std::int64_t ticks_alone() const;
  /// Groups of scenes stepped as one (cuda: scenes of one mesh and one step, whatever their materials).
  std::size_t groups() const { return groups_.size(); }
  /// The last tick of a batch with groups, in seconds: the host's starts
  /// (every scene's tick staged, or launched alone), the groups' launches
  /// up to the device's end, and the host's ends (results read, checks).
  struct TickPhases {
    double start = 0, device = 0, end = 0;
  };
  const TickPhases& last_phases() const { return phases_; }
  /// Scenes that have failed (ascending).
  std::vector<std::size_t> failed() const;
  /// Scene i back to rest (Session::restart), failure cleared.
  void restart(std::size_t i);
  /// Replaces scene i by a new one (a material changed): its model is
  /// shared with another scene of the same model input, or built; it
  /// starts at rest with the old session's host tool modes forgotten.
  void replace(std::size_t i, std::shared_ptr<const scene::Scene> scene);

 private:
  struct Prepared {
    std::shared_ptr<const scene::Scene> scene;
    std::shared_ptr<const TissueModel<double>> model;
  };
  struct Membership {
    std::shared_ptr<BackendGroup> group;  ///< null: the scene runs alone
    int slot = -1;
  };
  struct Group {
    std::shared_ptr<const TissueModel<double>> model;  ///< its first scene's (the others' are groupable with it)
    std::shared_ptr<BackendGroup> group;
    int slots = 0, filled = 0;
  };
  Prepared prepare(const std::shared_ptr<const scene::Scene>& scene, std::size_t index);
  std::unique_ptr<Session> build(const Prepared& p, std::size_t index, const Membership& slot,
                                 std::int64_t* device_bytes = nullptr);
  void measure_first(const Session& first, std::size_t scenes, std::int64_t device_bytes);
  void tick_in_groups();
  std::shared_ptr<const TissueModel<double>> model_for(const scene::Scene& scene);
  /// Whether scenes of these models can share a group's launch (one mesh and step; materials may differ).
  bool groupable(const std::shared_ptr<const TissueModel<double>>& a,
                 const std::shared_ptr<const TissueModel<double>>& b) const;
  void set_threads();

  std::string backend_;
  Precision precision_;
  std::vector<std::unique_ptr<Session>> sessions_;
  /// Built models with the model input and tick they were built from.
  struct BuiltModel;
  std::vector<std::shared_ptr<BuiltModel>> models_;
  /// The scenes as given and as run (the batch's backend and precision), for scenes given by one pointer.
  std::vector<std::pair<std::shared_ptr<const scene::Scene>, std::shared_ptr<const scene::Scene>>> run_scenes_;
  BatchMemory memory_;
  std::vector<Group> groups_;
  std::vector<Membership> member_;  ///< per scene
  TickPhases phases_;
};

}  // namespace tissue
