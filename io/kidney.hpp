// The built-in default scene: a kidney-shaped organ generated here (no data
// file), meshed by TetGen, with brain-tissue Neo-Hookean parameters, a fixed
// hilum and a scripted press-and-release probe. docs/kidney.md describes the
// construction and the sources of the numbers.
#pragma once

#include <optional>
#include <string>

#include "core/vec.hpp"
#include "io/surface_import.hpp"
#include "scene/scene.hpp"

namespace tissue::io {

/// The bean shape: an ellipsoid with semi-axes (a, b, c) along x (long,
/// superior-inferior), y (medial -y to lateral +y) and z (thickness), then
/// scaled radially by s(p) = 1 - bean * m(p) - hilum * h(p), where p is the
/// unit-sphere point, m(p) = ((1 - p_y) / 2)^4 exp(-(p_x / bean_width)^2)
/// pulls the middle of the medial side in (the bean's concavity) and
/// h(p) = exp(-(1 + p_y) / hilum_width) is the hilum dent centred on the
/// medial direction -y. s >= 1 - bean - hilum > 0 everywhere.
struct KidneyShape {
  double a = 0.055, b = 0.03, c = 0.022;  ///< ellipsoid semi-axes (m): about 11 x 6 x 4.4 cm
  double bean = 0.2;                      ///< depth of the medial concavity (fraction of the radius)
  double bean_width = 0.5;                ///< its extent along the long axis (unit-sphere x)
  double hilum = 0.2;                     ///< depth of the hilum dent (fraction of the radius)
  double hilum_width = 0.08;              ///< its angular size: 1 - cos(angle) scale
};

/// Radial scale s(p) of the shape at the unit-sphere point p (in (0, 1]).
double kidney_radial_scale(const KidneyShape& shape, Vec3<double> p);

/// Closed, outward-oriented kidney surface (m), centred at the origin: a
/// geodesic sphere of the given frequency (1..64: each icosahedron edge cut
/// into `frequency` segments, 10 f^2 + 2 vertices, 20 f^2 triangles; an
/// icosphere subdivided n times is frequency 2^n), each vertex p mapped to
/// s(p) (a p_x, b p_y, c p_z).
/// The map is radial from the origin (x/|x| is a bijection of the sphere),
/// so the surface is star-shaped and cannot intersect itself; every triangle
/// is also checked to face away from the origin. Throws std::invalid_argument
/// for a frequency outside 1..64 or a shape with s <= 0.
SurfaceMesh kidney_surface(int frequency, const KidneyShape& shape = {});

/// Where a kidney surface is refined: its geodesic sphere's vertices are
/// first moved by the conformal (Moebius) map of the unit sphere that
/// scales the stereographic coordinates about the pole `toward` by `scale`
/// (in (0, 1]; 1: uniform). Edges near the pole shrink by `scale`, those
/// at the antipode grow by 1 / scale, and the map is conformal: triangle
/// angles are kept, so the focus makes no slivers. Used for the contact's
/// mesh-convergence study (tissue converge): a 2 mm tool needs faces
/// finer than itself under it, not everywhere.
struct SurfaceFocus {
  Vec3<double> toward{0, 1, 0};  ///< the pole: a direction from the kidney's centre (the shape's own coordinates)
  double scale = 1.0;
};

/// The kidney surface with its vertices focused (SurfaceFocus) before the
/// shape's map; throws std::invalid_argument for a scale outside (0, 1]
/// or a zero direction, as kidney_surface does for the rest.
SurfaceMesh kidney_surface(int frequency, const KidneyShape& shape, const SurfaceFocus& focus);

/// The unit-sphere direction whose kidney point lies along x from the
/// centre (the inverse of the shape's map up to its radial scale).
Vec3<double> kidney_sphere_direction(const KidneyShape& shape, Vec3<double> x);

/// The point where the ray from the origin along `dir` leaves the closed
/// star-shaped surface (m). Throws std::runtime_error if the ray misses.
Vec3<double> surface_point_along(const SurfaceMesh& surface, Vec3<double> dir);

/// The surface triangle that the ray from the origin along `dir` crosses
/// first (the lowest id when the ray passes through an edge or a vertex).
index_t surface_triangle_along(const SurfaceMesh& surface, Vec3<double> dir);

/// Construction constants of the default kidney scene.
struct KidneyScene {
  static constexpr int frequency = 6;              ///< geodesic frequency: 362 vertices, 720 triangles
  static constexpr double quality = 2.0;           ///< TetGen radius-edge bound (1.414 would force ~9,300 tets)
  static constexpr int target_tets = 8400;         ///< the reference paper's kidney had 8,427
  static constexpr double fix_radius = 0.01;       ///< nodes within this distance of the hilum centre are fixed (m)
  static constexpr double tool_radius = 0.002;     ///< probe radius (m): a 4 mm rod with a hemispherical tip
  static constexpr double tool_shaft = 0.03;       ///< probe shaft length (m)
  static constexpr double approach = 0.01;         ///< the tool's surface starts this far outside the tissue (m)
  static constexpr double press_depth = 0.005;     ///< indentation: the tool's deepest point below the surface (m)
  static constexpr double E = 3000, nu = 0.45, rho = 1000;  ///< brain tissue (Pa, -, kg/m^3)
};

/// Hilum centre of the default kidney (m): the surface point along -y.
Vec3<double> kidney_hilum_centre();

/// The built-in default scene: the kidney surface (KidneyScene::frequency)
/// tetrahedralised by TetGen (KidneyScene::quality) to about
/// KidneyScene::target_tets tets; one Neo-Hookean material (E = 3000 Pa,
/// nu = 0.45, rho = 1000 kg/m^3) on every element; a Nodes constraint fixing
/// the nodes within fix_radius of the hilum centre; one scripted probe (a
/// capsule of radius 2 mm with a 3 cm shaft) on core press_path: aimed at
/// the generated surface's point on the convex lateral side (+y), along its
/// inward normal, from 1 cm outside: touch, press 5 mm, hold, retract (1 s);
/// solver: cpu, float, dt = 0.9 dt_crit, 2.5 % mass scaling, automatic
/// damping, depth auto, 1 ms tick. Deterministic; the mesh is inline
/// (Scene::nodes, Scene::tets).
scene::Scene default_kidney_scene();

/// Prony terms of the viscoelastic kidney (docs/materials.md): illustrative
/// values of the order published for kidney and liver in indentation
/// relaxation (a fast and a slow term), not a fit to one organ.
inline constexpr double kKidneyPronyG[2] = {0.3, 0.2};
inline constexpr double kKidneyPronyTau[2] = {0.2, 2.0};  ///< s
/// How long the viscoelastic kidney's probe holds its press (s).
inline constexpr double kKidneyViscoHold = 3.0;

/// "@kidney-visco": the built-in kidney with its material viscoelastic
/// (mu, K as "@kidney" are the instantaneous moduli; Prony terms
/// kKidneyPronyG / kKidneyPronyTau on the isochoric stress) and the press
/// held kKidneyViscoHold seconds, to feel and measure the relaxation.
scene::Scene viscoelastic_kidney_scene();

/// Construction constants of "@kidney-fat": a layer of fat over the
/// kidney's lateral side, pressed through by the probe (docs/kidney.md,
/// "The kidney in its fat").
struct KidneyFatScene {
  static constexpr double cap_angle = 40;      ///< degrees: the layer covers the unit-sphere cap within this of +y
  static constexpr double thickness = 0.005;   ///< m, along the rays from the kidney's centre
  static constexpr double size_ratio = 0.25;   ///< the layer's largest tet volume over the kidney's
  static constexpr double E = 2000, nu = 0.45, rho = 900;  ///< fat (Pa, -, kg/m^3): softer than the organ
};

/// The closed surface of the fat layer (m): the kidney surface's triangles
/// (KidneyScene::frequency) whose three vertices lie within cap_angle of +y
/// on the unit sphere, those same triangles moved out `thickness` along
/// the rays from the centre, and the walls joining the two along the
/// patch's rim (each wall quad lies in a plane through the centre).
/// Outward oriented; its inner side coincides with the kidney's surface.
SurfaceMesh kidney_fat_surface();

/// "@kidney-fat": two bodies, the built-in kidney (its mesh, material,
/// hilum support) and a fat layer (kidney_fat_surface, TetGen, tets up
/// to size_ratio of the kidney's largest; Neo-Hookean E = 2 kPa, nu = 0.45,
/// rho = 900 kg/m^3) lying on its lateral side, its rim walls fixed (held
/// by the tissue around it), frictionless contact between them; the probe
/// presses through the layer along the kidney's press axis, KidneyScene::
/// press_depth below the layer's outer surface; depth all (body contact).
scene::Scene kidney_fat_scene();

/// The built-in scene of a name ("@kidney", "@kidney-visco", "@kidney-fat"), or nullopt.
std::optional<scene::Scene> builtin_scene(const std::string& name);
/// Whether builtin_scene knows the name (without building the scene).
bool is_builtin_scene(const std::string& name);

}  // namespace tissue::io
