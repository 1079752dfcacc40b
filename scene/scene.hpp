// The scene model: the tissue (one mesh, or several bodies each with its own
// mesh), element sets with materials, constraints, loads, tools and solver
// settings, in SI units. io/scene_xml reads and
// writes it; scene/validate checks it and turns it into a core ModelInput.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "core/device.hpp"
#include "core/hd.hpp"
#include "core/model.hpp"
#include "core/region.hpp"

namespace tissue::scene {

/// A material (docs/materials.md): Neo-Hookean given as (E, nu), (mu, K) or
/// Lame (lambda, mu), optionally with a tension-only fibre term
/// (transversely isotropic) and a Prony series on the isochoric stress
/// (viscoelastic; the elastic constants are then the instantaneous ones).
/// The fibre direction is one for the whole material (fibre_dir), or a
/// field evaluated at each element's centroid, or read per element from a
/// file (FibreField; scene/fibre_field.hpp).
struct Material {
  enum class Form { YoungPoisson, ShearBulk, Lame };
  /// Where the fibre direction of each element comes from.
  enum class FibreField {
    Uniform,          ///< fibre_dir everywhere
    Circumferential,  ///< a = axis x (c - origin) at the centroid c: fibres wound around the axis
    Radial,           ///< a = (c - origin) less its component along the axis: fibres pointing away from it
    File,             ///< fibre_rows per element (a CSV file); elements not listed take fibre_dir
  };
  /// One row of a fibre direction file: an element and its direction.
  struct FibreRow {
    index_t element = 0;                 ///< 0-based element id of the mesh
    Vec3<double> dir = {0, 0, 0};        ///< any length but 0
    int line = 0;                        ///< line in the file, for messages (0 = unknown)
  };
  /// One Prony term: relative modulus g and relaxation time tau.
  struct Prony {
    double g = 0, tau = 0;  ///< dimensionless (> 0, sum < 1), s (> 0)
    int line = 0;
  };
  std::string name;
  Form form = Form::YoungPoisson;
  double a = 0, b = 0;   ///< (E, nu) | (mu, K) | (lambda, mu), in Pa (nu dimensionless)
  double rho = 1000;     ///< kg/m^3
  int line = 0;          ///< source line, for messages (0 = unknown)
  double fibre_eta = 0;  ///< fibre stiffness eta (Pa); 0 = isotropic
  Vec3<double> fibre_dir = {1, 0, 0};  ///< fibre direction (any length but 0)
  int fibre_line = 0;    ///< line of the <fibre> element (0 = none)
  std::vector<Prony> prony = {};  ///< empty = elastic
  FibreField fibre_field = FibreField::Uniform;  ///< how fibre directions vary over the material's elements
  Vec3<double> fibre_axis = {0, 0, 1};    ///< Circumferential / Radial: the axis direction (any length but 0)
  Vec3<double> fibre_origin = {0, 0, 0};  ///< Circumferential / Radial: a point of the axis (m)
  std::string fibre_file = {};            ///< File: the CSV as named in the scene (relative to the scene file)
  std::string fibre_file_path = {};       ///< File: the CSV as opened, for messages ("" = fibre_file)
  std::vector<FibreRow> fibre_rows = {};  ///< File: the directions read from it (read_scene loads them)

  /// mu and K of this material, with rho (no validation):
  /// YoungPoisson: mu = E / (2 (1 + nu)), K = E / (3 (1 - 2 nu));
  /// ShearBulk: as given; Lame: K = lambda + 2 mu / 3; and the fibre and
  /// Prony terms (at most kMaxProny are copied).
  MaterialParams params() const;
};

/// Elements carrying one material. `elements` empty with all = true: every
/// element (of its body, when body >= 0).
struct ElementSet {
  std::string name;
  std::string material;             ///< Material::name
  bool all = false;
  std::vector<index_t> elements;    ///< element ids of the whole scene (a <body>'s local ids plus its first_element)
  int line = 0;                     ///< source line, for messages (0 = unknown)
  int body = -1;                    ///< index into Scene::bodies it belongs to; -1 in the single-mesh form
};

/// Fixed nodes: by id list, by an axis-aligned box, or by the side of a plane.
struct Constraint {
  enum class Kind { Nodes, Box, Plane };
  Kind kind = Kind::Nodes;
  std::vector<index_t> nodes;       ///< Kind::Nodes: node ids of the whole scene (a <body>'s local ids plus
                                    ///< its first_node)
  double lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0};   ///< Kind::Box (m)
  double point[3] = {0, 0, 0}, normal[3] = {0, 0, 1};  ///< Kind::Plane: fixes nodes with (x - point).normal >= 0
  int line = 0;                     ///< source line, for messages (0 = unknown)
  int body = -1;                    ///< index into Scene::bodies whose nodes alone it selects; -1 in the single-mesh
                                    ///< form
};

/// A constant external force (a dead load: Backend::set_loads) on the nodes
/// a selection picks, as <fixed> picks them.
struct Load {
  Constraint where;                 ///< the selection (its line is the <load>'s)
  double force[3] = {0, 0, 0};      ///< N: the total over the selected surface faces, spread by area (each =
                                    ///< false), or the force on every selected node (each = true)
  bool each = false;
};

/// A blade's default cutting resistance (N/m = J/m^2): the fracture
/// toughness of bovine liver, 164 +- 6 J/m^2 (Gokgol, Basdogan and
/// Canadinc, "Estimation of fracture toughness of liver tissue: experiments
/// and validation", Med. Eng. Phys. 34(7), 2012).
inline constexpr double kDefaultCutResistance = 164;
/// A blade's default cut delay (s): 0, the cut made within the tick that
/// gives. A delay > 0 prepares it off the tick's thread while the simulation
/// runs on, and it takes effect that long after the tissue gives (Session,
/// docs/cutting.md "The blade").
inline constexpr double kDefaultCutDelay = 0;
/// The longest cut delay a scene may ask (s): a blade that gives a second
/// late is a typing mistake.
inline constexpr double kMaxCutDelay = 1;
/// A blade's default thickness (m): its contact capsule's diameter.
inline constexpr double kDefaultBladeThickness = 1e-3;

