// Force rendering through a virtual coupling (Colgate, Stanley & Brown 1995;
// Adams & Hannaford 1999): the haptic device never touches the tissue
// directly. A virtual tool, the proxy (mass m_p), is tied to the device by a
// spring k_c and a damper b_c; the proxy is what the Scheduler sees as the
// tool (it drives the contact triangle), and the device renders the pull of
// the coupling spring, clamped to the device's maximum force.
//
// Per haptic period h, with device sample x_d (velocity v_d by backward
// difference) and F_e the tissue's force on the tool from the previous tick:
//
//   m_eff v_p' = m_p v_p + h (k_c (x_d - x_p) + b_c v_d + F_e),
//   m_eff      = m_p + h b_c + h^2 k_c,
//   x_p'       = x_p + h v_p',
//   F_device   = clamp(k_c (x_p' - x_d), F_max).
//
// This is backward Euler in the coupling terms and explicit in F_e:
// - the proxy-coupling subsystem is dissipative for every h, k_c, b_c, m_p
//   (backward Euler removes 1/2 m_p |dv|^2 + 1/2 k_c |dx|^2 per step on top
//   of the damper's h b_c |v_p - v_d|^2), so it cannot create energy;
// - the tissue force enters one period late (symplectic Euler in it), which
//   is stable while h^2 k_e < 4 m_p for a contact stiffness k_e (defaults:
//   k_e < 4 kN/m; soft tissue under a probe is 1 to 100 N/m);
// - the device feels a spring to a damped mass, impedance
//   Z(s) = k_c m_p s / (m_p s^2 + b_c s + k_c), positive real
//   (Re Z(jw) = k_c m_p b_c w^2 / |k_c - m_p w^2 + j b_c w|^2 >= 0), hence
//   passive; holding it for a period costs k_c h / 2 of the device's own
//   damping (Colgate & Schenkel 1997): b_dev > k_c h / 2 = 0.2 N s/m with the
//   defaults, and k_c stays below the 700 N/m CHAI3D recommends for the
//   Phantom Omni. The damper is not rendered, so the device velocity estimate
//   (a finite difference) never reaches the force directly.
// Continuity: the rendered force follows F_e through the proxy dynamics,
// overdamped with the defaults (w_n = sqrt(k_c / m_p) = 632 rad/s,
// zeta = b_c / (2 sqrt(k_c m_p)) = 1.58, slow pole k_c / b_c = 200 rad/s,
// about 5 ms of lag), so its step response is monotone: a jump dF of the
// tissue force reaches the device over several periods, at most
// coupling_jump_gain() |dF| = 0.14 |dF| per period, and (device at rest) the
// device's force never changes faster than the tissue's. At rest the rendered force equals
// the tissue force (k_c (x_p - x_d) = F_e). The price is the lag and the
// proxy's inertia m_p a (1 g: 10 mN at 10 m/s^2) felt as the hand
// accelerates. docs/viewer.md derives all of this.
#pragma once

#include "core/device.hpp"
#include "core/vec.hpp"

namespace tissue {

/// Virtual coupling parameters (SI). Defaults suit a Phantom Omni at 1 kHz.
struct CouplingParams {
  double stiffness = 400;     ///< k_c, coupling spring (N/m)
  double damping = 2.0;       ///< b_c, coupling damper on the proxy (N s/m)
  double proxy_mass = 0.001;  ///< m_p, virtual tool mass (kg)
  double max_force = 3.3;    ///< F_max, device peak force (N); Phantom Omni: 3.3 N
  double period = 1e-3;      ///< h, haptic period (s)
};

/// Throws std::invalid_argument naming the parameter when one is not finite
/// and positive (damping may be 0).
void validate(const CouplingParams& p);

/// Largest change of the rendered force in one period after the tissue
/// force jumps by 1 N with the device at rest (N per N): the largest
/// increment of the coupling's discrete unit-step response, which it runs.
double coupling_jump_gain(const CouplingParams& p);

/// `f` scaled down to magnitude `max_force` when longer (direction kept).
Vec3<double> clamp_force(Vec3<double> f, double max_force);

/// State of the coupling between two periods.
struct CouplingState {
  bool started = false;        ///< false until the first device sample
  Vec3<double> proxy = {};     ///< x_p (m)
  Vec3<double> proxy_vel = {}; ///< v_p (m/s)
  Vec3<double> device = {};    ///< x_d, last device sample (m)
  Vec3<double> device_vel = {};///< v_d, backward difference (m/s)
  Vec3<double> env_force = {}; ///< F_e, tissue force on the proxy (N)
  Vec3<double> coupling = {};  ///< unclamped spring force on the device: k_c (x_p - x_d) (N)
  Vec3<double> rendered = {};  ///< clamped force sent to the device (N)
  bool clamped = false;        ///< |coupling| > F_max in the last period
};

/// Advances the proxy one period to device sample `device_pos` (m) with the
/// stored tissue force, then recomputes the coupling and rendered forces.
/// The first call places the proxy on the device. Returns the new proxy
/// position.
Vec3<double> coupling_step(const CouplingParams& p, CouplingState& s, Vec3<double> device_pos);

/// A Device adapter: the Scheduler reads the proxy and sends it the tissue
/// force; the wrapped device gets the clamped coupling force. Not thread-safe
/// (the haptic thread alone uses it).
class CoupledDevice : public Device {
 public:
  /// Wraps `inner` (which must outlive this); validates `params`.
  CoupledDevice(Device& inner, CouplingParams params);

  /// Reads the wrapped device at t (s) and returns the advanced proxy (m)
  /// as the tip; the axis and the grasp button pass through unchanged.
  ToolInput read(double t) override;
  /// Stores the tissue force on the tool (N) and sends the rendered force on.
  void send_force(const Vec3<double>& force) override;
  bool finished(double t) const override { return inner_.finished(t); }

  const CouplingParams& params() const { return params_; }
  const CouplingState& state() const { return state_; }
  Device& inner() { return inner_; }

 private:
  Device& inner_;
  CouplingParams params_;
  CouplingState state_;
};

}  // namespace tissue
