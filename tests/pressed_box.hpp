// A box pressed from above, for the tests that step material laws against
// each other: its bottom face fixed, its top face driven down.
#pragma once

#include <algorithm>
#include <vector>

#include "core/box_mesh.hpp"
#include "core/model.hpp"

namespace tissue::test {

/// The top face's nodes and their driven displacements (3 per node).
struct PressedTop {
  std::vector<index_t> nodes;
  std::vector<double> target;
};

/// Fixes the nodes of `in` at its lowest z and returns those at its highest
/// (the top face, found rather than named: box_mesh's rounding can leave a
/// face a last bit off its nominal height), each to be driven by (0, 0, dz).
inline PressedTop fix_bottom_press_top(ModelInput& in, double dz) {
  const size_t n = in.nodes.size() / 3;
  double lo = in.nodes[2], hi = in.nodes[2];
  for (size_t i = 0; i < n; ++i) lo = std::min(lo, in.nodes[3 * i + 2]), hi = std::max(hi, in.nodes[3 * i + 2]);
  PressedTop p;
  in.fixed.assign(n, 0);
  for (size_t i = 0; i < n; ++i) {
    in.fixed[i] = in.nodes[3 * i + 2] == lo;
    if (in.nodes[3 * i + 2] == hi) {
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
