// A sliver tet that build_model accepts (its volume 1e-5 of its longest
// edge cubed): well inside the model's rules, yet its gradients recomputed
// in float stray far (core worst_gradient_deviation; the cuda backend's
// CudaGradients keeps the stored ones for a mesh that has one); and a tet
// far away that widens a mesh's extent (float's reference grid coarsens).
#pragma once

#include "core/model.hpp"
#include "core/vec.hpp"

namespace tissue::test {

/// Appends a separate sliver with a corner at x0 to `in` (four new nodes
/// and one tet, material 0): corners a, b, c of a tilted 1 mm face and d
/// 1e-7 m off the middle of edge bc. Returns its element index.
inline index_t append_sliver(ModelInput& in, Vec3<double> x0) {
  const index_t first = index_t(in.nodes.size() / 3);
  const Vec3<double> a = x0, b = x0 + Vec3<double>{0.001, 0.001, 0.0}, c = x0 + Vec3<double>{0.0, 0.001, 0.001};
  const Vec3<double> n = (1.0 / norm(cross(b - a, c - a))) * cross(b - a, c - a);
  const Vec3<double> d = 0.5 * (b + c) + 1e-7 * n;
  for (const Vec3<double>& x : {a, b, c, d}) in.nodes.insert(in.nodes.end(), {x.x, x.y, x.z});
  in.tets.insert(in.tets.end(), {first, first + 1, first + 2, first + 3});
  if (!in.elem_material.empty()) in.elem_material.push_back(0);
  return index_t(in.tets.size() / 4 - 1);
}

/// Appends a separate tet with a right-angled corner at x0 and legs of
/// `leg` m along the axes to `in` (four new nodes, material 0): far from a
/// mesh, it widens the mesh's extent without touching it. Returns its
/// element index.
inline index_t append_corner_tet(ModelInput& in, Vec3<double> x0, double leg) {
  const index_t first = index_t(in.nodes.size() / 3);
  for (const Vec3<double>& x :
       {x0, x0 + Vec3<double>{leg, 0.0, 0.0}, x0 + Vec3<double>{0.0, leg, 0.0}, x0 + Vec3<double>{0.0, 0.0, leg}})
    in.nodes.insert(in.nodes.end(), {x.x, x.y, x.z});
  in.tets.insert(in.tets.end(), {first, first + 1, first + 2, first + 3});
  if (!in.elem_material.empty()) in.elem_material.push_back(0);
  return index_t(in.tets.size() / 4 - 1);
}

}  // namespace tissue::test
