// A scene's body re-meshed to another tet count (the tradeoff's coarse and
// fine meshes). The scene's tool, materials, solver settings and geometric
// constraints (box, plane) carry over unchanged; what refers to the old
// mesh's ids is moved by geometry:
//   - the built-in kidney (source "@kidney") is rebuilt as
//     io::default_kidney_scene() builds it (the same generated shape, the
//     same TetGen quality, the same hilum rule: nodes within fix_radius of
//     the hilum centre are fixed) with another target count and its surface
//     refined with it (kidney_frequency): a finer volume under the same
//     8 mm surface triangles would leave thin elements under faces larger
//     than the tool, and the contact force could not converge;
//   - any other scene is re-meshed from its mesh's boundary surface; a
//     node-list constraint fixes each new node whose nearest old node (the
//     largest barycentric corner of the old tet containing it) was fixed,
//     and element sets listing ids take each new element by the set of the
//     old element containing its centroid.
#pragma once

#include "scene/scene.hpp"

namespace tissue::accuracy {

/// The scene with its body re-meshed by TetGen to about target_tets tets
/// (io::tetrahedralize_surface's target helper, within its 5%). Throws
/// io::MeshError when TetGen fails and scene::SceneError / ModelError for a
/// scene that does not validate.
scene::Scene remesh_scene(const scene::Scene& scene, int target_tets);

/// How the built-in kidney's surface is built for remesh_scene: its
/// geodesic frequency (0: kidney_frequency of the target) and a focus
/// (io::SurfaceFocus's scale; 1: uniform) about the direction of the
/// scene's first tool at its deepest scripted point -- finer faces under
/// the tool, coarser on the far side (tissue converge).
struct KidneySurfacing {
  int frequency = 0;
  double focus = 1.0;
};

/// remesh_scene with the kidney's surface chosen (only for "@kidney";
/// throws std::invalid_argument for another scene with a focus < 1 or a
/// frequency set, or for a focus without a scripted tool).
scene::Scene remesh_scene(const scene::Scene& scene, int target_tets, const KidneySurfacing& surfacing);

/// The built-in kidney's surface frequency for a target tet count: the
/// default scene's (io::KidneyScene::frequency at its target_tets) scaled
/// by the cube root of the count, so surface and volume edges shrink
/// together; in 2..64.
int kidney_frequency(int target_tets);

}  // namespace tissue::accuracy
