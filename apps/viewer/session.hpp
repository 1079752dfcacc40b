// The viewer's simulation session, free of OpenGL: the scene, the initial
// live parameters read from it, the factory that (re)builds the simulation
// for the haptic loop, and the geometry the display needs up front (the
// organ's bounds, where the tool starts and which way it presses).
#pragma once

#include <string>

#include "haptics/haptic_loop.hpp"
#include "scene/scene.hpp"

namespace tissue::viewer {

/// Axis-aligned box (m).
struct Bounds {
  Vec3<double> lo = {0, 0, 0}, hi = {0, 0, 0};
  Vec3<double> center() const { return 0.5 * (lo + hi); }
  double diagonal() const { return norm(hi - lo); }
};

/// Young's modulus and Poisson's ratio of a Neo-Hookean (mu, K) pair:
/// E = 9 K mu / (3 K + mu), nu = (3 K - 2 mu) / (2 (3 K + mu)).
void young_poisson(const MaterialParams& m, double* E, double* nu);

/// The scene with LiveParams applied: E > 0 gives every material (E, nu)
/// (density kept); fibre_eta >= 0 and prony_terms >= 0 give every material
/// that fibre stiffness (direction kept, x where it had none) and Prony
/// series; depth and precision replace the solver's; scalpel makes the
/// first tool a blade (kScalpelLength, kScalpelThickness) where it is not one.
scene::Scene with_params(scene::Scene s, const LiveParams& p);

/// Scene -> model -> backend (the scene's solver backend) -> scheduler, for
/// the given parameters: an engine, or for a scene with a blade (the
/// scalpel among them) a Session, which makes its cuts. Throws SceneError /
/// ModelError / std::runtime_error with the scene's file and the rule broken.
Simulated build_simulation(const scene::Scene& scene, const LiveParams& p);

struct Session {
  scene::Scene scene;
  LiveParams params;          ///< initial: the scene's solver and first material
  Bounds bounds;              ///< reference positions of the mesh
  Vec3<double> tool_start;    ///< first waypoint of the first tool, else above the organ
  Vec3<double> press_dir;     ///< unit: from the tool's start towards its first target
  double approach = 0;        ///< distance from the start to that target (m)
  double tool_radius = 1e-3;  ///< m
  /// A factory for HapticLoop over a copy of the scene.
  EngineFactory factory() const;
};

/// Reads the session's geometry and parameters from a loaded scene with the
/// command line's overrides (empty strings: keep the scene's).
Session make_session(scene::Scene scene, const std::string& backend, const std::string& precision,
                     const std::string& depth);

}  // namespace tissue::viewer
