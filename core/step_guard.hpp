// The step guard: mass scaling carried on while the tissue deforms
// (variable mass scaling, as Abaqus/Explicit and LS-DYNA offer it). An
// element's stable step L_e / c_e shrinks with its smallest altitude: an
// element the tool crushes to a third of its height has a third of its
// step. Mass scaling lifts the small elements' steps to dt / safety at rest,
// so a small element under a deep press (a mesh refined where the tool
// works) can fall below dt and ring until it inverts. Every few ticks while
// a tool touches the tissue, the guard measures the deformed altitude of
// the elements near the tools whose step at rest is within a few dt, and
// gives an element whose deformed step fell below `trigger` x dt the
// density that brings it back to `target` x dt (its nodes take the added
// mass, as mass scaling's do). Static equilibria do not change; the added
// inertia is small and local (docs/accuracy.md, "The step guard").
#pragma once

#include <span>
#include <vector>

#include "core/model.hpp"
#include "core/tet.hpp"
#include "core/tool.hpp"

namespace tissue {

struct StepGuardSettings {
  bool on = true;
  int interval = 5;       ///< ticks between two checks while a tool touches the tissue (>= 1)
  double trigger = 0.7;   ///< an element whose deformed step is below trigger x dt is given mass
  double target = 1.25;   ///< the density it gets brings its step back to target x dt (> trigger): mass
                          ///< scaling's own dt / safety at the default safety 0.8
  double watch = 4.0;     ///< only elements whose step at rest is below watch x dt are watched
  /// The most mass the guard may add, a fraction of the physical mass, less what mass scaling added at
  /// rest: the scene's mass-scaling budget. 0 (no mass scaling): the guard watches nothing, as dt then
  /// keeps its safety's margin over every element but the one that sets dt_crit.
  double budget = 0.025;
};

/// What a check gave.
struct StepGuardLift {
  index_t elements = 0;       ///< elements given mass
  double added_mass = 0;      ///< kg, at this check
  double worst = 0;           ///< the smallest deformed step among the checked, over dt (0: none checked)
  index_t worst_elem = -1;
  index_t refused = 0;        ///< elements that needed more mass than the budget has left (not given any)
};

class StepGuard {
 public:
  StepGuard() = default;
  /// Watches the elements of `m` whose step at rest (TissueModel::elem_step)
  /// is below settings.watch x m.dt, where mass scaling raised some
  /// (m.scaled_elems > 0) and the budget is > 0. Throws std::invalid_argument
  /// for settings out of range (naming the setting).
  StepGuard(const TissueModel<double>& m, const StepGuardSettings& settings);

  bool watching() const { return !elems_.empty(); }
  std::size_t watched() const { return elems_.size(); }

  /// The watched elements that may be under a tool: its ball about its
  /// centroid (through its farthest corner) within `reach` (m) of a tool's
  /// capsule, at rest (the caller adds how far the tissue has moved to
  /// `reach`).
  std::vector<index_t> near(std::span<const ToolShape> shapes, std::span<const ToolPose> poses, double reach) const;

  /// Checks elements (from near()) whose deformed smallest altitudes are
  /// `altitude` (m, one each): where the step falls below trigger x dt,
  /// raises the element's density so that it is target x dt again, adding
  /// the mass to its corners' entries of `mass` (the nodal masses, n_nodes
  /// kg; the caller takes them into the model and its central difference's
  /// constants, set_time_step), within the budget. A non-positive or
  /// non-finite altitude is left to the health check (an inverted element).
  StepGuardLift lift(const TissueModel<double>& m, std::span<double> mass, std::span<const index_t> elems,
                     std::span<const double> altitude);

  /// kg added since construction.
  double added_mass() const { return added_; }

 private:
  StepGuardSettings settings_;
  std::vector<index_t> elems_;   ///< watched elements, ascending
  std::vector<Vec3<double>> centre_;  ///< their centroids at rest (m), by watched position
  std::vector<double> bound_;    ///< their farthest corner's distance from it (m)
  std::vector<double> rest_alt_; ///< their smallest altitude at rest (m), by element id
  std::vector<double> step_;     ///< every element's step at rest with the guard's density (s), by element id
  std::vector<double> mass_;     ///< every element's mass with the guard's density (kg), by element id
  double added_ = 0;
  double left_ = 0;  ///< kg the budget has left
};

/// The smallest altitude of element e of `m` at displacements u (3 x n_nodes,
/// component-major, m; double, or a backend's float): 3 V / (the largest
/// face area); 0 where the deformed element is inverted or flat (V <= 0).
template <class U>
double deformed_altitude(const TissueModel<double>& m, std::span<const U> u, index_t e) {
  const std::size_t n = m.n_nodes;
  Vec3<double> x[4];
  for (int a = 0; a < 4; ++a) {
    const index_t i = m.elem_nodes[std::size_t(a) * m.n_elems + e];
    x[a] = reference_position(m, i) + Vec3<double>{double(u[i]), double(u[n + i]), double(u[2 * n + i])};
  }
  const double V = dot(x[1] - x[0], cross(x[2] - x[0], x[3] - x[0])) / 6;
  return V > 0 ? tet_min_altitude(x, V) : 0.0;
}

}  // namespace tissue
