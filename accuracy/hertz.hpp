// Verification of the tool contact against Hertz's closed form (docs/contact.md):
// a rigid sphere of radius R pressed by delta into an elastic half-space
// needs the force
//     F = (4/3) E / (1 - nu^2) sqrt(R) delta^(3/2),   contact radius a = sqrt(R delta),
// for delta / R small (the linear-elastic, small-strain limit of Neo-Hookean).
//
// The half-space is a quarter block [0, L] x [0, L] x [-L, 0] with L = 50
// times the contact radius at the deepest press, its symmetry planes x = 0
// and y = 0 on rollers (the normal component held) and its base fixed; the
// sphere presses at the top corner on the z axis, and the force is four
// times the quarter's. The mesh is a cube of n^3 cells (6 tets each) mapped
// from the corner: a core [0, c]^3 with c a little over the largest contact
// radius is meshed uniformly, so the contact zone is resolved evenly and
// the time step is not cut by ever smaller corner cells; beyond it the
// cells grow as a power of the distance out to L, with aspect ratio about
// p. Each indentation is relaxed to equilibrium (accuracy/relaxation.hpp,
// the tool ramped from the previous one), whole mesh, double.
//
// Two elastic spheres (HertzOptions::spheres): radii R1, R2, moduli E1, E2
// pressed together by delta (the approach of distant points) need
//     F = (4/3) E* sqrt(R*) delta^(3/2),  1/E* = (1 - nu1^2)/E1 + (1 - nu2^2)/E2,  1/R* = 1/R1 + 1/R2
// (Johnson, Contact Mechanics, 4.2), Hertz's idealisation of each sphere as
// a half-space whose surface near the contact is the sphere's. Each body is
// the graded quarter block, the upper one mirrored onto the lower, and each
// face bent into its sphere's cap out to twice the largest contact radius
// (then on along the cap's tangent cone, never reached by the contact). The
// bodies meet at the origin; the lower block's base is fixed, the upper's
// far face driven down by delta, and the force is four times that face's
// reaction; the body contact (core/body_contact.hpp) is what carries it.
#pragma once

#include <string>
#include <vector>

#include "core/model.hpp"

namespace tissue::accuracy {

/// Hertz's force (N) for a rigid sphere of radius R (m) pressed delta (m)
/// into a half-space of Young's modulus E (Pa) and Poisson's ratio nu.
double hertz_force(double E, double nu, double R, double delta);

/// The graded quarter block (see above): n cells per axis, edge L (m), a
/// uniform core of edge `core` (m), cells beyond it growing with aspect
/// ratio about p >= 1; Neo-Hookean (E, nu), rho 1000.
ModelInput hertz_block(int n, double L, double core, double p, double E, double nu);

/// Hertz's force (N) for two elastic spheres (E1, nu1, R1) and (E2, nu2, R2)
/// pressed together by delta (m); a radius of infinity is a flat half-space.
double hertz_force_pair(double E1, double nu1, double R1, double E2, double nu2, double R2, double delta);

/// One sphere of a pair: its modulus (Pa), Poisson's ratio, radius (m).
struct HertzSphere {
  double E = 3000, nu = 0.45, R = 0.005;
};

/// The two bodies of a pair as one mesh: the lower (nodes first, base
/// fixed) and the upper (from `first_upper`), each a graded quarter block
/// (hertz_block's n, L, core, p) with its contact face bent into its
/// sphere's cap out to radius `cap` (m, below either radius); materials 0
/// and 1. `upper_far` lists the upper block's far face (driven).
struct HertzPairMesh {
  ModelInput in;
  index_t first_upper = 0;
  std::vector<index_t> upper_far;
};
HertzPairMesh hertz_pair(int n, double L, double core, double p, const HertzSphere& lower, const HertzSphere& upper,
                         double cap);

struct HertzOptions {
  double E = 3000;                  ///< Pa
  double nu = 0.45;
  double R = 0.005;                 ///< sphere radius (m)
  std::vector<double> ratios = {0.025, 0.05, 0.075, 0.1};  ///< delta / R (spheres: / R*), ascending
  bool spheres = false;             ///< two elastic spheres: (E, nu, R) the lower, `upper` the upper
  HertzSphere upper = {6000, 0.45, 0.005};
  double block = 50;                ///< L / contact radius at the deepest press
  double core = 1.5;                ///< uniform core edge / contact radius at the deepest press
  double grading = 3;               ///< aspect ratio of the cells beyond the core
  std::vector<int> levels = {16, 24, 32, 48};  ///< cells per axis, coarse to fine
  std::string backend = "cpu";      ///< relaxes in double on it
  double residual_tol = 1e-5;       ///< each relaxation's relative residual
  bool verbose = true;              ///< progress on stderr
};

/// One indentation on one mesh.
struct HertzPoint {
  double delta = 0;                 ///< m
  double force = 0;                 ///< N, the whole sphere's (4 x the quarter)
  double hertz = 0;                 ///< N, the closed form
  double error = 0;                 ///< (force - hertz) / hertz
  index_t contact_nodes = 0;        ///< in the quarter (spheres: nodes of either body inside the other)
  double spread = 0;                ///< spheres: (max - min) / mean of the force over the steps it was averaged
                                    ///< over, when a contact node kept cycling (0: it came to rest)
  double balance = 0;               ///< spheres: |base + far face reactions| / far face's (0 for the rigid tool)
};

/// One mesh.
struct HertzLevel {
  int cells = 0;                    ///< per axis
  index_t nodes = 0, elems = 0;
  double h_contact = 0;             ///< mean element edge under the tool at the deepest press (m)
  std::vector<HertzPoint> points;
  double max_error = 0;             ///< max |error| over the points
  double wall = 0;                  ///< s
};

struct HertzStudy {
  HertzOptions options;
  std::string device;
  double L = 0;                     ///< block edge (m)
  std::vector<HertzLevel> levels;
};

/// Runs every level. Throws what the relaxation throws (RelaxError, ...).
HertzStudy run_hertz(const HertzOptions& options);

/// The study as a table (stdout) and as JSON.
std::string hertz_table(const HertzStudy& study);
std::string hertz_json(const HertzStudy& study);

}  // namespace tissue::accuracy
