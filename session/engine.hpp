// A scene's engine: its model, a backend holding it and a Scheduler with the
// scene's loads. build_engine is the one assembly of a scene that every
// program uses: the facade's Session, `tissue run`, the viewer's haptic
// loop, `tissue bench` and `tissue tradeoff`.
#pragma once

#include <memory>
#include <optional>

#include "core/backend.hpp"
#include "core/model.hpp"
#include "core/scheduler.hpp"
#include "scene/scene.hpp"
#include "scene/validate.hpp"

namespace tissue {

struct Engine {
  std::shared_ptr<const TissueModel<double>> model;
  std::unique_ptr<Backend> backend;
  std::unique_ptr<Scheduler> scheduler;
};

/// (Re)starts an engine at rest: uploads its model to its backend, makes the
/// Scheduler with `settings` and gives it `loads` (null: the scene's own
/// <load>s). Throws what the Scheduler throws for bad settings.
void start_engine(Engine& e, const scene::Scene& s, const SchedulerSettings& settings,
                  const scene::SceneLoads* loads = nullptr);

/// Whether a tool of the scene is a blade: its cuts replace the scene and
/// the model, so it runs as a Session (session/session.hpp), not an engine.
bool has_blade(const scene::Scene& s);

/// The assembly of a scene: its model (scene::load_model, which validates
/// the whole scene; or `model` when the caller built it), the backend its
/// solver names at its precision, then start_engine with `settings` (unset:
/// the scene's own, scene::scheduler_settings). Throws std::invalid_argument
/// for a scene with a blade (its cuts need a Session).
Engine build_engine(const scene::Scene& s, std::optional<SchedulerSettings> settings = std::nullopt,
                    std::shared_ptr<const TissueModel<double>> model = nullptr);

}  // namespace tissue
