// Many scenes stepped together (docs/batch.md): N scenes, each with its own
// materials, tools, loads and scripted paths, on one backend, ticked as one.
// For calibration, parameter sweeps, training data and robot-learning
// environments: where Simulation runs one scene for one hand, a Batch runs
// hundreds.
//
// - Scenes may share one mesh or have different meshes. Scenes that load to
//   the same model (the same mesh, materials and solver settings) share it.
// - Each scene's contact, reactions, residuals and health checks are its
//   own. A scene that goes unstable stops alone: status() says so, failure()
//   why, the others go on, and reset(scene) starts it again.
// - A scene in a batch gives the same results as the same scene in a
//   Simulation, bit for bit (the same code runs it: docs/batch.md says how).
// - Arrays: forces as size() x max_tools() x 3, fields as size() x nodes x
//   components (scenes of one node count), row-major, SI units.
//
// Like Simulation, a Batch is not thread-safe: call it from one thread at a
// time. Errors are std::invalid_argument (a bad argument, naming it) or
// std::runtime_error (a scene that does not validate, naming its index).
#pragma once

#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "tissue/simulation.hpp"

namespace tissue {

/// A new relative modulus or relaxation time for one Prony term of a
/// material (unset: the term's value). term = the material's term count + 1
/// adds a term, then both g and tau are needed.
struct PronyChange {
  int term = 1;              ///< 1-based, in the scene's order
  std::optional<double> g;   ///< relative modulus (> 0, the terms' sum < 1)
  std::optional<double> tau; ///< relaxation time (s, > 0)
};

/// New parameters for one material of a scene (unset: the scene's value).
/// The material's form becomes (E, nu) when E or nu is given.
struct MaterialChange {
  std::string material;                  ///< the scene's material name; "" = every material of the scene
  std::optional<double> youngs_modulus;  ///< E (Pa)
  std::optional<double> poisson_ratio;   ///< nu
  std::optional<double> density;         ///< rho (kg/m^3)
  std::optional<double> fibre_stiffness = {};  ///< eta (Pa) of a material that has a <fibre>
  std::vector<PronyChange> prony = {};   ///< changed or added Prony terms
};

/// One scene of a batch: a scene file or "@kidney" (or a host's mesh), and
/// material changes applied in order before it is validated.
struct BatchScene {
  std::string scene;  ///< a file or "@kidney"; unused when mesh is given
  std::vector<MaterialChange> materials;
  std::optional<MeshScene> mesh;  ///< a host's mesh (Simulation::from_mesh) instead of a file
};

/// A waypoint of a scripted tool path (as a scene's path file gives it).
struct PathPoint {
  double t = 0;        ///< s, increasing along the path
  Vector3 tip = {};    ///< m
  bool grasp = false;  ///< grasp button held from this point to the next
  Vector3 axis = {};   ///< shaft axis; {0, 0, 0} = the scene's direction
};

class Batch {
 public:
  /// Loads, validates and uploads every scene on one backend and precision
  /// (options; empty = the first scene's own). Before building more than
  /// one scene it measures the first and refuses a batch that would not
  /// fit in memory, naming the sizes.
  static Batch load(const std::vector<BatchScene>& scenes, const SimulationOptions& options = {});
  /// `copies` scenes of one scene file (or "@kidney").
  static Batch load(const std::string& scene, int copies, const SimulationOptions& options = {});

  Batch(Batch&&) noexcept;
  Batch& operator=(Batch&&) noexcept;
  ~Batch();

  // --- what is loaded ---
  std::size_t size() const;       ///< scenes
  std::string backend() const;    ///< "cpu" | "cuda"
  std::string precision() const;  ///< "float" | "double"
  std::string device_name() const;
  int max_tools() const;  ///< the most tools any scene has (forces' second dimension)
  /// Models held on the host: scenes of the same mesh and materials share one.
  std::size_t distinct_models() const;
  /// Host and device bytes one scene takes, measured on the first scene.
  std::int64_t scene_host_bytes() const;
  std::int64_t scene_device_bytes() const;
  /// How the backend runs them: groups of scenes of one model stepped as
  /// one, each pass one launch over the group (cuda; 0 on the cpu), and the
  /// scene ticks run that way so far (docs/batch.md, "One launch per pass").
  std::size_t groups() const;
  std::int64_t ticks_together() const;

  std::string name(int scene) const;
  std::size_t n_nodes(int scene) const;
  std::size_t n_elements(int scene) const;
  int n_tools(int scene) const;
  int steps_per_tick(int scene) const;
  double dt(int scene) const;
  double tick_seconds(int scene) const;
  /// When the scene's scripted tool paths end (s): the latest last waypoint
  /// of its tools (0 for tools without a path).
  double path_end(int scene) const;
  const std::vector<std::string>& warnings(int scene) const;
  /// The scene's bodies (Simulation::bodies).
  std::vector<BodyRange> bodies(int scene) const;
  /// The scene's surface nodes inside another body after its last tick
  /// (Simulation::body_contacts).
  std::vector<BodyContact> body_contacts(int scene) const;

