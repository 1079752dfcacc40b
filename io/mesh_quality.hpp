// Tet mesh quality as the solver pays for it (docs/meshing.md): the stable
// step is set by the worst element (core build_model's dt_crit = min_e L_e /
// c_e), so a sliver costs steps. The report gives the dihedral angles, the
// worst element's step against the median element's, and the selective mass
// scaling that the scene's default budget would add (core
// choose_mass_scaling) to run the fewest steps per haptic tick.
#pragma once

#include <string>
#include <vector>

#include "core/model.hpp"
#include "io/tetgen_mesher.hpp"

namespace tissue::io {

/// The six dihedral angles of the tet X (radians, in [0, pi]), one per edge
/// (01, 02, 03, 12, 13, 23).
void tet_dihedral_angles(const Vec3<double> X[4], double angles[6]);

/// What the mesh costs the solver.
/// The dt_crit / median L/c the meshing aims at: at least 0.25, so that 4
/// steps a tick need at most x16 density on the worst elements
/// (docs/meshing.md).
inline constexpr double kDtRatioGoal = 0.25;

struct QualityReport {
  index_t n_tets = 0, n_nodes = 0;
  double min_dihedral = 0;      ///< smallest dihedral angle of any tet (degrees)
  double median_dihedral = 0;   ///< median of the tets' smallest dihedral angles (degrees)
  index_t below_10 = 0;         ///< tets whose smallest dihedral angle is under 10 degrees
  double dt_crit = 0;           ///< min_e L_e / c_e (s)
  index_t dt_crit_elem = -1;    ///< the element that sets it
  double dt_median = 0;         ///< the median element's L_e / c_e (s)
  MassScaling mass;             ///< what the budget below would add (steps per tick, added mass, ...)
  int steps_unscaled = 0;       ///< steps per tick at safety * dt_crit without mass scaling
  double budget = 0;            ///< mass-scaling budget used (fraction of the total mass)
  double tick = 0;              ///< haptic period used (s)
  double safety = 0;            ///< dt safety factor used
  double total_mass = 0;        ///< kg
  /// The element that sets dt_crit: its centroid (m), its shortest and
  /// longest edges and its smallest dihedral angle; the median element's
  /// longest edge (m), for scale.
  Vec3<double> worst_centroid = {0, 0, 0};
  double worst_min_edge = 0, worst_max_edge = 0, worst_dihedral = 0, median_edge = 0;

  /// dt_crit / dt_median: 1 for a mesh of equal tets, -> 0 with a sliver.
  double dt_ratio() const { return dt_median > 0 ? dt_crit / dt_median : 0; }
  /// A few lines for the user; below kDtRatioGoal, where the worst
  /// element lies and how it compares with the median.
  std::string summary() const;
};

/// Measures the mesh: materials per tet from `tet_material` (index into
/// `materials`; empty = all 0), the solver's haptic tick (s), dt safety
/// factor and mass-scaling budget (scene::Solver's defaults: 1 ms, 0.9,
/// 0.025).
QualityReport mesh_quality(const VolumeMesh& mesh, const std::vector<MaterialParams>& materials,
                           const std::vector<index_t>& tet_material, double tick, double safety, double budget);

}  // namespace tissue::io
