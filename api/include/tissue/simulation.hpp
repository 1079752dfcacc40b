// Tissue's embedding interface (docs/embedding.md): one class a host
// application drives without knowing the engine's wiring. It loads a scene
// (an XML file or "@kidney") or a host's own tetrahedral mesh, runs it on a
// backend ("cpu" or "cuda") at a precision ("float" or "double"), takes the
// tools' poses and grasp buttons from the host, steps haptic ticks and gives
// back forces, positions and fields.
//
// This header needs the standard library only: the engine's own headers,
// Eigen, TBB, Embree and CUDA stay inside the library. Every error is a
// std::exception whose what() names the file, element, node or value and the
// rule broken (std::invalid_argument for a bad argument, std::runtime_error
// for everything else: a scene that does not validate, a backend that is not
// built or has no GPU, a simulation that went unstable).
//
// A Simulation is not thread-safe: call it from one thread at a time (a host
// with a 1 kHz haptic thread calls step() there and reads fields between
// ticks). The C interface over it is tissue/tissue_c.h.
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "tissue/fields.h"

namespace tissue {

/// The library's version, "major.minor.patch".
const char* version();

/// Backend names this library was built with ("cpu", and "cuda" when the
/// CUDA backend was compiled in) that can run on this machine now.
std::vector<std::string> available_backends();

using Vector3 = std::array<double, 3>;

/// How to run: empty strings keep the scene's own setting.
struct SimulationOptions {
  std::string backend;    ///< "cpu" | "cuda"
  std::string precision;  ///< "float" | "double"
  std::string depth;      ///< region depth: "all" | "auto" | a whole number of rings
};

/// A host's own tetrahedral mesh with one Neo-Hookean material, the nodes
/// it holds fixed and its tools (spheres or capsules). Solver settings are
/// the scene format's defaults (docs/scene-format.md), region depth "auto".
struct MeshScene {
  std::string name = "<mesh>";        ///< for messages
  std::vector<double> nodes;          ///< x y z per node (m)
  std::vector<std::int32_t> tets;     ///< four 0-based node ids per tetrahedron
  double youngs_modulus = 3000;       ///< E (Pa)
  double poisson_ratio = 0.45;        ///< nu, in (-1, 0.5)
  double density = 1000;              ///< rho (kg/m^3)
  std::vector<std::int32_t> fixed_nodes;  ///< held at rest (a body with none is warned about)
  std::vector<double> tool_radii = {2e-3};  ///< one tool per radius (m), at most 4
  double tool_shaft = 0;              ///< shaft length of every tool (m); 0 = spheres
};

/// A surface meshed into tetrahedra (mesh_surface).
struct VolumeMeshResult {
  std::vector<double> nodes;          ///< x y z per node (m)
  std::vector<std::int32_t> tets;     ///< four node ids per tetrahedron, positively oriented
  std::string quality;                ///< the quality report, one finding per line
};

/// Repairs, remeshes and tetrahedralises a closed surface file (OBJ, STL,
/// PLY, OFF, ...) as `tissue mesh` does (docs/meshing.md). unit: "m", "cm"
/// or "mm"; target_tets: about this many tetrahedra (0 = the mesher's own
/// sizing).
VolumeMeshResult mesh_surface(const std::string& path, const std::string& unit = "m", int target_tets = 0);

/// A tetrahedral mesh cut where a blade sweeps (cut_mesh; docs/cutting.md).
struct CutMeshResult {
  std::vector<double> nodes;            ///< x y z per node (m)
  std::vector<std::int32_t> tets;       ///< four node ids per tetrahedron, positively oriented
  std::vector<std::int32_t> node_from;  ///< per node the two input nodes it lies between (the same one twice: a kept
                                        ///< or copied node)
  std::vector<double> weight;           ///< per node its place between them: (1 - w) X_a + w X_b
  std::vector<std::int32_t> element_from;  ///< per element the input element it is (part of)
  int pieces_split = 0, nodes_snapped = 0, nodes_copied = 0, faces_opened = 0, left_whole = 0;
};

/// Cuts a mesh (x y z per node, 4 ids per tetrahedron) where a blade sweeps:
/// the parallelogram origin + s edge + t sweep, s, t in [0, 1] (m). method:
/// "snap-split" (the default), "snap" or "split" (docs/cutting.md: snap
/// nodes near the cut onto it, split what it still crosses, open the faces
/// on it by copying their nodes; no element is deleted). Throws
/// std::invalid_argument naming the rule for a zero-length blade, a blade
/// moving along its edge, a cut that crosses no element, an unknown method
/// or a mesh whose ids are out of range.
CutMeshResult cut_mesh(std::span<const double> nodes, std::span<const std::int32_t> tets, const Vector3& origin,
                       const Vector3& edge, const Vector3& sweep, const std::string& method = "snap-split");

/// What Simulation::cut did.
struct CutStats {
  std::size_t nodes_before = 0, elements_before = 0;  ///< the mesh before the cut
  std::size_t nodes = 0, elements = 0;                ///< and after it
  int pieces_split = 0, nodes_snapped = 0, nodes_copied = 0, faces_opened = 0, left_whole = 0;  ///< as CutMeshResult
  double dt_before = 0, dt_after = 0;                 ///< the TLED step before and after (s)
};

/// One tool at the end of a tick.
struct ToolResult {
  Vector3 tip = {};                   ///< m
  Vector3 axis = {};                  ///< unit shaft axis (tip -> handle)
  Vector3 force = {};                 ///< the force on the tool: what the hand feels (N)
  int contact_nodes = 0;              ///< surface nodes in contact (pushed or grasped)
  int grasped_nodes = 0;              ///< of which grasped
  bool grasp = false;                 ///< the button held: a probe's grasp, a blade's cut
  bool cut = false;                   ///< a blade: the tissue gave, and was cut, after this tick
};

/// What one haptic tick did.
struct TickResult {
  long tick = 0;                      ///< ticks run so far (1 after the first)
  double time = 0;                    ///< simulated time at the end of the tick (s)
  int steps = 0;                      ///< TLED steps in the tick
  std::vector<ToolResult> tools;      ///< one per tool, scene order
  double max_displacement = 0;        ///< m
  double residual = 0;                ///< relative free-node residual
  bool equilibrium = false;           ///< residual and kinetic energy under the scene's tolerances
  int region_nodes = 0, region_elements = 0;  ///< the deformation region in use
};

/// One body of a scene (docs/scene-format.md, "Bodies"): its nodes and
/// elements are consecutive ranges of the simulation's, so a body's part of
/// a per-node field is nodes [first_node, first_node + n_nodes). A scene of
/// one <mesh> is one body named "body" holding everything.
struct BodyRange {
  std::string name;
  std::size_t first_node = 0, n_nodes = 0;
  std::size_t first_element = 0, n_elements = 0;
};

/// One surface node inside another body after the last tick
/// (Simulation::body_contacts; docs/contact.md, "Bodies touching each
/// other"): a scene's <contact bodies="a b"> keeps each body's surface
/// nodes out of the other's triangles every TLED step, and these are the
/// nodes its last step found inside, before that step's correction.
struct BodyContact {
  std::int32_t node = -1;                     ///< the surface node
  std::array<std::int32_t, 3> triangle = {};  ///< the other body's surface triangle it was inside: its corners' node ids
  int body = -1;                              ///< the node's body (index into bodies())
  int other_body = -1;                        ///< the triangle's body (index into bodies())
  double depth = 0;                           ///< how far inside it was, before the correction (m, >= 0)
};

/// Per-node and per-element fields (all in SI units), tissue/fields.h's
/// list: Displacement (u, 3 per node, m), Position (X + u, 3 per node, m),
/// Pressure (IANP nodal pressure, 1 per node, Pa), InternalForce (internal
/// nodal force less the applied load of set_loads, 3 per node, N), Jacobian
/// (J = det F, 1 per element, its last computed value).
enum class Field {
#define TISSUE_FIELD_CPP_ENUM(c_name, cpp_name, python, per, components, unit, what) cpp_name,
  TISSUE_FIELD_LIST(TISSUE_FIELD_CPP_ENUM)
#undef TISSUE_FIELD_CPP_ENUM
};

/// Values per node (or element) of a field: 3 or 1.
int field_components(Field f);
/// Whether a field has one value (or vector) per element, not per node.
bool field_per_element(Field f);

class Simulation {
 public:
  /// Loads a scene file (docs/scene-format.md) or "@kidney" (the built-in
  /// kidney), validates it and uploads it to the backend.
  static Simulation load(const std::string& scene, const SimulationOptions& options = {});
  /// Builds a simulation of a host's mesh (validated as a scene is: zero
  /// or inverted volumes, unused nodes and out-of-range ids are refused
  /// naming the element or node).
  static Simulation from_mesh(const MeshScene& mesh, const SimulationOptions& options = {});

