// Real organ surfaces to tetrahedra (docs/meshing.md): repair each surface
// (io/surface_repair), check the inclusions lie inside the organ, remesh
// surfaces that are finer than the target needs, then one conforming TetGen
// run over the organ and its inclusions, each inclusion its own region.
#pragma once

#include <string>
#include <vector>

#include "io/surface_repair.hpp"
#include "io/tetgen_mesher.hpp"

namespace tissue::io {

/// A surface with the name used in messages (its file).
struct NamedSurface {
  SurfaceMesh surface;
  std::string source;
};

/// Which volume mesher runs (docs/meshing.md compares them).
/// Auto: Mesh3 for a body alone (it meets the quality goal, TetGen does not:
/// docs/meshing.md), TetGen when there are inclusions (its region attributes
/// mesh them conformingly) or no size is given.
enum class Mesher { Auto, TetGen, Mesh3 };

struct OrganMeshOptions {
  Mesher mesher = Mesher::Auto;  ///< Mesh3: CGAL Mesh_3 with sliver perturbation and exudation (no inclusions)
  bool repair = true;             ///< false: surfaces must already be closed and clean (check_closed's errors)
  RepairOptions repair_options;
  double remesh_edge = 0;         ///< m; 0 = auto (see organ_edge_length), < 0 = never remesh
  int remesh_passes = 3;          ///< isotropic remeshing passes
  /// Mesh_3 with a size (a body alone): replace the repaired organ by its
  /// alpha wrap at alpha = kWrapAlpha x the target edge (wrap_surface), so
  /// that no groove, fold or gap narrower than the elements the size asks
  /// for forces smaller ones (docs/meshing.md, "Elements no smaller than
  /// the size asks"). false: mesh the surface as repaired.
  bool wrap = true;
  MeshingOptions meshing;         ///< TetGen settings (regions are set here, from the inclusions)
};

/// What happened to one surface.
struct SurfaceSteps {
  std::string source;
  bool repaired = false;          ///< repair ran (OrganMeshOptions::repair)
  RepairReport repair;
  index_t triangles_in = 0;       ///< as read
  double wrapped_alpha = 0;       ///< the alpha wrap's alpha (m); 0 = not wrapped
  double wrap_volume_change = 0;  ///< the wrap's relative change of the enclosed volume
  double remeshed_to = 0;         ///< edge length it was remeshed to (m); 0 = not remeshed
  index_t triangles_out = 0;      ///< as tetrahedralised
};

struct OrganMesh {
  VolumeMesh mesh;                ///< tet_region: 0 = organ tissue, k = inclusion k (1-based)
  std::vector<SurfaceSteps> surfaces;  ///< organ first, then the inclusions in order
  double target_edge = 0;         ///< the edge length the size asks for (m); 0 = no size given
  Mesher mesher = Mesher::TetGen; ///< the mesher that ran
};

/// The alpha wrap's alpha and offset, as fractions of the target edge a:
/// a ball of a / 2 closes what is narrower than about a, and a / 50 of
/// offset keeps the wrap within 2 % of a outside the surface (measured on
/// five organ surfaces at 10k-40k tets: docs/meshing.md).
inline constexpr double kWrapAlpha = 0.5, kWrapOffset = 0.02;

/// Remeshing rule (auto): a surface is remeshed to the target edge a when its
/// mean edge is under kRemeshBelow * a (it would force more tets than the
/// target), or, with no size given, when it has more than kMaxTriangles
/// triangles (to the edge that gives about kMaxTriangles / 4). a is the edge
/// of a regular tet of the mean volume the size asks for: volume / target
/// or max_volume, a = (6 sqrt(2) v)^(1/3). An inclusion is remeshed to at
/// most a tenth of its bounding-box diagonal, so that it keeps its shape.
inline constexpr double kRemeshBelow = 0.5;
/// --target-tets holds within this fraction: when the surface alone forces
/// more tets (TetGen's count no longer falls with the volume bound), the
/// organ surface is remeshed coarser by (count / target)^(1/3) and meshed
/// again (at most 3 times; not when the remesh edge was given).
inline constexpr index_t kMaxTriangles = 50000;
inline constexpr double kTargetPromise = 0.15;

/// Edge of a regular tet of volume v (m^3): (6 sqrt(2) v)^(1/3).
double regular_tet_edge(double volume);

/// Runs the whole pipeline; throws MeshError naming the surface and the rule
/// broken (a surface that cannot be repaired, an inclusion not inside the
/// organ or overlapping another, TetGen failures).
OrganMesh mesh_organ(NamedSurface organ, std::vector<NamedSurface> inclusions, const OrganMeshOptions& options);

/// A warning when the body's largest extent (m) is implausible for an
/// organ (over 1 m or under 5 mm) with the unit the file was read in, naming
/// the unit that makes it plausible ("... try --unit mm"); empty otherwise.
std::string unit_warning(double max_extent, const std::string& unit);

}  // namespace tissue::io