/// A rigid tool -- a capsule (core/tool.hpp) -- and the device that drives it.
struct Tool {
  /// What the tool's button does: a probe grasps the tissue it touches; a
  /// blade, a straight edge (its capsule: radius = half its thickness,
  /// shaft = its length, from the tip), cuts (docs/cutting.md).
  enum class Kind { Probe, Blade };
  Kind kind = Kind::Probe;
  std::string name = "probe";
  double radius = 2e-3;             ///< tip and shaft radius (m): the loaded patch, physical
  double shaft = 0;                 ///< shaft length (m) from the tip along the direction; 0 = a sphere
  double friction = 0;              ///< Coulomb's mu at its contacts (>= 0); 0 = frictionless
  /// A blade's cutting resistance (N/m = J/m^2): with its button down the
  /// tissue gives where the force against the blade's motion per metre of
  /// edge in contact reaches it (Mahvash and Hayward's energy criterion).
  double cut_resistance = kDefaultCutResistance;
  /// A blade's cut delay (s): how long after the tissue gives its cut takes
  /// effect; the cut is prepared meanwhile while the ticks run on (0: made
  /// within the tick, a pause of the cut's whole time).
  double cut_delay = kDefaultCutDelay;
  Vec3<double> direction = {0, 0, 1};  ///< shaft axis, tip -> handle, used when the device has no orientation
  std::string device = "scripted";  ///< "scripted" | "mouse" | "phantom"
  std::string path_file;            ///< CSV t,x,y,z[,grasp][,ax,ay,az] (io/path_csv; a blade's grasp column is its
                                    ///< cut button) relative to the scene file;
                                    ///< empty = inline
  std::vector<Waypoint> path;       ///< scripted path (inline, or loaded from path_file by read_scene)
  int line = 0;                     ///< source line, for messages (0 = unknown)
};

/// Solver and loop settings; io/scene_xml's <solver> element.
struct Solver {
  std::string backend = "cpu";      ///< "cpu" | "cuda"
  Precision precision = Precision::Float;  ///< scalar of the backend's store and arithmetic
  std::optional<double> dt;         ///< s (> 0); unset ("auto") = dt-safety x dt_crit
  double dt_safety = 0.8;           ///< fraction of dt_crit used when dt is auto, in (0, 1) (docs/reliability.md: why 0.8)
  double mass_scaling = 0.025;      ///< selective mass scaling budget, a fraction of the total mass in [0, 1)
                                    ///< (core choose_mass_scaling); 0 = off
  std::optional<double> damping;    ///< alpha (1/s, >= 0); unset ("auto") = 2 x lowest-mode estimate
  int depth = kDepthAuto;           ///< rings; kDepthAll = whole mesh, kDepthAuto = adaptive
  double tick = 1e-3;               ///< haptic period (s)
  double residual_tol = 1e-3;       ///< equilibrium: relative free-node residual (SchedulerSettings)
  double kinetic_tol = 1e-6;        ///< equilibrium: relative kinetic energy (SchedulerSettings)
  bool ianp = true;                 ///< improved average nodal pressure; false = plain tets
  bool lip_contact = false;         ///< a cut's lips keep out of each other (SchedulerSettings::lip_contact)
  bool step_guard = true;           ///< mass scaling carried on under the tools (SchedulerSettings::step_guard)
  int line = 0;                     ///< source line of <solver>, for messages (0 = unknown / defaults)
};

/// One body of a scene of several (docs/scene-format.md, "Bodies"): its
/// nodes and elements are contiguous ranges of the scene's, in body order,
/// and its elements use only its own nodes. The solver sees one mesh of
/// several pieces; the bodies name the pieces for input and output.
struct Body {
  std::string name;
  std::string mesh_file;            ///< its <mesh file=...> as named in the scene ("" = inline)
  int line = 0;                     ///< source line of <body>, for messages (0 = unknown)
  int mesh_line = 0;                ///< source line of its <mesh>
  index_t first_node = 0, n_nodes = 0;
  index_t first_element = 0, n_elements = 0;
};

/// Two bodies that may touch each other (<contact bodies="a b">; core/body_contact.hpp).
struct BodyContact {
  std::string a, b;                 ///< body names
  double friction = 0;              ///< Coulomb's mu between them (>= 0); 0 = frictionless
  int line = 0;                     ///< source line, for messages (0 = unknown)
};

/// A whole scene as read from a file, before validation (scene/validate.hpp).
struct Scene {
  std::string source = "<scene>";   ///< file name, for messages
  std::string mesh_file;            ///< external mesh (resolved relative to the scene file), if any
  int mesh_line = 0;                ///< source line of <mesh>, for messages
  std::vector<double> nodes;        ///< (n_nodes x 3) m; with bodies, theirs one after the other
  std::vector<index_t> tets;        ///< (n_elems x 4); with bodies, theirs one after the other (scene node ids)
  std::vector<Body> bodies;         ///< empty = the single-mesh form (one <mesh>, no <body>)
  std::vector<Material> materials;
  std::vector<ElementSet> sets;
  std::vector<Constraint> constraints;
  std::vector<Load> loads;
  std::vector<Tool> tools;
  std::vector<BodyContact> contacts;  ///< which bodies touch (a scene of bodies only)
  Solver solver;                    ///< defaults when the file has no <solver>
};

}  // namespace tissue::scene
