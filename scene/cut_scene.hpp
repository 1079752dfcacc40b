// A scene cut along the surface a blade sweeps (core/cut.hpp,
// docs/cutting.md): the mesh is replaced by the cut one and what refers to
// its nodes and elements follows them.
#pragma once

#include "core/cut.hpp"
#include "scene/scene.hpp"

namespace tissue::scene {

/// The scene with its mesh cut along `cut` (core cut_along). An element
/// set's list carries over to the pieces of its elements; a <fixed> or
/// <load> node list to the copies of its nodes and to the nodes made on an
/// edge between two of them; box and plane selections are geometric and
/// stay; a fibre file's rows follow their elements. The mesh becomes inline
/// (Scene::mesh_file cleared). `result` (may be null) receives the cut's
/// counts and maps. Throws SceneError (validate.hpp) for a scene of bodies,
/// CutError for a bad cut.
Scene cut_scene(const Scene& scene, const CutSurface& cut, const CutOptions& options, CutResult* result = nullptr);

/// The scene with its mesh replaced by a cut's (`r`, of this scene's mesh),
/// what refers to nodes and elements following them as cut_scene says.
Scene scene_after_cut(const Scene& scene, const CutResult& r);

/// Throws SceneError for a scene that cutting does not take (several bodies).
void check_cuttable(const Scene& scene);

}  // namespace tissue::scene
