// Volume meshing through CGAL Mesh_3 (Delaunay refinement of a polyhedral
// domain) followed by sliver perturbation and sliver exudation: the
// alternative to TetGen that docs/meshing.md measures against it. CGAL stays
// inside cgal_mesher.cpp.
#pragma once

#include <string>

#include "io/tetgen_mesher.hpp"

namespace tissue::io {

struct Mesh3Options {
  double cell_size = 0;        ///< largest tet circumradius (m); 0 = from target_tets
  std::string cell_size_from;  ///< what set cell_size, for messages ("--max-volume 1e-15"); "" = the size itself
  int target_tets = 0;         ///< aim at this many tets (cell size iterated, up to kMesh3Rounds runs)
  double sliver_bound = 18;    ///< dihedral angle (degrees) perturbation and exudation aim above
  double time_limit = 30;      ///< seconds for each of perturbation and exudation
  Progress progress;           ///< one line per run
};

/// Memory Mesh_3 needs per tet (bytes): the process's peak resident size
/// over its tet count, measured (docs/meshing.md), with a margin.
inline constexpr double kMesh3BytesPerTet = 2000;

/// Most Mesh_3 runs the target-count iteration makes.
inline constexpr int kMesh3Rounds = 4;

/// Meshes the closed surface with Mesh_3 (facets: angle >= 25 degrees, size
/// <= cell size, no bound on their distance to the input, which follows
/// from the surface's own resolution; cells: radius-edge <= 2, circumradius
/// <= cell size), then perturbs and exudes slivers.
/// Every tet positively oriented. Throws MeshError naming `source` for an
/// open surface, bad options or an empty result.
VolumeMesh mesh3_surface(const SurfaceMesh& surface, const Mesh3Options& options, const std::string& source);

}  // namespace tissue::io
