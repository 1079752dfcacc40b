// Dynamic relaxation to a tight equilibrium on any backend (docs/design.md
// section 2: "for quasi-static answers use dynamic relaxation, damping chosen
// from the lowest mode estimate"). The engine's own damped central
// difference is the relaxation: mass-proportional damping alpha = 2 omega_1
// damps the lowest mode critically and every higher one at the rate
// alpha / 2, the fastest decay one alpha can give them all.
//
// omega_1 is first taken from core lowest_mode_estimate (a geometric guess)
// and then measured during the relaxation (adaptive dynamic relaxation,
// Underwood 1983): once the fast modes have died, the step-to-step change of
// u is dominated by the slowest mode, and its Rayleigh quotient
//     omega^2 = (du . df) / (du . M du)   over free components,
// du = u^{n+k} - u^n, df = f(u^{n+k}) - f(u^n), estimates omega_1 (k = 1,
// or 50 with contact, leaving out each step's contact nodes). When the
// estimate moves alpha by more than 10%, the model is re-uploaded with the
// new alpha and the current displacements (velocity restarts at zero).
#pragma once

#include <functional>

#include <cstdint>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/backend.hpp"
#include "core/model.hpp"
#include "core/tool.hpp"

namespace tissue::accuracy {

/// A prescribed boundary: nodes driven on chosen components (Backend::set_driven_axes).
struct Drive {
  std::vector<index_t> nodes;      ///< driven nodes (n_driven)
  std::vector<double> u;           ///< their target displacements (n_driven x 3, xyz interleaved) m
  std::vector<std::uint8_t> axes;  ///< component mask per node (n_driven; bit c = axis c); empty = all three
};

/// A tool pressed and held during a relaxation: it moves from `start` to
/// `held` while the drive's targets ramp up, then stays at `held`; the
/// backend's contact stage (core/contact.hpp) acts as in a run.
struct HeldTool {
  ToolShape shape;
  ToolPose start, held;
  ContactOptions contact;
  double t_touch = 0;          ///< s: when the scripted path first touched the surface (reports)
};

/// How to relax.
struct RelaxOptions {
  double residual_tol = 1e-9;   ///< stop when |f_free| / |f_held| <= this (the Scheduler's relative residual)
  double kinetic_tol = 1e-12;   ///< ... and kinetic energy <= this x 0.5 |f_held| max|u| (relative)
  double ramp_time = -1;        ///< s over which the targets rise linearly from the start state; < 0 = one
                                ///< period 2 pi / omega of the lowest-mode estimate
  double damping = -1;          ///< initial alpha (1/s); < 0 = 2 x core lowest_mode_estimate
  bool adapt_damping = true;    ///< re-estimate omega_1 from the relaxation (Rayleigh quotient, above)
  bool mass_scaling = true;     ///< replace the nodal masses by fictitious ones that put every node at
                                ///< its stability limit for the model's dt (relaxation_masses below): the
                                ///< static answer does not depend on the masses, and equal local steps
                                ///< relax a graded mesh in far fewer steps than the smallest element's
  double mass_safety = 0.5;     ///< fraction of the Gershgorin stability bound the fictitious masses use
  double contact_mass_safety = 0.25;  ///< ... with a held tool: the contact's corrections need the margin
                                ///< (kidney held 5 mm in: 0.5 keeps a limit cycle at residual 0.04,
                                ///< 0.25 reaches 1e-7 in 8500 steps; docs/contact.md)
  int check_every = 200;        ///< steps between reductions (convergence checks)
  int adapt_every = 2000;       ///< steps between omega_1 estimates (after the ramp)
  double adapt_above = 1e-6;    ///< ... while the relative residual is above this: near the answer the
                                ///< step-to-step change is rounding (and, under a tool, contact nodes
                                ///< settling), not the slowest mode, and a restart would only perturb it
  long max_steps = 2'000'000;   ///< give up after this many steps (converged = false)
  double stall_periods = 3;     ///< give up when the best residual has not halved for this many periods
                                ///< 2 pi / omega_1 (critical damping divides it by ~500 per period): the
                                ///< rounding floor of the precision is reached (stalled = true)
  double max_wall = 600;        ///< ... or this many wall seconds
  double contact_floor = 30;    ///< under a tool, a relaxation that stalls within this factor of
                                ///< residual_tol, its kinetic tolerance met, has converged to the
                                ///< contact's floor: a surface node whose contact force is zero to
                                ///< rounding goes in and out of the contact set, each time leaving its
                                ///< rounding-size force in the residual (at_contact_floor = true)
  double force_floor = 1e-12;   ///< N, denominator floor of the relative residual
  BodyContactSpec bodies;       ///< contact between the model's bodies (Backend::set_body_contact), set again
                                ///< after every upload. A node inside another body, and the corners of the
                                ///< triangle it is inside, carry the contact's force: the residual then counts
                                ///< the free components of the other nodes, plus the net force of those (the
                                ///< two sides' contact forces cancel at equilibrium)
  std::function<bool()> stop;   ///< asked at every convergence check; true ends the relaxation there
                                ///< (RelaxResult::interrupted: a signal, apps/interrupt.hpp)
};

/// What a relaxation reached.
struct RelaxResult {
  bool converged = false;       ///< both tolerances met
  bool stalled = false;         ///< stopped at the precision's rounding floor (see stall_periods)
  bool at_contact_floor = false; ///< converged at the contact's floor (see contact_floor)
  bool interrupted = false;     ///< RelaxOptions::stop ended it
  std::string why;              ///< why it stopped, a phrase that follows "it" ("converged to the tolerances
                                ///< after N steps: ...", "hit the step limit of N steps ..."), with the numbers:
                                ///< converged to the tolerances,
                                ///< stalled (the rounding floor), the step or wall-time limit, interrupted
                                ///< (a breakdown -- NaN, an inverted element -- throws RelaxError instead)
  double residual = 0;          ///< relative free residual at the end
  double kinetic = 0;           ///< kinetic energy relative to 0.5 |f_held| max|u| at the end
  long steps = 0;               ///< TLED steps taken (ramp included)
  double wall = 0;              ///< s
  double damping = 0;           ///< final alpha (1/s)
  int restarts = 0;             ///< re-uploads for a new alpha
  Reductions last;              ///< the last reduction
  std::vector<double> history;  ///< relative residual at each check (every check_every steps)
};

/// A relaxation stopped by NaN/Inf or an inverted element (the message names
/// the step and the element).
struct RelaxError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// Uploads `model` (with the damping of `options`) to `backend` (whole mesh),
/// optionally sets the start displacements u0 (3 x n_nodes, m; empty = 0),
/// ramps `drive`'s targets from u0's values to their own (and moves `tool`,
/// if given, from its start to its held pose) over options.ramp_time, then
/// steps until the relative residual and kinetic
/// energy fall below the tolerances or the step/wall limits run out. The
/// backend is left holding the relaxed state (download() it). Throws
/// RelaxError on NaN/Inf or an inverted element, std::invalid_argument for a
/// malformed drive.
RelaxResult relax(Backend& backend, const TissueModel<double>& model, const Drive& drive, const RelaxOptions& options,
                  std::span<const double> u0 = {}, const HeldTool* tool = nullptr);

/// Fictitious nodal masses (n_nodes, kg) for dynamic relaxation with step
/// dt (s): m_a = dt^2 / (4 safety) sum_e (K_e + 4 mu_e / 3) V_e |dN_a| sum_b |dN_b|,
/// a Gershgorin bound on the row of the small-strain stiffness (||K_ab|| <=
/// (lambda + 2 mu) V |dN_a| |dN_b|), so that dt omega_max <= 2 sqrt(safety).
/// The masses follow the local stiffness, which equalises the nodes' stable
/// steps (Underwood's choice for dynamic relaxation).
std::vector<double> relaxation_masses(const TissueModel<double>& model, double dt, double safety);

/// Rayleigh-quotient estimate of omega^2 (rad^2/s^2) from two displacement
/// states (one step apart, or more) and the internal forces at them (3 x n_nodes each),
/// over the components `free_mask` marks (n_nodes, bit c = component c
/// free), with lumped masses (n_nodes, kg). Returns 0 when du is zero.
double rayleigh_omega2(std::span<const double> u0, std::span<const double> u1, std::span<const double> f0,
                       std::span<const double> f1, std::span<const double> mass,
                       std::span<const std::uint8_t> free_mask);

}  // namespace tissue::accuracy
