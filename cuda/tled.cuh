// The four IANP passes of DESIGN.md section 2 as per-item device functions
// (one element or one node each), built on the shared __host__ __device__
// math of core/tet.hpp, and the kernels that run them: one kernel per pass
// (plain launches and CUDA graphs, chained with programmatic dependent
// launch) and persistent kernels that run whole steps with a barrier
// between passes. nvcc only.
//
// Model arrays never change while kernels run, so they are read through the
// read-only path (__ldg); state arrays are read with plain loads (the
// persistent kernels read what other blocks wrote before the barrier).
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
  for (int a = 0; a < 4; ++a) c[a] = __ldg(m.elem_nodes + a * ne + e);
#pragma unroll
  for (int k = 0; k < 12; ++k) dN[k] = __ldg(m.dndx + k * ne + e);
#pragma unroll
  for (int a = 0; a < 4; ++a) ue[a] = u[c[a]].vec();
}

/// Pass 1 for element e: J_e = det F, and p_e V_e (p_e = K (J_e - 1)) into
/// the node_elem slots of its four corners.
template <class T>
__device__ void element_pressure_at(const ModelView<T>& m, const StateView<T>& s, const Packed3<T>* u, index_t e) {
  index_t c[4];
  Vec3<T> ue[4];
  T dN[12];
  load_element(m, u, e, c, ue, dN);
  const T J = det(deformation_gradient(ue, dN));
  const T pv = volumetric_pressure(J, __ldg(m.K + e)) * __ldg(m.volume + e);
  s.elem_J[e] = J;
  const index_t ne = m.n_elems;
#pragma unroll
  for (int a = 0; a < 4; ++a) s.pv_slot[__ldg(m.slot_of + a * ne + e)] = pv;
}

/// Pass 2 for node a: p_a = sum_e p_e V_e / sum_e V_e over its elements, in
/// the stored order of node_elem (deterministic; the cpu backend's order).
template <class T>
__device__ void nodal_pressure_at(const ModelView<T>& m, const StateView<T>& s, index_t a) {
  T pv = T(0);
  const index_t end = __ldg(m.node_elem_start + a + 1);
#pragma unroll 8
  for (index_t k = __ldg(m.node_elem_start + a); k < end; ++k) pv += s.pv_slot[k];
  s.node_p[a] = pv / __ldg(m.node_volume + a);
}

/// Pass 3 for element e: pbar = (1/4) sum_a p_a, then IANP forces (or plain
/// tet forces when the model has ianp off) into the node_elem slots of its
/// corners. An element with J <= 0, Jbar <= 0 or a non-finite J is recorded
/// in s.bad (lowest wins; its forces are zero, as core's functions return).
template <class T>
__device__ void element_forces_at(const ModelView<T>& m, const StateView<T>& s, const Packed3<T>* u, index_t e) {
  index_t c[4];
  Vec3<T> ue[4];
  T dN[12];
  load_element(m, u, e, c, ue, dN);
  Vec3<T> f[4];
  T J;
  const T V = __ldg(m.volume + e), mu = __ldg(m.mu + e), K = __ldg(m.K + e);
  if (m.ianp) {
    const T pbar = (s.node_p[c[0]] + s.node_p[c[1]] + s.node_p[c[2]] + s.node_p[c[3]]) / T(4);
    J = ianp_element_forces(ue, dN, V, mu, K, pbar, f);
  } else {
    J = plain_element_forces(ue, dN, V, mu, K, f);
  }
  if (!(J > T(0)) || !isfinite(J)) atomicMin(s.bad, bad_key(e, static_cast<float>(J)));
  const index_t ne = m.n_elems;
#pragma unroll
  for (int a = 0; a < 4; ++a) s.f_slot[__ldg(m.slot_of + a * ne + e)] = Packed3<T>::of(f[a]);
}

/// Pass 4 for node a: f_a = sum of its corners' element forces in the stored
/// order of node_elem (a gather: no atomics), then u_next = u_held for held
/// nodes, else the damped central difference with R = 0.
template <class T>
__device__ void node_update_at(const ModelView<T>& m, const StateView<T>& s, const StepBuffers<T>& b, index_t a) {
  Vec3<T> f = {T(0), T(0), T(0)};
  const index_t end = __ldg(m.node_elem_start + a + 1);
#pragma unroll 8
  for (index_t k = __ldg(m.node_elem_start + a); k < end; ++k) f = f + s.f_slot[k].vec();
  s.f[a] = Packed3<T>::of(f);
  if (s.held[a]) {
    b.u_next[a] = s.u_held[a];
    return;
  }
  const CentralDifference<T> k = {__ldg(m.cd_A + a), __ldg(m.cd_B + a), __ldg(m.cd_C + a)};
  const Packed3<T> u = b.u[a], up = b.u_prev[a];
  b.u_next[a] = {central_difference_update(k, -f.x, u.x, up.x), central_difference_update(k, -f.y, u.y, up.y),
                 central_difference_update(k, -f.z, u.z, up.z), T(0)};
}

// ---- one kernel per pass ------------------------------------------------------
// Each lets the next pass's grid launch at once and then waits for the
// previous grid (programmatic dependent launch: the launch latency overlaps
// the previous pass; both calls are no-ops for a plain launch). Nothing is
// read before the wait, so a predecessor that is not a pass is safe too.

__device__ __forceinline__ void chain_to_previous_pass() {
  cudaTriggerProgrammaticLaunchCompletion();
  cudaGridDependencySynchronize();
}

template <class T>
__global__ void element_pressure_kernel(ModelView<T> m, StateView<T> s, RegionView r, const Packed3<T>* u) {
  chain_to_previous_pass();
  const index_t i = thread_index();
  if (i < r.n_elems) element_pressure_at(m, s, u, r.elem(i));
}

template <class T>
__global__ void nodal_pressure_kernel(ModelView<T> m, StateView<T> s, RegionView r) {
  chain_to_previous_pass();
  const index_t i = thread_index();
  if (i < r.n_nodes) nodal_pressure_at(m, s, r.node(i));
}

template <class T>
__global__ void element_forces_kernel(ModelView<T> m, StateView<T> s, RegionView r, const Packed3<T>* u) {
  chain_to_previous_pass();
  const index_t i = thread_index();
  if (i < r.n_elems) element_forces_at(m, s, u, r.elem(i));
}

template <class T>
__global__ void node_update_kernel(ModelView<T> m, StateView<T> s, RegionView r, StepBuffers<T> b) {
  chain_to_previous_pass();
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

/// Threads per block of the persistent kernels: 1024 in float (a 16-block
/// cluster then covers 16k items, one per thread, for the ~8k-element
/// kidney), 512 in double (its pass 3 needs ~128 registers per thread).
template <class T>
inline constexpr int kPersistentBlock = sizeof(T) == 4 ? 1024 : 512;

template <class T>
__global__ void __launch_bounds__(kPersistentBlock<T>)
    persistent_grid_kernel(ModelView<T> m, StateView<T> s, RegionView r, StepBuffers<T> b, int steps) {
  run_steps(m, s, r, b, steps, GridBarrier{});
}

template <class T>
__global__ void __launch_bounds__(kPersistentBlock<T>)
    persistent_cluster_kernel(ModelView<T> m, StateView<T> s, RegionView r, StepBuffers<T> b, int steps) {
  run_steps(m, s, r, b, steps, ClusterBarrier{});
}

}  // namespace tissue::gpu
