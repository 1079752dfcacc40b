#include "session/engine.hpp"

#include "backends/registry.hpp"

namespace tissue {

void start_engine(Engine& e, const scene::Scene& s, const SchedulerSettings& settings, const scene::SceneLoads* loads) {
  e.scheduler.reset();
  e.backend->upload(*e.model);
  e.scheduler = std::make_unique<Scheduler>(*e.backend, *e.model, settings);
  if (loads)
    e.scheduler->set_loads(loads->nodes, loads->force);
  else
    scene::apply_loads(s, *e.model, *e.scheduler);
}

Engine build_engine(const scene::Scene& s, std::optional<SchedulerSettings> settings,
                    std::shared_ptr<const TissueModel<double>> model) {
  Engine e;
  e.model = model ? std::move(model) : std::make_shared<const TissueModel<double>>(scene::load_model(s));
  e.backend = create_backend(s.solver.backend, s.solver.precision);
  start_engine(e, s, settings ? *settings : scene::scheduler_settings(s));
  return e;
}

}  // namespace tissue