  Simulation(Simulation&&) noexcept;
  Simulation& operator=(Simulation&&) noexcept;
  ~Simulation();

  // --- what is loaded ---
  std::string name() const;            ///< the scene's file (or MeshScene::name)
  std::string backend() const;         ///< "cpu" | "cuda"
  std::string precision() const;       ///< "float" | "double"
  std::string device_name() const;     ///< processor or GPU
  std::size_t n_nodes() const;
  std::size_t n_elements() const;
  std::size_t n_surface_triangles() const;
  int n_tools() const;
  double tick_seconds() const;         ///< haptic period (s)
  int steps_per_tick() const;          ///< TLED steps per tick
  double dt() const;                   ///< TLED step (s)
  /// Warnings found when the scene was loaded (a body with no support, ...).
  const std::vector<std::string>& warnings() const;
  /// The scene's bodies, in the scene's order (at least one).
  std::vector<BodyRange> bodies() const;
  /// The surface nodes inside another body after the last tick (its last
  /// TLED step, before that step's correction), ascending node id; empty
  /// before the first step and for a scene without <contact bodies>. Read
  /// from the backend on each call (a download on the cuda backend).
  std::vector<BodyContact> body_contacts() const;

  /// The reference mesh: views valid until the mesh changes (cut(), or
  /// reset() after a cut; mesh_version() says when), else for the
  /// Simulation's life.
  std::span<const double> rest_positions() const;          ///< 3 per node (m)
  std::span<const std::int32_t> tetrahedra() const;        ///< 4 per element
  std::span<const std::int32_t> surface_triangles() const; ///< 3 per triangle, outward
  /// Counts the mesh's changes: 1 after loading, one more with each cut()
  /// and each reset() after a cut.
  std::uint64_t mesh_version() const;

