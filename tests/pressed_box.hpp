// A box pressed from above, for the tests that step material laws against
// each other: its bottom face fixed, its top face driven down.
#pragma once

#include <vector>

#include "core/box_mesh.hpp"
#include "core/model.hpp"

namespace tissue::test {

/// The top face's nodes and their driven displacements (3 per node).
struct PressedTop {
  std::vector<index_t> nodes;
  std::vector<double> target;
};

/// Fixes the nodes of `in` at z = 0 and returns those at z = top, each to
/// be driven by (0, 0, dz).
inline PressedTop fix_bottom_press_top(ModelInput& in, double top, double dz) {
  PressedTop p;
  in.fixed.assign(in.nodes.size() / 3, 0);
  for (size_t i = 0; i < in.fixed.size(); ++i) {
    in.fixed[i] = in.nodes[3 * i + 2] == 0.0;
    if (in.nodes[3 * i + 2] == top) {
      p.nodes.push_back(index_t(i));
      p.target.insert(p.target.end(), {0.0, 0.0, dz});
    }
  }
  return p;
}

/// A box of n^3 cells of the given edge: its first half of elements (by
/// index) fibre-reinforced (eta 3000 Pa along (0, 0.6, 0.8)) and
/// viscoelastic (two Prony terms, g 0.3 / 0.2, tau 0.01 / 0.1 s) on a
/// Neo-Hookean base (mu 1000 Pa, K 20000 Pa), the rest Neo-Hookean: every
/// law kernel in one mesh.
inline ModelInput mixed_law_box(int n, double edge) {
  ModelInput in;
  box_mesh(in, n, n, n, edge, edge, edge);
  MaterialParams nh{1000, 20000, 1000}, law = nh;
  law.fibre_eta = 3000;
  law.fibre_dir = {0.0, 0.6, 0.8};
  law.prony_terms = 2;
  law.prony_g[0] = 0.3, law.prony_tau[0] = 0.01;
  law.prony_g[1] = 0.2, law.prony_tau[1] = 0.1;
  in.materials = {law, nh};
  const index_t ne = index_t(in.tets.size() / 4);
  in.elem_material.assign(ne, 0);
  for (index_t e = ne / 2; e < ne; ++e) in.elem_material[e] = 1;
  return in;
}

}  // namespace tissue::test
