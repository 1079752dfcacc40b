// Uses a piece of each installed engine library: the built-in kidney (io,
// scene, core), its engine through the registry (backends, cpu, session), a
// haptic coupling (haptics) and the facade's version (tissue). Prints one
// tick's force.
#include <cstdio>

#include "backends/registry.hpp"
#include "haptics/force_coupling.hpp"
#include "io/kidney.hpp"
#include "session/engine.hpp"
#include "tissue/simulation.hpp"

int main() {
  tissue::scene::Scene s = tissue::io::default_kidney_scene();
  s.solver.backend = "cpu";
  tissue::Engine e = tissue::build_engine(s);
  tissue::ScriptedDevice script(s.tools.front().path);
  tissue::CoupledDevice device(script, tissue::CouplingParams{});  // the hand's side, through the coupling
  const tissue::TickReport r = e.scheduler->tick(device);
  std::printf("tissue %s, %zu backends known, %d nodes, tick %ld, force z %g N, coupling gain %g\n",
              tissue::version(), tissue::list_backends().size(), int(e.model->n_nodes), r.tick, r.force.z,
              tissue::coupling_jump_gain(tissue::CouplingParams{}));
  return e.model->n_nodes > 0 ? 0 : 1;
}
