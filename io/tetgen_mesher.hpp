// Volume meshing of a closed surface through the TetGen library (tetgen.h,
// tetrahedralize(char* switches, ...)), not its executable.
//
// Switches used: p (the input is a piecewise linear complex), z (zero-based
// ids), Q (quiet), q<ratio>/<min dihedral> (quality: radius-edge bound and
// minimum dihedral angle), O<level> (mesh optimisation passes), a<volume>
// (maximum tet volume), A (region attributes, for inclusions) and, for the
// self-intersection pre-check, d. docs/meshing.md gives the measurements
// behind the defaults. Debian's libtet is built with
// TETLIBRARY, so TetGen reports failure by throwing an int; every such code is
// caught and turned into a MeshError naming the source and the cause.
#pragma once

#include <string>
#include <vector>

#include "core/hd.hpp"
#include "io/surface_import.hpp"

namespace tissue::io {

/// tissue mesh's TetGen defaults, chosen from the measurements in
/// docs/meshing.md: the minimum dihedral angle bound of q and the O level.
inline constexpr double kDefaultMinDihedral = 10;
inline constexpr int kDefaultOptimise = 4;

/// A point inside a closed sub-surface and the region attribute its tets get.
struct RegionSeed {
  Vec3<double> point;  ///< m
  int attribute = 1;   ///< > 0; tets outside every seeded region get 0
};

/// TetGen settings.
struct MeshingOptions {
  double quality = 1.414;    ///< maximum radius-edge ratio (q switch); must be >= 1 (TetGen may not end below); 0 = no q
  double min_dihedral = 0;   ///< minimum dihedral angle bound of the q switch (degrees, in [0, 30]); 0 = TetGen's own
  int optimise = 2;          ///< optimisation level of the O switch (0..10; TetGen's default 2)
  double max_volume = 0;     ///< maximum tet volume (a switch) m^3; 0 = none
  int target_tets = 0;       ///< aim at this many tets by iterating max_volume (see kTargetTolerance); 0 = off.
                             ///< When > 0 it replaces max_volume.
  std::vector<RegionSeed> regions;  ///< sub-regions (A switch): VolumeMesh::tet_region
  Progress progress;         ///< one line per TetGen run; empty = silent
};

/// A tetrahedral mesh in SI units. Every tet is positively oriented
/// (signed volume > 0 with core/tet.hpp's convention) and every node is a
/// corner of some tet.
struct VolumeMesh {
  std::vector<double> nodes;  ///< positions (n_nodes x 3, xyz interleaved) m
  std::vector<index_t> tets;  ///< corner node ids (n_tets x 4)
  std::vector<int> tet_region;  ///< region attribute per tet (n_tets); empty without MeshingOptions::regions
  double max_volume = 0;      ///< the a switch of the run that produced it (m^3); 0 = none
  int runs = 0;               ///< TetGen runs it took (1 without a target)
  double peak_bytes = 0;      ///< largest resident size of a TetGen child (bytes)

  index_t n_nodes() const { return static_cast<index_t>(nodes.size() / 3); }
  index_t n_tets() const { return static_cast<index_t>(tets.size() / 4); }
  Vec3<double> node(index_t i) const { return {nodes[3 * i], nodes[3 * i + 1], nodes[3 * i + 2]}; }
};

/// Relative tolerance of the target-count helper: the iteration stops as soon
/// as |n_tets - target| <= kTargetTolerance * target; otherwise it returns
/// the closest of kTargetRounds runs. Targets well above the count the
/// surface alone forces (a few times its triangle count) land inside it.
inline constexpr double kTargetTolerance = 0.05;
/// Most TetGen runs the target-count helper makes.
inline constexpr int kTargetRounds = 8;

/// Memory a TetGen run needs per output tet (bytes), measured (the child's
/// peak resident size over its tet count, docs/meshing.md) with a margin;
/// used to refuse a target that cannot fit before any run starts.
inline constexpr double kBytesPerTet = 600;

/// Throws MeshError naming `source`, `what` was asked ("a target of 50000000
/// tets") and the memory needed when `tets` tets at `bytes_per_tet` do not
/// fit in the memory available.
void check_tet_memory(double tets, double bytes_per_tet, const std::string& what, const std::string& source);

/// Memory the system has available now (bytes; MemAvailable of
/// /proc/meminfo, or physical memory when it cannot be read).
double available_memory();

/// Tetrahedralises the closed surface: check_closed() first, then a TetGen
/// self-intersection check (d switch), then the meshing run (or, with
/// target_tets > 0, the target-count iteration: max_volume starts at the
/// enclosed volume / target and is multiplied by n_tets / target after each
/// run, up to kTargetRounds runs). Throws MeshError starting with `source`
/// for an open or self-intersecting surface, bad options or any TetGen
/// failure, e.g. "part.stl: the surface intersects itself (24 triangles
/// involved, e.g. 3, 4, 17, 18)". Each TetGen run happens in a forked child
/// process (libtet 1.5.0 double-frees after its own errors; see the .cpp), so
/// no TetGen failure can take the caller down. The child dies with its parent
/// (PR_SET_PDEATHSIG), SIGINT/SIGTERM/SIGHUP during a run kill it before the
/// parent goes, and its address space is limited to the memory available.
/// A target (or max_volume) whose tets need more than the available memory
/// (kBytesPerTet) is refused before any run, naming the memory it needs.
/// The mesh comes numbered for locality (sort_for_locality).
VolumeMesh tetrahedralize_surface(const SurfaceMesh& surface, const MeshingOptions& options, const std::string& source);

/// The TetGen switch string for one meshing run ("pzQq1.414/12O4a1e-08",
/// ...; /<min dihedral> only when set, O only when not TetGen's default 2,
/// A with regions); throws MeshError for a quality in (0, 1), a minimum
/// dihedral outside [0, 30], an optimisation level outside 0..10, a negative
/// or non-finite max_volume.
std::string tetgen_switches(const MeshingOptions& options, const std::string& source);

/// Sum of the tets' volumes (m^3).
double total_volume(const VolumeMesh& mesh);

/// Renumbers the mesh's nodes and tets along a Morton (Z-order) curve
/// through the mesh's bounding box: nodes by their positions, tets by their
/// centroids (ties by their old order), each tet's corners in the same
/// order (its orientation kept). Neighbours in space get nearby numbers,
/// so a contiguous range of tets touches a compact set of nodes: what a
/// thread's slice of the cpu passes and a warp's gathers on the GPU read.
/// The mesh is the same; only its numbering changes. A mesh with a
/// non-finite position is left as it is; a region list of another length
/// than the tets is refused (MeshError).
void sort_for_locality(VolumeMesh& mesh);

}  // namespace tissue::io