  /// Replaces a scene's material parameters (MaterialChange) and starts
  /// that scene again at rest; the others are untouched. Throws
  /// std::invalid_argument naming the scene, the material and the rule
  /// (an unknown material, E <= 0, nu outside (-1, 0.5), ...).
  void set_material(int scene, const MaterialChange& change);

  // --- device arrays (cuda) ---
  /// A field where it lies in GPU memory, as __cuda_array_interface__ and
  /// DLPack describe it: no copy.
  struct DeviceView {
    std::uintptr_t data = 0;
    std::vector<std::int64_t> shape;    ///< (scenes, nodes, 3) or (nodes, 3)
    std::vector<std::int64_t> strides;  ///< bytes per step of each dimension
    int scalar_bytes = 0;               ///< 4 (float) or 8 (double)
    int device = 0;                     ///< the CUDA device
  };
  /// Field::Displacement or Field::InternalForce of every scene, (size(),
  /// nodes, 3), read where the cuda backend keeps it; of one scene, (nodes,
  /// 3). Valid until the next step(), reset, set_material or set_loads of
  /// the batch (the displacement's buffers rotate every step); read it, or
  /// copy it, before then. Every scene's at once needs them one stride
  /// apart: scenes of one model in one group (docs/batch.md); otherwise
  /// throws naming the first scene that is not, as for the cpu backend,
  /// another field or scenes of different sizes.
  DeviceView device_field(Field f);
  DeviceView device_field(int scene, Field f);

  // --- tools ---
  /// The pose tool `tool` of `scene` reaches at the end of the next tick
  /// (Simulation::set_tool_pose).
  void set_tool_pose(int scene, int tool, const Vector3& tip, const Vector3& axis = {0, 0, 0});
  /// Every scene's tool poses at once: tips (and axes, or empty for the
  /// scenes' directions) hold size() x max_tools() x 3 values, row-major.
  /// Rows past a scene's own tools are ignored.
  void set_tool_poses(std::span<const double> tips, std::span<const double> axes = {});
  /// The same from a CUDA device array (size() x max_tools() x 3 tips,
  /// contiguous, float64, or float32 with `single`): one copy to the host,
  /// then set_tool_poses(tips). Throws naming the pointer where it is not
  /// device memory.
  void set_tool_poses_from_device(std::uintptr_t tips, std::size_t count, bool single = false);
  void set_grasp(int scene, int tool, bool down);
  /// One scene's tool's Coulomb coefficient (Simulation::set_tool_friction).
  void set_tool_friction(int scene, int tool, double mu);
  double tool_friction(int scene, int tool) const;
  /// A new scripted path for a tool, followed from the next tick on.
  void set_tool_path(int scene, int tool, const std::vector<PathPoint>& path);
  /// Hands the tool back to its scripted path.
  void follow_scene_path(int scene, int tool);

  // --- loads ---
  /// Simulation::set_loads for one scene.
  void set_loads(int scene, std::span<const std::int32_t> nodes, std::span<const double> forces);

  // --- time ---
  /// Runs `ticks` haptic ticks (>= 1) of every running scene; a scene that
  /// fails stops alone. Returns how many scenes still run.
  std::size_t step(long ticks = 1);
  /// True when the scene has stopped (unstable); failure() says why.
  bool failed(int scene) const;
  std::string failure(int scene) const;
  /// The failed scenes, ascending.
  std::vector<int> failed_scenes() const;
  /// The scene's last tick (its last good one, for a failed scene).
  const TickResult& last(int scene) const;
  long ticks(int scene) const;
  /// One scene, or every scene, back to rest (Simulation::reset).
  void reset(int scene);
  void reset();
  std::vector<std::string> take_notes(int scene);

  // --- arrays ---
  /// The force on every tool after the last tick (N): size() x max_tools()
  /// x 3, zero past a scene's own tools.
  void read_forces(std::span<double> out) const;
  std::vector<double> forces() const;
  /// Every tool's tip after the last tick (m), laid out as read_forces.
  void read_tips(std::span<double> out) const;
  /// Copies one scene's field (Simulation::read_field).
  void read_field(int scene, Field f, std::span<double> out);
  /// Every scene's field, size() x (nodes or elements) x components; the
  /// scenes must have one node count (one element count for the Jacobian):
  /// std::invalid_argument names two that differ.
  void read_fields(Field f, std::span<double> out);
  std::vector<double> fields(Field f);

 private:
  struct Impl;
  explicit Batch(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace tissue
