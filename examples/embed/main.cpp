// Embedding Tissue: load a scene, press the tool into the top of the organ
// for half a second, hold it, and print the force the hand would feel.
// Usage: embed [scene.xml | @kidney] [cpu | cuda]
#include <tissue/simulation.hpp>

#include <algorithm>
#include <cstdio>
#include <exception>

int main(int argc, char** argv) try {
  tissue::SimulationOptions options;
  if (argc > 2) options.backend = argv[2];
  tissue::Simulation sim = tissue::Simulation::load(argc > 1 ? argv[1] : "@kidney", options);
  std::printf("%s: %zu nodes, %zu tets on %s (%s), %d steps per %.1f ms tick\n", sim.name().c_str(), sim.n_nodes(),
              sim.n_elements(), sim.backend().c_str(), sim.device_name().c_str(), sim.steps_per_tick(),
              1e3 * sim.tick_seconds());

  // The highest node of the surface: the tool starts one radius above it.
  const auto X = sim.rest_positions();
  std::size_t top = 0;
  for (std::size_t a = 0; a < sim.n_nodes(); ++a)
    if (X[3 * a + 2] > X[3 * top + 2]) top = a;
  const double r = sim.tool_radius(0), depth = 3e-3;  // press 3 mm
  const tissue::Vector3 start = {X[3 * top], X[3 * top + 1], X[3 * top + 2] + r};

  const int press_ticks = 500, hold_ticks = 500;
  for (int k = 1; k <= press_ticks + hold_ticks; ++k) {
    const double s = std::min(1.0, double(k) / press_ticks);
    sim.set_tool_pose(0, {start[0], start[1], start[2] - s * depth});  // the device's pose this tick
    const tissue::TickResult t = sim.step();
    if (k % 100 == 0) {
      const tissue::Vector3 f = t.tools[0].force;
      std::printf("t = %.3f s  press %.2f mm  force (%.4f, %.4f, %.4f) N  %d nodes in contact\n", t.time,
                  1e3 * s * depth, f[0], f[1], f[2], t.tools[0].contact_nodes);
    }
  }
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "embed: %s\n", e.what());
  return 1;
}
