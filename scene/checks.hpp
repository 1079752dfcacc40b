// Checks of a valid scene that may still not do what its author meant: the
// scene loads and runs, but the result would be meaningless or the cost
// absurd. Each finding is a warning (the commands print them before
// running) or, for the work estimate, a refusal the commands lift with
// --force. The rules:
//   mesh:         inverted input tets (negative volume) that the model
//                 reoriented, counted (TissueModel::reoriented);
//   support:      no node fixed (the tool pushes the body away as a rigid
//                 body: no equilibrium, a `tissue reference` cannot
//                 converge); every node fixed (nothing can move); a
//                 disconnected piece of the mesh with no node fixed while
//                 the rest is held (that piece is pushed away); a <load>
//                 whose force lands only on fixed nodes (the support takes it);
//   tool path:    a haptic tick longer than the whole scripted path of
//                 any tool (that tool jumps from its first to its last
//                 waypoint in one tick); a tick outside 1e-5..0.1 s (far from a haptic
//                 device's 1 ms);
//   damping:      a damping alpha more than kMaxDampingPerMode times the
//                 lowest mode's omega_1 (the body creeps instead of responding);
//   cost:         more than kManyStepsPerTick TLED steps per tick, naming
//                 the element, its material and wave speed that set the step;
//   precision:    a material so nearly incompressible that the precision's
//                 rounding of J moves the pressure by more than 1 % of the
//                 shear modulus (K / mu x epsilon > 1e-2): the run may stop
//                 with an inverted element, NaN, or a pressure of noise.
#pragma once

#include <string>
#include <vector>

#include "core/model.hpp"
#include "scene/scene.hpp"

namespace tissue::scene {

/// Damping alpha (1/s) per rad/s of the lowest mode above which a scene
/// warns: 100 is a damping ratio of 50 (auto is 1, critical), so the body
/// creeps with the time constant alpha / omega_1^2 = 100 / omega_1, some
/// sixteen periods of its lowest mode, instead of following the tool.
inline constexpr double kMaxDampingPerMode = 100;

/// TLED steps per haptic tick above which a scene warns about its cost
/// (the built-in kidney needs 3, typical meshes 1..20).
inline constexpr double kManyStepsPerTick = 100;

/// What a run of `ticks` haptic ticks of `model` costs.
struct WorkEstimate {
  double steps_per_tick = 0;  ///< TLED steps per tick (tick / dt)
  double ticks = 0;
  double steps = 0;           ///< TLED steps in all
  double element_steps = 0;   ///< steps x elements: the unit of TLED work
};

/// The cost of `ticks` ticks of length `tick` (s) on `model` (its dt).
WorkEstimate estimate_work(const TissueModel<double>& model, double tick, double ticks);

/// Element updates a run may take before it is refused unless forced: 1e12,
/// hours on a workstation (the kidney's whole mesh runs ~1e8 per second on
/// a laptop CPU, ~1e9 on a GPU).
inline constexpr double kMaxElementSteps = 1e12;

/// "element 12 of material 'brain' (E = .. Pa, nu = .., rho = .. kg/m^3):
/// wave speed c = .. m/s across its smallest altitude L = .. m": what sets
/// the model's stable step. `scene` must be the one `model` was loaded from.
std::string step_cause(const Scene& scene, const TissueModel<double>& model);

/// The warnings listed above, each one sentence naming the scene file, the
/// values and what to change; empty when none applies. `scene` must be the
/// one `model` was loaded from (scene::load_model).
std::vector<std::string> scene_warnings(const Scene& scene, const TissueModel<double>& model);

/// Materials whose incompressibility the scene's precision cannot resolve
/// (the precision rule above), one phrase each; empty when none.
std::vector<std::string> incompressibility_findings(const Scene& scene);

/// Number of nodes the model fixes in any component.
index_t supported_nodes(const TissueModel<double>& model);

}  // namespace tissue::scene
