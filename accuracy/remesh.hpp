// A scene's body re-meshed to another tet count (the tradeoff's coarse and
// fine meshes). The scene's tool, materials, solver settings and geometric
// constraints (box, plane) carry over unchanged; what refers to the old
// mesh's ids is moved by geometry:
//   - the built-in kidney (source "@kidney") is rebuilt exactly as
//     io::default_kidney_scene() builds it (the same generated surface, the
//     same TetGen quality, the same hilum rule: nodes within fix_radius of
//     the hilum centre are fixed), only with another target count;
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

}  // namespace tissue::accuracy
