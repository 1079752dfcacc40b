// The per-node rules of a TLED step and of the per-tick reductions, written
// once for every backend as host/device functions (the per-element rules
// are core/tet.hpp, the contact rules core/contact.hpp); cpu/ and cuda/ only
// loop over nodes and call these.
//
// Holding rule, per component (an axis mask per node, model.hpp kAllAxes):
//   fixed  (kFixed, or kFixedX/Y/Z for one component)  held at 0, wins over everything
//   driven (Backend::set_driven's axis mask)          held at the drive's target
//   halo   (region role kHalo)                        every component held; the others at
//                                                     u when the node became halo
//   anything else in the region                       integrated (central difference)
#pragma once

#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <type_traits>

#include "core/contact.hpp"
#include "core/cube_root.hpp"
#include "core/model.hpp"
#include "core/tet.hpp"

namespace tissue {

/// u^{n+1} of one node: the held components (axis mask h) at their targets
/// u_held, the others by the damped central difference with the
/// out-of-balance force f = f_int - R (R: the applied load, Backend::set_loads;
/// 0 without).
///
/// Double takes the three-term form u' = A (R - f) + B u + C u_prev. Float
/// takes the increment form u' = u + (A (R - f) - C (u - u_prev)) (in exact
/// arithmetic B + C = 1, so both are the same update), compensated: the low bits that
/// rounding u + increment to u's spacing drops are kept per node in carry
/// and added to the next step's increment (Kahan summation). Uncompensated,
/// the rounded B and C act as a spring of about eps m / dt^2 on every node
/// and u' is rounded to u's spacing every step: float drifted 4e-5 to 1e-4
/// of max |u| from double on nu 0.49 cubes; compensated, 1e-6
/// (docs/accuracy.md, section 7). carry is zero in held components and in
/// double.
template <class T>
TISSUE_HD Vec3<T> node_next(std::uint8_t h, Vec3<T> u_held, const CentralDifference<T>& cd, Vec3<T> f, Vec3<T> u,
                            Vec3<T> u_prev, Vec3<T>& carry) {
  if (h == kAllAxes) {
    carry = {T(0), T(0), T(0)};
    return u_held;
  }
  Vec3<T> next;
  if constexpr (std::is_same_v<T, float>) {
    for (int c = 0; c < 3; ++c) {
      const T step = cd.A * -f[c] - cd.C * (u[c] - u_prev[c]);
      const T y = step - carry[c];
      const T t = u[c] + y;
      carry[c] = (t - u[c]) - y;
      next[c] = t;
    }
  } else {
    next = {central_difference_update(cd, -f.x, u.x, u_prev.x), central_difference_update(cd, -f.y, u.y, u_prev.y),
            central_difference_update(cd, -f.z, u.z, u_prev.z)};
  }
  for (int c = 0; c < 3; ++c)
    if (h >> c & 1) {
      next[c] = u_held[c];
      carry[c] = T(0);
    }
  return next;
}

/// Target of a halo node: 0 where the model fixes it (axis mask `fixed`),
/// the drive's target (already in held_at) where it is driven, else its
/// current displacement u.
template <class T>
TISSUE_HD Vec3<T> halo_target(std::uint8_t fixed, std::uint8_t driven, Vec3<T> u, Vec3<T> held_at) {
  for (int c = 0; c < 3; ++c) {
    if (fixed >> c & 1)
      held_at[c] = T(0);
    else if (!(driven >> c & 1))
      held_at[c] = u[c];
  }
  return held_at;
}

/// A contact correction dx applied to the components that are free (held
/// mask h clear).
template <class T>
TISSUE_HD Vec3<T> free_part(std::uint8_t h, Vec3<T> dx) {
  return {(h & 1) ? T(0) : dx.x, (h & 2) ? T(0) : dx.y, (h & 4) ? T(0) : dx.z};
}

/// Coulomb friction at a pushed node (core/contact.hpp, docs/contact.md
/// "Friction"): u1 is its displacement after the step's contact correction
/// dx along the contact normal n (dx = push n, push >= 0; |dx| is taken
/// only when mu > 0, so the frictionless step pays nothing), u_now its
/// displacement before the step, w the tool's motion at the node over the
/// step (tool_motion_at), h its held axes. The node's tangential motion
/// relative to the tool, s, is removed up to mu push: all of it when
/// |s| <= mu push (it sticks: it moves with the tool), else mu push of it
/// (it slides). The correction of an explicit step is the impulse of the
/// force that makes it (A f, A = the node's cd_A), so this is Coulomb's law
/// on that force, |f_t| <= mu f_n, with no state kept from step to step; a
/// node held by the tool at rest has A f_n = push and A f_t = |s|, the
/// quasi-static forces contact_reaction reports. Returns the new u1 (mu = 0:
/// u1 itself, the frictionless rule).
template <class T>
TISSUE_HD Vec3<T> coulomb_slip(std::uint8_t h, Vec3<T> u_now, Vec3<T> u1, Vec3<T> n, Vec3<T> w, Vec3<T> dx, T mu) {
  if (!(mu > T(0))) return u1;
  const Vec3<T> rel = u1 - u_now - w;
  const Vec3<T> slip = free_part(h, rel - dot(rel, n) * n);
  const T s = norm(slip), cap = mu * norm(dx);
  return u1 - (s > cap ? cap / s : T(1)) * slip;
}

/// A contact node keeps this fraction of its tangential velocity relative
/// to the tool per TLED step (contact_previous).
inline constexpr double kContactTangentialKeep = 0.5;

/// The contact's velocity rule: a node that contact moved leaves the step
/// with the tool's velocity along its contact normal n (inelastic: no
/// bounce, no kick) and with half of its own tangential velocity relative
/// to the tool (w: the tool's motion at the node over the step,
/// tool_motion_at), in its free components (h: held axes). The
/// central-difference state carries the velocity as u^{n+1} - u^n, so the
/// contact sets u^n (returned). A node that coulomb_slip stuck has no
/// tangential velocity relative to the tool; on a frictionless tool the
/// tangential forces move the node along the tool in every step and the
/// equilibrium is the frictionless one; the halving is a viscous damping
/// of the contact nodes' sliding. Measured on the kidney held 5 mm in (docs/contact.md):
/// moving only u^{n+1} turned every correction into velocity (a corner
/// that face contact lifted flew on); resetting the normal velocity alone
/// left sliding nodes pumping energy into the faceted contact (remeshed to
/// 20,000 and 50,000 tets: inverted elements within 6,000 steps); with the
/// halving every mesh settles to a relative residual below 1e-6.
template <class T>
TISSUE_HD Vec3<T> contact_previous(std::uint8_t h, Vec3<T> u_now, Vec3<T> u_next, Vec3<T> n, Vec3<T> w) {
  const Vec3<T> rel = u_next - u_now - w;  // the node's motion relative to the tool over the step
  const Vec3<T> normal = dot(rel, n) * n;
  return u_now + free_part(h, normal + T(1 - kContactTangentialKeep) * (rel - normal));
}

/// What one surface node's contact is after a step, merged over the
/// proposals of its triangles (core/contact.hpp's step 2).
template <class T>
struct NodeContact {
  Vec3<T> dx = {T(0), T(0), T(0)};  ///< correction (m); the contact normal is dx / |dx|
  T largest2 = T(0);                ///< |dx_i|^2 of the largest proposal merged
  signed char tool = -1;            ///< the tool of the largest proposal
  std::uint8_t kind = kNoContact;   ///< ContactKind
};

/// Passes of merge_corner over a node's proposals (core/contact.hpp's step 2).
inline constexpr int kMergePasses = 4;

/// How far the correction dx falls short of a proposal c of length len
/// along c (merge_corner and pass_would_change: one expression for both).
template <class T>
TISSUE_HD T merge_shortfall(Vec3<T> dx, Vec3<T> c, T len) {
  return len - dot(dx, c) / len;
}

/// Whether a shortfall counts: one within rounding of a proposal already met
/// is none.
template <class T>
TISSUE_HD bool merge_falls_short(T shortfall, T len) {
  return shortfall > T(8) * std::numeric_limits<T>::epsilon() * len;
}

/// Merges one triangle's proposal for this node (call in ascending triangle
/// order, kMergePasses times over the node's proposals; core/contact.hpp's
/// step 2): the first proposal is taken as it is, every further one adds its
/// shortfall along its own direction. A blocked
/// penetration (rigid support, outside the region) is kept only while no
/// correction was proposed, rigid before outside.
template <class T>
TISSUE_HD void merge_corner(NodeContact<T>& acc, const CornerContact<T>& c) {
  const T s2 = dot(c.dx, c.dx);
  if (s2 > T(0)) {
    if (acc.kind != kPushed) {
      acc.dx = c.dx;
    } else {
      const T len = std::sqrt(s2);
      const T shortfall = merge_shortfall(acc.dx, c.dx, len);
      if (merge_falls_short(shortfall, len)) acc.dx = acc.dx + (shortfall / len) * c.dx;
    }
    if (s2 > acc.largest2) {
      acc.largest2 = s2;
      acc.tool = c.tool;
    }
    acc.kind = kPushed;
    return;
  }
  if (acc.kind == kPushed || !c.blocked) return;
  if (acc.kind == kNoContact || (acc.kind == kOutsideRegion && c.blocked == kRigidContact)) {
    acc.kind = c.blocked;
    acc.tool = c.tool;
  }
}

/// Whether two merge states have the same bits (then a further pass over the
/// same proposals computes exactly what the last one did: merge_corner is a
/// function of the state and the proposal alone).
template <class T>
TISSUE_HD bool same_bits(const NodeContact<T>& a, const NodeContact<T>& b) {
  using U = typename detail::FloatBits<T>::U;  // (core/cube_root.hpp)
  const auto same = [](T x, T y) { return std::bit_cast<U>(x) == std::bit_cast<U>(y); };
  return same(a.dx.x, b.dx.x) && same(a.dx.y, b.dx.y) && same(a.dx.z, b.dx.z) && same(a.largest2, b.largest2) &&
         a.tool == b.tool && a.kind == b.kind;
}

/// A node's merged contact from its `count` proposals, get(j) giving the
/// j-th in ascending triangle order: kMergePasses passes of merge_corner
/// (one when nothing was proposed). Proposals within 90 degrees of each
/// other are satisfied after the first pass; more obtuse ones (a node
/// squeezed from two sides) approach theirs by a factor cos(angle - 90 deg)
/// per pass, and the next step goes on. A pass that leaves the state's bits
/// as they were ends the passes: the rest would repeat it (the same result
/// as all kMergePasses, in two passes for most nodes; the GPU merges with
/// merge_proposals_unrolled below).
template <class T, class Get>
TISSUE_HD NodeContact<T> merge_proposals(int count, Get get) {
  NodeContact<T> acc;
  for (int pass = 0; pass < kMergePasses; ++pass) {
    const NodeContact<T> before = acc;
    for (int j = 0; j < count; ++j) merge_corner(acc, get(j));
    if (acc.kind != kPushed || (pass > 0 && same_bits(acc, before))) break;
  }
  return acc;
}

/// Whether one more pass of merge_corner over a pushed node's proposals
/// (at most N; get(j) as merge_proposals') would change its state acc. It
/// would not when no proposal of positive length falls short of acc.dx
/// (merge_falls_short) and none is longer than the largest merged (after a
/// whole pass none is; tested all the same, so that the argument does not
/// rest on it): each merge_corner of the pass then meets the state the pass
/// started with and leaves it as it is (a zero or blocked proposal leaves a
/// pushed node as it is), and same_bits would end the passes after it. Each
/// test reads only that starting state, so they are independent and a GPU
/// thread runs them side by side; the pass itself is one chain through
/// acc.dx. The tests are merge_corner's own expressions: the same bits as
/// long as the compiler rounds an inlined expression alike in both places,
/// which the step modes' bits rest on as well (a fused multiply-add formed
/// in one and not the other could differ by a rounding at the threshold);
/// cuda_tests' Merge.LaterPassesCheckedSideBySideGiveEveryPassesBits checks
/// it on the device.
template <int N, class T, class Get>
TISSUE_HD bool pass_would_change(const NodeContact<T>& acc, int count, Get get) {
  bool change = false;
  TISSUE_UNROLL
  for (int j = 0; j < N; ++j) {
    if (!(j < count)) continue;
    const Vec3<T> c = get(j).dx;
    const T s2 = dot(c, c);
    if (!(s2 > T(0))) continue;
    const T len = std::sqrt(s2);
    change |=
        merge_falls_short(merge_shortfall(acc.dx, c, len), len) | (s2 > acc.largest2);  // (no short cut: side by side)
  }
  return change;
}

/// merge_proposals for at most N proposals, in the same order and with the
/// same result: get(j) is called with constant j once the loops unroll, so a
/// GPU thread can keep a node's proposals in registers and read each from
/// memory once (the loop above reads them kMergePasses times; on the kidney
/// in contact on an H100 the gather's busiest multiprocessor went from 9.8
/// to 7.7 us per step). A pass after the first runs only when
/// pass_would_change says it would change something: most pushed nodes are
/// done after one pass, and the check that says so is N independent tests
/// where the pass that found it was a chain (on an H200 the kidney's tick
/// about 2 % shorter; a node that needs a further pass pays for the check
/// as well: docs/cuda.md, "The contact stage's own chains").
template <int N, class T, class Get>
TISSUE_HD NodeContact<T> merge_proposals_unrolled(int count, Get get) {
  NodeContact<T> acc;
  for (int pass = 0; pass < kMergePasses; ++pass) {
    if (pass > 0 && !pass_would_change<N>(acc, count, get)) break;  // the pass would leave the same bits
    const NodeContact<T> before = acc;
    TISSUE_UNROLL
    for (int j = 0; j < N; ++j)
      if (j < count) merge_corner(acc, get(j));
    if (acc.kind != kPushed || (pass > 0 && same_bits(acc, before))) break;
  }
  return acc;
}

/// Per-node terms of the tick's reductions (core Reductions), in double.
struct NodeTerms {
  double reaction[3] = {0, 0, 0};  ///< driven components' internal force
  double internal[3] = {0, 0, 0};  ///< inner nodes' internal force
  double free2 = 0, held2 = 0;     ///< squared force over free / held components of inner nodes
  double kinetic = 0;              ///< J
  double disp = 0;                 ///< |u| (m)
  bool finite = true;
};

/// The terms of node a: internal force f (N), displacement u and u_prev (m),
/// lumped mass (kg), step dt (s), inner or not, its held and driven axis
/// masks, and its contact: a pushed node's normal component counts as held
/// (the tool holds it), its tangential part as free.
template <class T>
TISSUE_HD NodeTerms node_terms(Vec3<T> f_, Vec3<T> u_, Vec3<T> up_, double mass, double dt, bool inner,
                               std::uint8_t held, std::uint8_t driven, std::uint8_t contact, Vec3<T> normal) {
  NodeTerms t;
  const double f[3] = {double(f_.x), double(f_.y), double(f_.z)};
  double u2 = 0, v2 = 0;
  for (int c = 0; c < 3; ++c) {
    const double u = double(u_[c]), v = (u - double(up_[c])) / dt;
    u2 += u * u;
    v2 += v * v;
    if (driven >> c & 1) t.reaction[c] = f[c];
  }
  const double f2 = f[0] * f[0] + f[1] * f[1] + f[2] * f[2];
  t.kinetic = 0.5 * mass * v2;
  t.disp = std::sqrt(u2);
  t.finite = f2 - f2 == 0 && u2 - u2 == 0 && v2 - v2 == 0;  // false for NaN and infinity
  if (!inner) return t;
  double free_n = 0;  // normal part of the free components of a pushed node
  const bool pushed = contact == kPushed;
  for (int c = 0; c < 3; ++c) {
    t.internal[c] = f[c];
    if (held >> c & 1)
      t.held2 += f[c] * f[c];
    else
      t.free2 += f[c] * f[c];
    if (pushed && !(held >> c & 1)) free_n += f[c] * double(normal[c]);
  }
  if (contact == kGrasped) {  // every component held by the tool
    t.held2 += t.free2;
    t.free2 = 0;
  } else if (pushed) {
    t.held2 += free_n * free_n;
    t.free2 = t.free2 > free_n * free_n ? t.free2 - free_n * free_n : 0.0;
  }
  return t;
}

}  // namespace tissue
