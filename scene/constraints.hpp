// Which mesh nodes a scene constraint fixes. A box selects the nodes with
// lo - tol <= x <= hi + tol on every axis; a plane selects the nodes on the
// side its normal points to, (x - point) . n / |n| >= -tol. The tolerance
// (selection_tolerance) lets a box or plane placed exactly on a mesh face
// catch that face's nodes despite rounding in the coordinates.
#pragma once

#include <span>
#include <string>
#include <vector>

#include "scene/scene.hpp"

namespace tissue::scene {

/// Geometric tolerance of box and plane selection (m): 1e-9 x the largest
/// extent of the node bounding box. nodes: (n_nodes x 3) m, xyz interleaved.
double selection_tolerance(std::span<const double> nodes);

/// Ids of the nodes `c` fixes, ascending and unique. nodes: (n_nodes x 3) m,
/// xyz interleaved; tol in m. A selection of a body (c.body >= 0, an index
/// into `bodies`) picks among that body's nodes only. Node-list ids outside
/// [0, n_nodes) or outside the body are skipped (scene validation reports
/// them). A plane with a zero normal selects none.
std::vector<index_t> constrained_nodes(const Constraint& c, std::span<const double> nodes, double tol,
                                       std::span<const Body> bodies = {});

/// The constraint in words, for messages: "fixed nodes", "fixed box
/// min (x, y, z) max (x, y, z)" or "fixed plane point (..) normal (..)".
std::string describe(const Constraint& c);

}  // namespace tissue::scene
