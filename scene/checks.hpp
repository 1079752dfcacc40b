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
//   stop causes:  after a run stopped, the values above that most likely
//                 made it stop (stop_causes below);
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

struct SceneLoads;  // scene/validate.hpp

/// Damping alpha (1/s) per rad/s of the lowest mode above which a scene
/// warns: 100 is a damping ratio of 50 (auto is 1, critical), so the body
/// creeps with the time constant alpha / omega_1^2 = 100 / omega_1, some
/// sixteen periods of its lowest mode, instead of following the tool.
inline constexpr double kMaxDampingPerMode = 100;

/// TLED steps per haptic tick above which a scene warns about its cost
/// (the built-in kidney needs 3, typical meshes 1..20).
inline constexpr double kManyStepsPerTick = 100;

/// The mesh's pieces: elements joined through shared nodes. Returns the
/// number of pieces and, in `piece`, each node's (-1 for a node of no
/// element), numbered by their lowest element.
index_t mesh_pieces(const TissueModel<double>& m, std::vector<index_t>& piece);

/// What a run of `ticks` haptic ticks of `model` costs.
struct WorkEstimate {
  double steps_per_tick = 0;  ///< TLED steps per tick (tick / dt)
  double ticks = 0;
  double steps = 0;           ///< TLED steps in all
  double element_steps = 0;   ///< steps x elements: the unit of TLED work
  double seconds = 0;         ///< a rough wall time at the backend's nominal rates (below); the whole mesh, so
                              ///< an upper bound where a region of limited depth runs
};

/// Nominal cost of one TLED step on a backend, for WorkEstimate::seconds:
/// a fixed part (contact, reductions, launches) and a part per element.
/// Measured on the development machines and rounded up: the cpu backend on
/// 2 shared cores ran 8.2k steps/s on the kidney's 8,576 tets (1.4e-8 s an
/// element update) and 480k steps/s on a 6-tet block (2.1e-6 s a step); an
/// H200 runs the kidney's step in ~16 us and 1M tets in ~83 us.
struct StepCost {
  double per_step = 0;     ///< s
  double per_element = 0;  ///< s
};
StepCost nominal_step_cost(const std::string& backend);

/// The cost of `ticks` ticks of length `tick` (s) on `model` (its dt), its
/// time at the nominal rates of `backend` ("cpu", "cuda").
WorkEstimate estimate_work(const TissueModel<double>& model, double tick, double ticks,
                           const std::string& backend = "cpu");

/// Element updates a run may take before it is refused unless forced: 1e12,
/// hours on a workstation (the kidney's whole mesh runs ~1e8 per second on
/// a laptop CPU, ~1e9 on a GPU).
inline constexpr double kMaxElementSteps = 1e12;

/// Estimated wall seconds beyond which a run of a scene that needs more than
/// kManyStepsPerTick steps per tick is refused unless forced: such a scene
/// (E = 1e15 Pa, a density of 1e-12, nu = 0.49999) cannot run at a haptic
/// rate, is most often a unit mistake or a material beyond what was meant,
/// and its run takes minutes to hours while the warning scrolls away.
inline constexpr double kMaxSecondsAtManySteps = 10;

/// "element 12 of material 'brain' (E = .. Pa, nu = .., rho = .. kg/m^3):
/// wave speed c = .. m/s across its smallest altitude L = .. m": what sets
/// the model's stable step. `scene` must be the one `model` was loaded from.
std::string step_cause(const Scene& scene, const TissueModel<double>& model);

/// The warnings listed above, each one sentence naming the scene file, the
/// values and what to change; empty when none applies. `scene` must be the
/// one `model` was loaded from (scene::load_model).
/// A body's largest extent (m) outside which a scene warns that its
/// coordinates are likely not in metres (organs are centimetres to tens of
/// centimetres across).
inline constexpr double kMinBodyExtent = 1e-4, kMaxBodyExtent = 5.0;

std::vector<std::string> scene_warnings(const Scene& scene, const TissueModel<double>& model);

/// Materials whose incompressibility the scene's precision cannot resolve
/// (the precision rule above), one phrase each; empty when none.
std::vector<std::string> incompressibility_findings(const Scene& scene);

/// The scene's values that most likely made a run stop (NaN or an inverted
/// element), one phrase each naming the material or load, the value and the
/// range or limit it is measured against; empty when none is suspect:
///   - a material's E (from any pair of constants) outside kTissueE, its
///     density outside kTissueRho, a fibre stiffness above 1e3 x its mu;
///   - a Prony term whose tau is shorter than the step dt (it relaxes within
///     one step: a modulus that jumps, not a viscosity);
///   - a <load> whose total force over the body's largest extent squared,
///     F / L^2, is more than kMaxLoadStrain x the softest material's E (a
///     nominal strain the elements cannot follow);
///   - the incompressibility findings below and no fixed node.
/// `host_loads`, when given, are loads set through the API (set_loads) in
/// place of the scene's <load>s, measured by the same F / L^2 rule.
std::vector<std::string> stop_causes(const Scene& scene, const TissueModel<double>& model,
                                     const SceneLoads* host_loads = nullptr);

/// stop_causes as text to append to a stop's message: "\n  likely cause:"
/// and one indented line each, or else a line saying that the checks found
/// nothing and a tool most likely pressed deeper than the elements follow.
std::string stop_cause_text(const Scene& scene, const TissueModel<double>& model,
                            const SceneLoads* host_loads = nullptr);

/// The ranges stop_causes measures materials against: soft tissue spans E ~
/// 1e3..1e6 Pa and rho ~ 1000 kg/m^3; a decade beyond either end is taken as
/// the suspect's edge.
inline constexpr double kTissueE[2] = {1e2, 1e7};        ///< Pa
inline constexpr double kTissueRho[2] = {100, 1e4};      ///< kg/m^3
inline constexpr double kMaxLoadStrain = 0.5;            ///< F / (L^2 E_min)

/// Number of nodes the model fixes in any component.
index_t supported_nodes(const TissueModel<double>& model);

}  // namespace tissue::scene
