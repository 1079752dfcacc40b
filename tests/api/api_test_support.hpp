// What the facade's tests share: a host's block mesh and the message of what a call throws.
#pragma once

#include <algorithm>
#include <exception>
#include <string>

#include "core/box_mesh.hpp"
#include "tissue/simulation.hpp"

namespace tissue::test {

/// A 20 x 20 x 10 mm block of n x n x n/2 cells (E Pa, nu 0.4), its base fixed; `tools` spheres of 4 mm.
inline MeshScene block(double E, int tools = 1, int n = 6) {
  ModelInput in;
  box_mesh(in, n, n, n / 2, 0.02, 0.02, 0.01);
  MeshScene m;
  m.name = "block";
  m.nodes = in.nodes;
  m.tets.assign(in.tets.begin(), in.tets.end());
  m.youngs_modulus = E;
  m.poisson_ratio = 0.4;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) m.fixed_nodes.push_back(box_node(n, n, i, j, 0));
  m.tool_radii.assign(std::size_t(tools), 4e-3);
  return m;
}

/// "@kidney-fat"'s probe driven by the host, `tick` ticks after `first` (its
/// first tick): along its axis into the layer, 0.5 mm a tick up to 12 mm,
/// through the 10 mm approach and 2 mm into the fat, which it pushes into
/// the kidney.
inline Vector3 fat_press_tip(const ToolResult& first, int tick) {
  const double d = std::min(12e-3, 0.5e-3 * tick);
  return {first.tip[0] - d * first.axis[0], first.tip[1] - d * first.axis[1], first.tip[2] - d * first.axis[2]};
}

/// What f throws, as its message; "(nothing thrown)" when it returns.
template <class F>
std::string thrown(F&& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "(nothing thrown)";
}

}  // namespace tissue::test
