// Structured tetrahedral meshes of a box: tests, benchmarks and verification.
#pragma once

#include "core/model.hpp"

namespace tissue {

/// A box [0, lx] x [0, ly] x [0, lz] (m) of nx x ny x nz hexahedral cells,
/// each split into 6 positively oriented tets around its main diagonal
/// (conforming across cells). Fills nodes and tets of `in` (node id
/// i + (nx+1) (j + (ny+1) k) for grid point (i, j, k)); leaves the rest.
/// Elements: 6 nx ny nz; nodes: (nx+1)(ny+1)(nz+1).
void box_mesh(ModelInput& in, int nx, int ny, int nz, double lx, double ly, double lz);

/// Node id of grid point (i, j, k) in box_mesh's numbering.
inline index_t box_node(int nx, int ny, int i, int j, int k) { return i + (nx + 1) * (j + (ny + 1) * k); }

}  // namespace tissue
