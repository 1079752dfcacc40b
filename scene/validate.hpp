// Scene validation and its translation into core inputs. Every rule broken
// gives a SceneError whose message reads
//     "<file>:<line>: <what> ... <rule>"
// (just "<file>: " when the scene was built in code and has no line), naming
// the material, element set, element, node, tool or solver setting at fault.
// The rules, in the order they are checked (the first broken one is reported):
//   mesh:        coordinates and corner counts, finite coordinates, corner ids in range;
//   bodies:      (a scene of <body>s) names non-empty and unique; node and
//                element ranges consecutive in body order and covering the
//                mesh; each body with an element, its elements using only
//                its own nodes; every set, constraint and load naming a
//                body that exists, and only its elements or nodes;
//   materials:   names unique and non-empty; numbers finite; rho > 0;
//                (E, nu): E > 0 and -1 < nu < 0.5; (mu, K): mu > 0, K > 0;
//                Lame (lambda, mu): mu > 0 and K = lambda + 2 mu / 3 > 0;
//                fibre stiffness >= 0 and direction finite and non-zero; a
//                fibre field's axis finite and non-zero, its origin finite; a
//                fibre file named and giving rows; Prony g > 0, tau > 0, sum g < 1;
//   sets:        material defined; element ids in range; no element twice
//                (within or across sets); every element in a set;
//   fibres:      (scene/fibre_field.hpp) a fibre file's rows: element in
//                range, listed once, direction finite and non-zero (cited at
//                the file's line), and at least one of its material's elements
//                listed; a fibre field's axis off every element centroid;
//   constraints: node ids in range; numbers finite; box min <= max; plane
//                normal non-zero; every constraint fixes at least one node;
//   tools:       radius finite, > 0, at most half the body's largest
//                extent and at least 1e-6 of it; shaft-length >= 0 and within
//                1000 mesh sizes (bounding-box diagonals); direction
//                non-zero; device scripted | mouse | phantom; a scripted tool
//                has a path; waypoints (tip and axis) finite with increasing
//                t, tips within 1000 mesh sizes of the mesh; names unique;
//   solver:      backend cpu | cuda; numbers finite; dt > 0 or unset (auto);
//                0 < dt-safety < 1; 0 <= mass-scaling < 1; damping >= 0 or
//                unset (auto); depth >= 0, kDepthAll (-1) or kDepthAuto (-2);
//                tick > 0; residual-tol > 0; kinetic-tol > 0.
// The mesh geometry itself (zero-volume tets, unused nodes, dt above the
// stable limit) is checked by core build_model(), whose ModelError names the
// scene file (ModelInput::source) and the element or node.
#pragma once

#include <algorithm>

#include <span>
#include <stdexcept>
#include <string>

#include "core/model.hpp"
#include "core/scheduler.hpp"
#include "core/vec.hpp"
#include "scene/scene.hpp"

namespace tissue::scene {

/// A scene rule broken; the message starts with "<file>:<line>: ".
struct SceneError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// Tool tips (scene waypoints and poses a host sets) must lie within
/// kToolReach mesh sizes of the mesh's bounding box: farther is a unit or
/// typing mistake, and coordinates that overflow a float break the collision
/// query.
inline constexpr double kToolReach = 1000;
/// A node lying beyond the other nodes on an axis by more than this many
/// times their span there is refused as a stray coordinate, named.
inline constexpr double kStrayNodeGap = 1000;

/// The axis-aligned bounding box of xyz-interleaved node coordinates and its
/// diagonal, the mesh size the tool reach is measured in.
struct MeshBox {
  Vec3<double> lo, hi;
  double size = 0;  ///< |hi - lo| (m)
  /// The box's largest side (m; 0 for no nodes).
  double largest_extent() const { return std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z, 0.0}); }
  /// How far p lies outside the box (0 inside).
  double distance(const Vec3<double>& p) const;
};
MeshBox mesh_box(std::span<const double> nodes);

/// "<source>:<line>", or just "<source>" when line is 0 (unknown).
std::string location(const Scene& scene, int line);

/// Checks every rule listed above; throws SceneError for the first one broken.
void validate(const Scene& scene);

/// Checks one material by the materials' rules above (for a tool that makes
/// a scene, such as tissue mesh, before it does any work); throws SceneError
/// naming scene.source and the material.
void validate_material(const Scene& scene, const Material& material);

/// Validates the scene and resolves it for build_model(): nodes and tets
/// copied, element sets turned into one material index per element (the
/// index of the set's material in scene.materials), materials into
/// (mu, K, rho) and their terms, fibre fields and files into one direction
/// per element (fibre_dirs; empty when every material has one direction),
/// constraints into the `fixed` mask (n_nodes, 1 = fixed), and
/// the solver's dt, dt_safety, damping and ianp plus the scene's source name
/// copied. Throws SceneError.
ModelInput to_model_input(const Scene& scene);

/// The scene's loads on its model (load_model(scene)) as Backend::set_loads
/// / Scheduler::set_loads take them: each loaded node once (ascending) with
/// its summed force (N, xyz). A <load>'s force is its total, spread over the
/// model's surface triangles whose three corners its selection picks in
/// proportion to their area, a third of each triangle's share to each corner
/// (the consistent nodal loads of a uniform traction); with
/// distribute="each" every selected node gets the force. Throws SceneError
/// (file:line) for a bad selection, a non-finite force, a selection of no
/// node (to_model_input checks these three first), or an area load that
/// selects no surface triangle.
struct SceneLoads {
  std::vector<index_t> nodes;
  std::vector<double> force;  ///< 3 per node
};
SceneLoads resolve_loads(const Scene& scene, const TissueModel<double>& model);

/// Gives the scene's loads to the scheduler (Scheduler::set_loads, which
/// also seeds a region of limited depth with them); nothing without loads.
void apply_loads(const Scene& scene, const TissueModel<double>& model, Scheduler& scheduler);

/// build_model(to_model_input(scene)): throws SceneError for scene rules and
/// core ModelError (naming the source and the element or node) for the mesh
/// geometry: zero-volume tets, unused nodes, a dt above the stable limit.
/// The step is then shortened so that whole steps fill one haptic tick
/// (core align_time_step).
TissueModel<double> load_model(const Scene& scene);

/// The Scheduler's settings from the validated solver section (depth, tick,
/// tolerances) and the tools (shape and direction, scene order). Throws
/// SceneError for a broken solver or tool rule.
SchedulerSettings scheduler_settings(const Scene& scene);

}  // namespace tissue::scene
