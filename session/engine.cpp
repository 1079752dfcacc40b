#include "session/engine.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <stdexcept>

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

bool has_blade(const scene::Scene& s) {
  return std::any_of(s.tools.begin(), s.tools.end(),
                     [](const scene::Tool& t) { return t.kind == scene::Tool::Kind::Blade; });
}

Engine build_engine(const scene::Scene& s, std::optional<SchedulerSettings> settings,
                    std::shared_ptr<const TissueModel<double>> model) {
  // a blade's cuts are a Session's (they replace the scene and the model): an engine alone would run it
  // as a capsule whose button does nothing
  for (const scene::Tool& t : s.tools)
    if (t.kind == scene::Tool::Kind::Blade)
      throw std::invalid_argument(fmt::format(
          "{}: tool '{}' is a blade; blades cut in a Simulation (C++, C and Python: docs/cutting.md), tissue run "
          "and tissue view; the benchmarks and the accuracy commands do not run them yet",
          s.source, t.name));
  Engine e;
  e.model = model ? std::move(model) : std::make_shared<const TissueModel<double>>(scene::load_model(s));
  e.backend = create_backend(s.solver.backend, s.solver.precision);
  start_engine(e, s, settings ? *settings : scene::scheduler_settings(s));
  return e;
}

}  // namespace tissue
