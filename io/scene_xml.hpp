// The XML scene format (docs/scene-format.md has the full reference and an
// example): <tissue-scene version="1"> holding one <mesh> (inline <nodes> and
// <elements>, or file="x.node" for a TetGen pair beside the scene file),
// <material>s, <element-set>s, <fixed> constraints, <tool>s and a <solver>.
//
// Reading is strict: unknown elements or attributes (typos), missing required
// attributes, numbers that are not entirely numbers ("3e", "abc") and
// malformed XML are SceneErrors whose message starts with "<file>:<line>: "
// and names the element and attribute. Reading checks the syntax only; the
// scene's rules (materials, sets, constraints, ...) are checked by
// scene::validate / to_model_input, which cite the same lines.
#pragma once

#include <string>
#include <string_view>

#include "scene/scene.hpp"
#include "scene/validate.hpp"

namespace tissue::io {

/// Reads a scene file; a mesh file, tool path files and fibre direction files
/// are resolved relative to the scene file's folder and loaded
/// (Scene::nodes/tets, Tool::path, Material::fibre_rows).
/// Scene::source is `path`. Throws scene::SceneError.
scene::Scene read_scene(const std::string& path);

/// Parses scene XML held in memory. `source` names it in messages and becomes
/// Scene::source; `base_dir` is the folder that relative file references
/// (mesh file, tool path CSV, fibre CSV) are resolved against ("" = the working folder).
/// Throws scene::SceneError.
scene::Scene parse_scene(std::string_view xml, const std::string& source, const std::string& base_dir);

/// Writes the scene as XML to `path`, numbers with round-trip precision, so
/// that read_scene(path) gives the same scene (up to source lines). With
/// inline_mesh the mesh goes into the XML; otherwise into a TetGen .node/.ele
/// pair beside it, named Scene::mesh_file if set, else "<stem of path>.node"
/// (a scene of bodies: one pair per body, its Body::mesh_file if set, else
/// "<stem>-<body name>.node"; each body's ids are its own mesh's again).
/// A tool with a path_file gets its path written to that CSV, and a material
/// with a fibre file its rows to that CSV (both relative to path's folder). Each file is written whole under "<name>.part" and renamed
/// (io/atomic_file.hpp). Throws std::runtime_error when a file cannot be written.
void write_scene(const scene::Scene& scene, const std::string& path, bool inline_mesh);

/// The XML text write_scene writes (no files touched). mesh_file: "" puts the
/// mesh inline, otherwise <mesh file="mesh_file"/> is written (with bodies,
/// each body's file as write_scene names it from mesh_file).
std::string format_scene(const scene::Scene& scene, const std::string& mesh_file);

}  // namespace tissue::io