  // --- tools (index 0 .. n_tools()-1) ---
  /// The pose tool `tool` reaches at the end of the next tick: tip (m) and
  /// shaft axis (tip -> handle; {0, 0, 0} = the scene's direction). From
  /// the first call on, the host drives the tool; before it, the tool
  /// follows the scene's scripted path (or rests at its first point).
  /// Throws std::invalid_argument naming the tool and the value for a tip
  /// or axis that is not finite, or a tip farther from the mesh's bounding
  /// box than 1000 times its diagonal (the scene rule for waypoints).
  void set_tool_pose(int tool, const Vector3& tip, const Vector3& axis = {0, 0, 0});
  /// The tool's button. A probe's grasps: down grasps the nodes in
  /// contact, up releases them. A blade's (`<tool kind="blade">`) cuts: while
  /// it is down the tissue gives where the blade presses it with its cutting
  /// resistance per metre of edge in contact, and the mesh is cut between
  /// ticks (docs/cutting.md, "The blade"; n_nodes() and the reference mesh
  /// change, as with cut()).
  void set_grasp(int tool, bool down);
  /// Hands the tool back to the scene's scripted path.
  void follow_scene_path(int tool);
  /// The tool's shape: radius and shaft length (m).
  double tool_radius(int tool) const;
  double tool_shaft(int tool) const;
  /// The tool's Coulomb friction coefficient mu at its contacts (the
  /// scene's `friction`, 0 = frictionless): a contact node sticks to the
  /// tool while its tangential force is at most mu times its normal force,
  /// and slides with mu times it beyond (docs/contact.md, "Friction").
  /// set_tool_friction changes it from the next tick on, keeping the
  /// contacts, also across reset(); throws std::invalid_argument naming
  /// the tool for a value that is not finite and >= 0.
  double tool_friction(int tool) const;
  void set_tool_friction(int tool, double mu);

