// The four IANP passes of DESIGN.md section 2 as per-item device functions
// (one element or one node each), built on the shared __host__ __device__
// math of core/tet.hpp, and the kernels that run them: one kernel per pass
// (plain launches and CUDA graphs) and persistent kernels that run whole
// steps with a barrier between passes. nvcc only.
#pragma once

#include <cooperative_groups.h>

#include "core/tet.hpp"
#include "cuda/launch.cuh"
#include "cuda/views.hpp"

namespace tissue::gpu {

/// Key of a bad element for atomicMin: the element in the high word (the
/// lowest element wins), its offending J (as float bits) in the low word.
__device__ __forceinline__ unsigned long long bad_key(index_t e, float J) {
  return (static_cast<unsigned long long>(static_cast<unsigned>(e)) << 32) | __float_as_uint(J);
}

/// Corner nodes, corner displacements and shape gradients of element e.
template <class T>
__device__ __forceinline__ void load_element(const ModelView<T>& m, const Packed3<T>* u, index_t e, index_t c[4],
                                             Vec3<T> ue[4], T dN[12]) {
  const index_t ne = m.n_elems;
#pragma unroll
  for (int a = 0; a < 4; ++a) c[a] = m.elem_nodes[a * ne + e];
#pragma unroll
  for (int k = 0; k < 12; ++k) dN[k] = m.dndx[k * ne + e];
#pragma unroll
  for (int a = 0; a < 4; ++a) ue[a] = u[c[a]].vec();
}

/// Pass 1 for element e: J_e = det F and (p_e V_e, V_e), p_e = K (J_e - 1).
template <class T>
__device__ void element_pressure_at(const ModelView<T>& m, const StateView<T>& s, const Packed3<T>* u, index_t e) {
  index_t c[4];
  Vec3<T> ue[4];
  T dN[12];
  load_element(m, u, e, c, ue, dN);
  const T J = det(deformation_gradient(ue, dN));
  const T V = m.volume[e];
  s.elem_J[e] = J;
  s.elem_pv[e] = {volumetric_pressure(J, m.K[e]) * V, V};
}

/// Pass 2 for node a: p_a = sum_e p_e V_e / sum_e V_e over its elements, in
/// the stored order of node_elem (deterministic).
template <class T>
__device__ void nodal_pressure_at(const ModelView<T>& m, const StateView<T>& s, index_t a) {
  T pv = T(0), v = T(0);
  const index_t end = m.node_elem_start[a + 1];
  for (index_t k = m.node_elem_start[a]; k < end; ++k) {
    const PressureVolume<T> q = s.elem_pv[m.node_elem[k] >> 2];
    pv += q.pv;
    v += q.v;
  }
  s.node_p[a] = pv / v;
}

/// Pass 3 for element e: pbar = (1/4) sum_a p_a, then IANP forces (or plain
/// tet forces when the model has ianp off) into elem_f[4 e + a]. An element
/// with J <= 0, Jbar <= 0 or a non-finite J is recorded in s.bad (lowest wins;
/// its forces are zero, as core's element functions return them).
template <class T>
__device__ void element_forces_at(const ModelView<T>& m, const StateView<T>& s, const Packed3<T>* u, index_t e) {
  index_t c[4];
  Vec3<T> ue[4];
  T dN[12];
  load_element(m, u, e, c, ue, dN);
  Vec3<T> f[4];
  T J;
  if (m.ianp) {
    const T pbar = (s.node_p[c[0]] + s.node_p[c[1]] + s.node_p[c[2]] + s.node_p[c[3]]) / T(4);
    J = ianp_element_forces(ue, dN, m.volume[e], m.mu[e], m.K[e], pbar, f);
  } else {
    J = plain_element_forces(ue, dN, m.volume[e], m.mu[e], m.K[e], f);
  }
  if (!(J > T(0)) || !isfinite(J)) atomicMin(s.bad, bad_key(e, static_cast<float>(J)));
#pragma unroll
  for (int a = 0; a < 4; ++a) s.elem_f[4 * e + a] = Packed3<T>::of(f[a]);
}

/// Pass 4 for node a: f_a = sum of its corners' element forces in the stored
/// order of node_elem (gather, no atomics), then u_next = u_held for held
/// nodes, else the damped central difference with R = 0.
template <class T>
__device__ void node_update_at(const ModelView<T>& m, const StateView<T>& s, const StepBuffers<T>& b, index_t a) {
  Vec3<T> f = {T(0), T(0), T(0)};
  const index_t end = m.node_elem_start[a + 1];
  for (index_t k = m.node_elem_start[a]; k < end; ++k) f = f + s.elem_f[m.node_elem[k]].vec();
  s.f[a] = Packed3<T>::of(f);
  if (s.held[a]) {
    b.u_next[a] = s.u_held[a];
    return;
  }
  const CentralDifference<T> k = {m.cd_A[a], m.cd_B[a], m.cd_C[a]};
  const Packed3<T> u = b.u[a], up = b.u_prev[a];
  b.u_next[a] = {central_difference_update(k, -f.x, u.x, up.x), central_difference_update(k, -f.y, u.y, up.y),
                 central_difference_update(k, -f.z, u.z, up.z), T(0)};
}

// ---- one kernel per pass ------------------------------------------------------

template <class T>
__global__ void element_pressure_kernel(ModelView<T> m, StateView<T> s, RegionView r, const Packed3<T>* u) {
  const index_t i = thread_index();
  if (i < r.n_elems) element_pressure_at(m, s, u, r.elem(i));
}

template <class T>
__global__ void nodal_pressure_kernel(ModelView<T> m, StateView<T> s, RegionView r) {
  const index_t i = thread_index();
  if (i < r.n_nodes) nodal_pressure_at(m, s, r.node(i));
}

template <class T>
__global__ void element_forces_kernel(ModelView<T> m, StateView<T> s, RegionView r, const Packed3<T>* u) {
  const index_t i = thread_index();
  if (i < r.n_elems) element_forces_at(m, s, u, r.elem(i));
}

template <class T>
__global__ void node_update_kernel(ModelView<T> m, StateView<T> s, RegionView r, StepBuffers<T> b) {
  const index_t i = thread_index();
  if (i < r.n_nodes) node_update_at(m, s, b, r.node(i));
}

// ---- persistent kernels: whole steps, a barrier between passes ----------------

/// Barrier over a cooperative grid (cudaLaunchCooperativeKernel).
struct GridBarrier {
  __device__ void operator()() const { cooperative_groups::this_grid().sync(); }
};

/// Barrier over one thread-block cluster (the grid is exactly one cluster).
struct ClusterBarrier {
  __device__ void operator()() const { cooperative_groups::this_cluster().sync(); }
};

/// `steps` TLED steps; every pass is a grid-stride loop over the region and
/// the barrier separates passes (and steps). The buffers rotate per step.
template <class T, class Barrier>
__device__ void run_steps(const ModelView<T>& m, const StateView<T>& s, const RegionView& r, StepBuffers<T> b,
                          int steps, Barrier barrier) {
  const index_t first = thread_index(), stride = thread_stride();
  for (int k = 0; k < steps; ++k) {
    for (index_t i = first; i < r.n_elems; i += stride) element_pressure_at(m, s, b.u, r.elem(i));
    barrier();
    for (index_t i = first; i < r.n_nodes; i += stride) nodal_pressure_at(m, s, r.node(i));
    barrier();
    for (index_t i = first; i < r.n_elems; i += stride) element_forces_at(m, s, b.u, r.elem(i));
    barrier();
    for (index_t i = first; i < r.n_nodes; i += stride) node_update_at(m, s, b, r.node(i));
    b = b.rotated();
    if (k + 1 < steps) barrier();
  }
}

/// Threads per block of the persistent kernels.
inline constexpr int kPersistentBlock = 512;

template <class T>
__global__ void __launch_bounds__(kPersistentBlock) persistent_grid_kernel(ModelView<T> m, StateView<T> s,
                                                                            RegionView r, StepBuffers<T> b,
                                                                            int steps) {
  run_steps(m, s, r, b, steps, GridBarrier{});
}

template <class T>
__global__ void __launch_bounds__(kPersistentBlock) persistent_cluster_kernel(ModelView<T> m, StateView<T> s,
                                                                               RegionView r, StepBuffers<T> b,
                                                                               int steps) {
  run_steps(m, s, r, b, steps, ClusterBarrier{});
}

}  // namespace tissue::gpu
