// Per-element and per-node TLED math for linear 4-node tetrahedra, written
// once for every backend (docs/design.md section 2). All quantities refer to the
// undeformed configuration. Shapes: a tet's shape-function gradients are
// dN[3*a + j] = dN_a/dX_j (a = corner 0..3, j = axis 0..2), in 1/m.
#pragma once

#include <cmath>
#include <cstdint>

#include "core/cube_root.hpp"
#include "core/material.hpp"
#include "core/vec.hpp"

namespace tissue {

/// Reference volume (m^3, signed: > 0 for positively oriented corners) and
/// shape-function gradients dN (4 x 3, 1/m) of the tet X[0..3] (m).
/// Returns the signed volume; dN is written only when it is non-zero.
template <class T>
TISSUE_HD T tet_shape_gradients(const Vec3<T> X[4], T dN[12]) {
  // Columns of J are the edge vectors from corner 0: X = X0 + J (xi, eta, zeta).
  Mat3<T> J = {{X[1].x - X[0].x, X[2].x - X[0].x, X[3].x - X[0].x,  //
                X[1].y - X[0].y, X[2].y - X[0].y, X[3].y - X[0].y,  //
                X[1].z - X[0].z, X[2].z - X[0].z, X[3].z - X[0].z}};
  const T d = det(J);
  if (d == T(0)) return T(0);
  const Mat3<T> Ji = inverse(J, d);  // rows of J^-1 are d(xi,eta,zeta)/dX
  for (int j = 0; j < 3; ++j) {
    dN[3 + j] = Ji(0, j);
    dN[6 + j] = Ji(1, j);
    dN[9 + j] = Ji(2, j);
    dN[j] = -(Ji(0, j) + Ji(1, j) + Ji(2, j));
  }
  return d / T(6);
}

/// tet_shape_gradients at precision T from corners given in double: the
/// edges from corner 0 are differenced in double and only then rounded to
/// T. A float copy of the absolute coordinates would carry its rounding
/// (half an ulp of 0.1 m is 3.7e-9 m, 3.7e-6 of a 1 mm edge) into every
/// gradient; rounding the edges keeps a well-shaped tet's float gradients
/// within a few ulps of its double ones (shape_gradient_deviation). The cuda
/// backend recomputes an element's gradients with it at every pass instead
/// of loading them (docs/cuda.md, "Element gradients"). dN is zero when the
/// rounded tet has no volume.
template <class T>
TISSUE_HD T tet_shape_gradients_from(const Vec3<double> X[4], T dN[12]) {
  Vec3<T> R[4];
  R[0] = {T(0), T(0), T(0)};
TISSUE_UNROLL
  for (int a = 1; a < 4; ++a) R[a] = {T(X[a].x - X[0].x), T(X[a].y - X[0].y), T(X[a].z - X[0].z)};
TISSUE_UNROLL
  for (int k = 0; k < 12; ++k) dN[k] = T(0);
  return tet_shape_gradients(R, dN);
}

/// A reference position on a fixed-point grid (core/model.hpp
/// ReferenceGrid): whole steps from the grid's origin on each axis, below
/// 2^31. w is unused: 16 bytes, one load on the GPU.
struct alignas(16) GridPoint {
  std::int32_t x = 0, y = 0, z = 0, w = 0;
};

/// tet_shape_gradients at precision T from corners on a grid of `step` m (a
/// power of two): the edges from corner 0 are differenced exactly in
/// integers, rounded to T once and scaled by the step (exact), as
/// tet_shape_gradients_from rounds its double edges. The grid puts each
/// corner within half a step of its position, so an edge moves by at most a
/// step, about 2^-30 of the mesh's extent (2^-34 m, 5.8e-11 m, on a mesh
/// 0.06-0.12 m across: 3e-8 of a 2 mm edge, a quarter of a float ulp). So
/// the gradients are tet_shape_gradients_from's to an ulp or two where the
/// edges are at least ~1/64 of the extent, and stray further as the
/// elements shrink against it (core/model.hpp ReferenceGrid); the cuda
/// backend checks every element before its float passes recompute with it
/// (worst_gradient_deviation; docs/cuda.md, "Reference positions on a
/// grid"). dN is zero when the rounded tet has no volume.
template <class T>
TISSUE_HD T tet_shape_gradients_on_grid(const GridPoint q[4], T step, T dN[12]) {
  Vec3<T> R[4];
  R[0] = {T(0), T(0), T(0)};
TISSUE_UNROLL
  for (int a = 1; a < 4; ++a)
    R[a] = {T(q[a].x - q[0].x) * step, T(q[a].y - q[0].y) * step, T(q[a].z - q[0].z) * step};
TISSUE_UNROLL
  for (int k = 0; k < 12; ++k) dN[k] = T(0);
  return tet_shape_gradients(R, dN);
}

/// How far recomputed gradients dN and volume V (at any precision) stray
/// from the tet's double gradients dN_ref and volume V_ref
/// (tet_shape_gradients<double>): the largest gradient difference relative
/// to the largest |dN_ref|, or the volume's relative difference, whichever
/// is larger. A few 1e-7 for a well-shaped tet in float; it grows with the
/// tet's condition (a sliver's can reach 1 and beyond).
template <class T>
double gradient_deviation(const T dN[12], T V_recomputed, const double dN_ref[12], double V_ref) {
  const double V = static_cast<double>(V_recomputed);
  double scale = 0, worst = 0;
  for (int k = 0; k < 12; ++k) {
    scale = std::fmax(scale, std::fabs(dN_ref[k]));
    const double diff = std::fabs(static_cast<double>(dN[k]) - dN_ref[k]);
    if (!(diff <= worst)) worst = diff;  // a NaN sticks
  }
  const double dV = std::fabs(V - V_ref) / std::fabs(V_ref);
  const double d = worst / scale;
  return std::isfinite(d) && std::isfinite(dV) ? std::fmax(d, dV) : HUGE_VAL;
}

/// gradient_deviation of tet_shape_gradients_from<T> (double positions).
template <class T>
double shape_gradient_deviation(const Vec3<double> X[4], const double dN_ref[12], double V_ref) {
  T dN[12];
  const T V = tet_shape_gradients_from<T>(X, dN);
  return gradient_deviation(dN, V, dN_ref, V_ref);
}

/// Smallest altitude of the tet (m): 3 V / largest face area. The
/// characteristic length L_e of the critical time step.
template <class T>
TISSUE_HD T tet_min_altitude(const Vec3<T> X[4], T volume) {
  const int faces[4][3] = {{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}};
  T max_area = 0;
  for (const auto& f : faces) {
    const T a = T(0.5) * norm(cross(X[f[1]] - X[f[0]], X[f[2]] - X[f[0]]));
    max_area = a > max_area ? a : max_area;
  }
  return T(3) * std::fabs(volume) / max_area;
}

/// Deformation gradient F = I + sum_a u_a (dN_a/dX)^T from corner
/// displacements u (m).
template <class T>
TISSUE_HD Mat3<T> deformation_gradient(const Vec3<T> u[4], const T dN[12]) {
  Mat3<T> F = Mat3<T>::identity();
TISSUE_UNROLL
  for (int a = 0; a < 4; ++a)
TISSUE_UNROLL
    for (int i = 0; i < 3; ++i)
TISSUE_UNROLL
      for (int j = 0; j < 3; ++j) F(i, j) += u[a][i] * dN[3 * a + j];
  return F;
}

/// Neo-Hookean second Piola-Kirchhoff stress (Pa) of docs/design.md section 2:
/// S = mu J^(-2/3) (I - I1/3 C^-1) + K J (J - 1) C^-1, C = F^T F, I1 = tr C.
/// J = det F must be > 0 (the caller checks).
template <class T>
TISSUE_HD Mat3<T> neo_hookean_pk2(const Mat3<T>& F, T J, T mu, T K) {
  const Mat3<T> C = transpose(F) * F;
  const T I1 = trace(C);
  const Mat3<T> Ci = inverse(C, J * J);  // det C = J^2
  const T cbrt_J = cube_root(J);
  const T a = mu / (cbrt_J * cbrt_J);  // mu J^(-2/3)
  const T b = -a * I1 / T(3) + K * J * (J - T(1));
  Mat3<T> S = b * Ci;
  S(0, 0) += a;
  S(1, 1) += a;
  S(2, 2) += a;
  return S;
}

/// The same plus the optional terms of core/material.hpp that Terms
/// instantiates, added in their list order (the Prony state in law
/// advances). A Neo-Hookean scene
/// never calls it: its kernels are neo_hookean_pk2's alone.
template <class Terms, class T>
TISSUE_HD Mat3<T> law_pk2(const Mat3<T>& F, T J, T mu, T K, ElementLaw<T>& law) {
  Mat3<T> S = neo_hookean_pk2(F, J, mu, K);
  const Mat3<T> C = transpose(F) * F;  // the compiler shares these with neo_hookean_pk2's
  const Mat3<T> Ci = inverse(C, J * J);
  const T cbrt_J = cube_root(J);
  Terms::add_pk2(S, LawPoint<T>{C, Ci, T(1) / (cbrt_J * cbrt_J), mu / (cbrt_J * cbrt_J)}, law);
  return S;
}

/// Neo-Hookean strain energy density (J/m^3):
/// W = mu/2 (J^(-2/3) I1 - 3) + K/2 (J - 1)^2.
template <class T>
TISSUE_HD T neo_hookean_energy(const Mat3<T>& F, T mu, T K) {
  const T J = det(F);
  const T I1 = trace(transpose(F) * F);
  const T cbrt_J = cube_root(J);
  return mu / T(2) * (I1 / (cbrt_J * cbrt_J) - T(3)) + K / T(2) * (J - T(1)) * (J - T(1));
}

/// Element pressure (Pa) from the volumetric law p = K (J - 1).
template <class T>
TISSUE_HD T volumetric_pressure(T J, T K) {
  return K * (J - T(1));
}

/// Element nodal forces f_a = V F S dN_a (N) for a given deformation
/// gradient F (already modified for IANP, or plain) and its PK2 stress S.
template <class T>
TISSUE_HD void element_nodal_forces(const Mat3<T>& F, const Mat3<T>& S, T volume, const T dN[12], Vec3<T> f[4]) {
  const Mat3<T> P = volume * (F * S);  // V times the first Piola-Kirchhoff stress
TISSUE_UNROLL
  for (int a = 0; a < 4; ++a) f[a] = P * Vec3<T>{dN[3 * a], dN[3 * a + 1], dN[3 * a + 2]};
}

/// f[a] = 0 for every corner unless `keep` (a select, not a branch).
template <class T>
TISSUE_HD void zero_unless(bool keep, Vec3<T> f[4]) {
TISSUE_UNROLL
  for (int a = 0; a < 4; ++a) f[a] = {keep ? f[a].x : T(0), keep ? f[a].y : T(0), keep ? f[a].z : T(0)};
}

/// law.q = next.q when `ok`, else unchanged (a select): a bad element's
/// stand-in arithmetic never reaches the Prony state.
template <class T>
TISSUE_HD void keep_state_unless_bad(bool ok, const ElementLaw<T>& next, ElementLaw<T>& law) {
TISSUE_UNROLL
  for (int i = 0; i < kMaxProny; ++i)
TISSUE_UNROLL
    for (int c = 0; c < kSymComponents; ++c) law.q[i][c] = ok ? next.q[i][c] : law.q[i][c];
}

/// IANP pass 3 for one element: from the averaged nodal pressure pbar (Pa),
/// Jbar = 1 + pbar / K, Fbar = (Jbar / J)^(1/3) F, then f_a = V Fbar S(Fbar) dN_a.
/// Returns J = det F of the unmodified gradient; a bad element (J <= 0,
/// Jbar <= 0 or NaN) gets zero forces and returns the offending value (J,
/// or Jbar when only Jbar is bad). Branch-free: a bad element's arithmetic
/// runs on stand-in values (J = Jbar = 1) and its forces are selected away,
/// so SIMD lanes and GPU warps never diverge. F is the element's
/// deformation_gradient (pass 1 may have computed it already).
template <class Terms, class T>
TISSUE_HD T ianp_element_forces(const Mat3<T>& F, const T dN[12], T volume, T mu, T K, T pbar, Vec3<T> f[4],
                                ElementLaw<T>& law) {
  const T J = det(F);
  const T Jbar = T(1) + pbar / K;
  const bool ok = (J > T(0)) & (Jbar > T(0));  // & not &&: no branch
  const T Js = ok ? J : T(1), Jbars = ok ? Jbar : T(1);
  const Mat3<T> Fbar = cube_root(Jbars / Js) * F;
  if constexpr (Terms::stateful) {
    ElementLaw<T> next = law;
    element_nodal_forces(Fbar, law_pk2<Terms>(Fbar, Jbars, mu, K, next), volume, dN, f);
    keep_state_unless_bad(ok, next, law);
  } else {
    element_nodal_forces(Fbar, law_pk2<Terms>(Fbar, Jbars, mu, K, law), volume, dN, f);
  }
  zero_unless(ok, f);
  return ok ? J : (J > T(0) ? Jbar : J);
}

/// Neo-Hookean alone (no law data: the kernels of a Neo-Hookean scene).
template <class T>
TISSUE_HD T ianp_element_forces(const Mat3<T>& F, const T dN[12], T volume, T mu, T K, T pbar, Vec3<T> f[4]) {
  const T J = det(F);
  const T Jbar = T(1) + pbar / K;
  const bool ok = (J > T(0)) & (Jbar > T(0));  // & not &&: no branch
  const T Js = ok ? J : T(1), Jbars = ok ? Jbar : T(1);
  const Mat3<T> Fbar = cube_root(Jbars / Js) * F;
  element_nodal_forces(Fbar, neo_hookean_pk2(Fbar, Jbars, mu, K), volume, dN, f);
  zero_unless(ok, f);
  return ok ? J : (J > T(0) ? Jbar : J);
}

/// The same from the corner displacements u (m).
template <class T>
TISSUE_HD T ianp_element_forces(const Vec3<T> u[4], const T dN[12], T volume, T mu, T K, T pbar, Vec3<T> f[4]) {
  return ianp_element_forces(deformation_gradient(u, dN), dN, volume, mu, K, pbar, f);
}

/// Plain (un-averaged) tet forces f_a = V F S(F) dN_a: the locking-prone
/// formulation, kept as a reference for tests and the locking study.
/// Returns J; a bad element (J <= 0 or NaN) gets zero forces (branch-free,
/// as above), from the deformation gradient F.
template <class Terms, class T>
TISSUE_HD T plain_element_forces(const Mat3<T>& F, const T dN[12], T volume, T mu, T K, Vec3<T> f[4],
                                 ElementLaw<T>& law) {
  const T J = det(F);
  const bool ok = J > T(0);
  if constexpr (Terms::stateful) {
    ElementLaw<T> next = law;
    element_nodal_forces(F, law_pk2<Terms>(F, ok ? J : T(1), mu, K, next), volume, dN, f);
    keep_state_unless_bad(ok, next, law);
  } else {
    element_nodal_forces(F, law_pk2<Terms>(F, ok ? J : T(1), mu, K, law), volume, dN, f);
  }
  zero_unless(ok, f);
  return J;
}

/// Neo-Hookean alone (no law data).
template <class T>
TISSUE_HD T plain_element_forces(const Mat3<T>& F, const T dN[12], T volume, T mu, T K, Vec3<T> f[4]) {
  const T J = det(F);
  const bool ok = J > T(0);
  element_nodal_forces(F, neo_hookean_pk2(F, ok ? J : T(1), mu, K), volume, dN, f);
  zero_unless(ok, f);
  return J;
}

/// The same from the corner displacements u (m).
template <class T>
TISSUE_HD T plain_element_forces(const Vec3<T> u[4], const T dN[12], T volume, T mu, T K, Vec3<T> f[4]) {
  return plain_element_forces(deformation_gradient(u, dN), dN, volume, mu, K, f);
}

/// Per-node integration constants of the damped central difference,
/// u^{n+1} = A (R - f) + B u^n + C u^{n-1}, for lumped mass m (kg), step
/// dt (s) and mass-proportional damping alpha (1/s).
template <class T>
struct CentralDifference {
  T A, B, C;
};

template <class T>
TISSUE_HD CentralDifference<T> central_difference_constants(T m, T dt, T alpha) {
  const T inertia = m / (dt * dt);
  const T damp = alpha * m / (T(2) * dt);
  const T A = T(1) / (inertia + damp);
  return {A, T(2) * inertia * A, (damp - inertia) * A};
}

/// One component of the central-difference update.
template <class T>
TISSUE_HD T central_difference_update(const CentralDifference<T>& k, T residual, T u, T u_prev) {
  return k.A * residual + k.B * u + k.C * u_prev;
}

/// Segment A->B against triangle (P0, P1, P2) (Moller-Trumbore). Returns the
/// fraction t in [0, 1] of |AB| at the hit, or a negative value for a miss
/// (parallel segments miss). Hits on edges and vertices count (closed
/// barycentric test). bary receives the weights of P1 and P2.
template <class T>
TISSUE_HD T segment_triangle(Vec3<T> A, Vec3<T> B, Vec3<T> P0, Vec3<T> P1, Vec3<T> P2, T bary[2]) {
  const Vec3<T> d = B - A, e1 = P1 - P0, e2 = P2 - P0;
  const Vec3<T> p = cross(d, e2);
  const T det_ = dot(e1, p);
  const T scale = norm(e1) * norm(e2) * norm(d);
  if (!(std::fabs(det_) > scale * T(1e-7))) return T(-1);  // parallel or degenerate
  const T inv = T(1) / det_;
  const Vec3<T> s = A - P0;
  const T b1 = dot(s, p) * inv;
  if (b1 < T(0) || b1 > T(1)) return T(-1);
  const Vec3<T> q = cross(s, e1);
  const T b2 = dot(d, q) * inv;
  if (b2 < T(0) || b1 + b2 > T(1)) return T(-1);
  const T t = dot(e2, q) * inv;
  if (t < T(0) || t > T(1)) return T(-1);
  bary[0] = b1;
  bary[1] = b2;
  return t;
}

}  // namespace tissue