  // --- loads ---
  /// Constant external forces (dead loads) from the next tick on: x y z
  /// (N) per node of `nodes` (forces.size() = 3 nodes.size()). Replaces the
  /// scene's <load>s and any earlier call, also across reset(); a node given
  /// twice gets the sum; empty lists remove every load. Throws
  /// std::invalid_argument naming the node and the rule (out of range, not
  /// finite, wrong count).
  void set_loads(std::span<const std::int32_t> nodes, std::span<const double> forces);

  // --- cutting (docs/cutting.md) ---
  /// Cuts the tissue where it is now, between ticks, along the
  /// parallelogram origin + s edge + t sweep, s, t in [0, 1] (m, the
  /// deformed configuration: where the host sees its blade), as cut_mesh
  /// does, and runs on with the cut mesh: its nodes and elements (and so
  /// n_nodes(), rest_positions(), tetrahedra(), the fields' sizes) change;
  /// the old nodes keep their ids, new ones follow. The displacement and
  /// velocity carry over (the field's values at the new nodes), and so do
  /// the time, the tools and the loads (set_loads' nodes keep their ids; a
  /// copy of a loaded node takes none of its load). The Prony history and
  /// grasps are dropped (a grasp takes hold again when its button next goes
  /// down). reset() goes back to the mesh before the first cut. Throws
  /// std::invalid_argument naming the rule, leaving the simulation as it
  /// was, for a zero-length blade, a blade moving along its edge, a cut that
  /// crosses no element, an unknown method, a scene of several bodies, or a
  /// cut whose mesh the engine refuses (an element it would invert).
  CutStats cut(const Vector3& origin, const Vector3& edge, const Vector3& sweep,
               const std::string& method = "snap-split");

  // --- time ---
  /// Runs `ticks` haptic ticks (>= 1) and returns the last one's result.
  TickResult step(long ticks = 1);
  /// The last tick's result (a zero tick before the first step).
  const TickResult& last() const;
  Vector3 force(int tool) const;       ///< last().tools[tool].force (N)
  long ticks() const;
  double time() const;                 ///< simulated time (s)
  /// Back to rest (u = 0, tick 0, every grasp released); keeps tool modes
  /// and loads.
  void reset();
  /// The energy the viscoelastic (Prony) terms dissipated since the start
  /// (J) and what their Maxwell branches store after the last tick (J);
  /// 0 for elastic materials (docs/materials.md, energy).
  double dissipated_energy() const;
  double viscous_stored_energy() const;
  /// Notes since the last call (a tool pressing a fixed support, ...).
  std::vector<std::string> take_notes();

  // --- fields (downloaded once per tick, on the first read) ---
  /// Copies a field into out (size field_components(f) x n_nodes(), or x
  /// n_elements() for Jacobian); throws std::invalid_argument naming both
  /// sizes when out has another size.
  void read_field(Field f, std::span<double> out);
  std::vector<double> field(Field f);
  /// Deformed positions as float xyz (3 x n_nodes) written straight from
  /// the backend's store into dst: host memory when
  /// !positions_on_device(), device memory (a CUDA pointer, such as a
  /// mapped OpenGL vertex buffer) otherwise.
  void write_positions(float* dst);
  bool positions_on_device() const;

 private:
  struct Impl;
  explicit Simulation(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace tissue
