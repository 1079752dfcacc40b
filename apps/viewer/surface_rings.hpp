// The surface's one-ring lists the viewer's smooth shading reads
// (apps/viewer/renderer.hpp): GL-free, so that tests can check them.
#pragma once

#include <cstdint>
#include <vector>

#include "core/model.hpp"

namespace tissue::viewer {

/// Each node's surface triangles as the vertex shader reads them: per node
/// (first, count) into `corners`, which holds for every triangle at the
/// node its other two corners in the triangle's outward (counter-clockwise)
/// order, so cross(x_b - x_a, x_c - x_a) summed over them is the node's
/// area-weighted outward normal (twice the area). Nodes off the surface
/// have count 0.
struct SurfaceRings {
  std::vector<std::int32_t> range;    ///< 2 per node: first pair, number of pairs
  std::vector<std::int32_t> corners;  ///< 2 per (triangle, corner): the other corners b, c
};
SurfaceRings surface_rings(const TissueModel<double>& model);

/// 1 for each surface triangle a cut made, 0 for the others: a cut's faces
/// are the surface triangles with a twin, another surface triangle on the
/// same reference corners (the two faces one interior face became,
/// docs/cutting.md).
std::vector<std::uint8_t> cut_faces(const TissueModel<double>& model);

}  // namespace tissue::viewer
