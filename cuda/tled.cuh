// The four IANP passes of docs/design.md section 2 as per-item device functions
// (one element, or one lane of a node's group), built on the shared
// __host__ __device__ math of core/tet.hpp, and the kernels that run them:
// one kernel per pass (plain launches and CUDA graphs, chained with
// programmatic dependent launch) and persistent kernels that run whole steps
// with a barrier between passes. nvcc only.
//
// Each item is split in two: what it reads from the model (which never
// changes while kernels run: read through the read-only path, __ldg) and
// what it does with the state. A chained pass kernel loads its model part
// before waiting for the previous pass, so that round trip overlaps the
// previous kernel's tail. State arrays are read with coherent loads, plain
// or evict-first (`__ldcs`), never through the read-only path (the
// persistent kernels read what other blocks wrote before the barrier).
#pragma once

#include <cooperative_groups.h>

#include <algorithm>
#include <atomic>
#include <cstdint>
#include <type_traits>
#include <utility>

#include "core/node_rules.hpp"
#include "core/tet.hpp"
#include "cuda/contact.cuh"
#include "cuda/launch.cuh"
#include "cuda/views.hpp"

namespace tissue::gpu {

/// Key of a bad element for atomicMin: the element in the high word (the
/// lowest element wins), its offending J (as float bits) in the low word.
__device__ __forceinline__ unsigned long long bad_key(index_t e, float J) {
  return (static_cast<unsigned long long>(static_cast<unsigned>(e)) << 32) | __float_as_uint(J);
}

/// Records element e in *bad when its pass-3 J is not positive or not
/// finite (once per element; the lowest element wins).
template <class T>
__device__ __forceinline__ void record_if_bad(unsigned long long* bad, index_t e, T J) {
  if (!(J > T(0)) || !isfinite(J)) atomicMin(bad, bad_key(e, static_cast<float>(J)));
}

/// The model data of one element that passes 1 and 3 use; its gradients
/// and volume loaded or (kRecomputed) recomputed (ModelView::dndx).
template <class T>
struct ElementData {
  index_t e;
  index_t c[4];     ///< corner nodes
  index_t slot[4];  ///< node_elem slots of its corners (pass 3's: its forces go to its nodes' slots)
  T dN[12];         ///< shape gradients (1/m)
  T V, mu, K;       ///< m^3, Pa, Pa
};

/// An element's corners, gradients and volume; its slots, mu and K left
/// unset. Each pass loads only what it uses: the compiler keeps loads
/// through the read-only path even when their values go unused.
template <class T, bool kRecomputed>
__device__ __forceinline__ ElementData<T> load_element_shape(const ModelView<T>& m, index_t e) {
  ElementData<T> d;
  const index_t ne = m.n_elems;
  d.e = e;
#pragma unroll
  for (int a = 0; a < 4; ++a) d.c[a] = __ldg(m.elem_nodes + a * ne + e);
  if constexpr (!kRecomputed) {
#pragma unroll
    for (int k = 0; k < 12; ++k) d.dN[k] = __ldg(m.dndx + k * ne + e);
    d.V = __ldg(m.volume + e);
  } else if constexpr (sizeof(T) == 4) {  // from the corners' grid points: 4 gathered 16-byte nodes
    GridPoint q[4];
#pragma unroll
    for (int a = 0; a < 4; ++a) {
      const int4 v = __ldg(reinterpret_cast<const int4*>(m.X_ref + d.c[a]));
      q[a] = {v.x, v.y, v.z, 0};
    }
    d.V = tet_shape_gradients_on_grid<T>(q, m.grid_step, d.dN);
  } else {  // from the corners' reference positions: 4 gathered nodes instead of 13 element scalars
    Vec3<double> X[4];
#pragma unroll
    for (int a = 0; a < 4; ++a) {
      const double2 xy = __ldg(reinterpret_cast<const double2*>(m.X_ref + d.c[a]));
      X[a] = {xy.x, xy.y, __ldg(&m.X_ref[d.c[a]].z)};
    }
    d.V = tet_shape_gradients_from<T>(X, d.dN);
  }
  return d;
}

/// Loads element d.e's corners' slots into d.
template <class T>
__device__ __forceinline__ void load_slots(const ModelView<T>& m, ElementData<T>& d) {
#pragma unroll
  for (int a = 0; a < 4; ++a) d.slot[a] = __ldg(m.slot_of + a * m.n_elems + d.e);
}

/// The shape and the moduli, no slots: the fused force pass's (packed_forces_kernel)
/// and the reduction's (pass 1 needs the shape only: load_element_shape).
template <class T, bool kRecomputed>
__device__ __forceinline__ ElementData<T> load_element_moduli(const ModelView<T>& m, index_t e) {
  ElementData<T> d = load_element_shape<T, kRecomputed>(m, e);
  d.mu = __ldg(m.mu + e);
  d.K = __ldg(m.K + e);
  return d;
}

/// All of it: pass 3's.
template <class T, bool kRecomputed>
__device__ __forceinline__ ElementData<T> load_element(const ModelView<T>& m, index_t e) {
  ElementData<T> d = load_element_moduli<T, kRecomputed>(m, e);
  load_slots(m, d);
  return d;
}

/// Calls f(std::true_type) when the element passes over region r
/// recompute the gradients (recomputes()), else f(std::false_type): the
/// host's choice of the kernels' kRecomputed. Two instantiations rather
/// than a branch in the kernel: with the branch the kidney's latency-bound
/// steps ran 7 % slower (float) and 17 % (double) even on the stored path.
template <class T, class F>
decltype(auto) with_gradients(const ModelView<T>& m, const RegionView& r, F&& f) {
  if (recomputes(m, r)) return f(std::true_type{});
  return f(std::false_type{});
}

/// Calls f(std::true_type) when flag holds, else f(std::false_type): a
/// run-time choice made a kernel's template argument.
template <class F>
decltype(auto) with_flag(bool flag, F&& f) {
  if (flag) return f(std::true_type{});
  return f(std::false_type{});
}

template <class T>
__device__ __forceinline__ void corner_displacements(const ElementData<T>& d, const Packed3<T>* u, Vec3<T> ue[4]) {
#pragma unroll
  for (int a = 0; a < 4; ++a) ue[a] = u[d.c[a]].vec();
}

/// Pass 1 for an element: J_e = det F, and its volume change (J_e - 1) V_e
/// (stored once per element, elem_dv: element_pressure_at).
template <class T>
__device__ __forceinline__ T element_volume_change(const ElementData<T>& d, const Packed3<T>* u, T& J) {
  Vec3<T> ue[4];
  corner_displacements(d, u, ue);
  J = det(deformation_gradient(ue, d.dN));
  return (J - T(1)) * d.V;
}

template <class T>
__device__ void element_pressure_at(const StateView<T>& s, const ElementData<T>& d, const Packed3<T>* u) {
  T J;
  const T dv = element_volume_change(d, u, J);
  s.elem_J[d.e] = J;
  s.elem_dv[d.e] = dv;
}

/// An element's optional law terms (core/material.hpp): its fibre and, for a
/// viscoelastic element (slot >= 0), its Prony constants and state. Absent
/// terms keep ElementLaw's neutral values (eta = 0, gain = 0).
/// Element e's fibre direction and stiffness from LawView::fibre (4 x ne).
template <class T>
__device__ __forceinline__ void load_fibre(const T* fibre, index_t ne, index_t e, ElementLaw<T>& law) {
  law.a = {__ldg(fibre + e), __ldg(fibre + ne + e), __ldg(fibre + 2 * ne + e)};
  law.eta = __ldg(fibre + 3 * ne + e);
}

template <class T>
__device__ __forceinline__ index_t load_law(const ModelView<T>& m, const LawView<T>& w, index_t e,
                                            ElementLaw<T>& law) {
  if (w.fibre) load_fibre(w.fibre, m.n_elems, e, law);
  const index_t v = w.visco_slot ? __ldg(w.visco_slot + e) : index_t(-1);
  if (v >= 0) {
    const index_t nv = w.n_visco;
#pragma unroll
    for (int i = 0; i < kMaxProny; ++i) {
      if (i >= w.n_prony) break;  // the rest stay neutral (decay = gain = q = 0): no loads
      law.decay[i] = __ldg(w.prony_decay + i * nv + v);
      law.gain[i] = __ldg(w.prony_gain + i * nv + v);
#pragma unroll
      for (int c = 0; c < kSymComponents; ++c) law.q[i][c] = w.visco_q[(kSymComponents * i + c) * nv + v];
    }
  }
  return v;
}

/// Pass 3's stress and forces for a scene with law terms beyond
/// Neo-Hookean: one instantiation with every term (neutral where an
/// element's set lacks it), out of line so that the Neo-Hookean path keeps
/// its registers. Returns J as the Neo-Hookean path does.
template <class T>
__device__ __forceinline__ T law_element_forces(const ModelView<T>& m, const LawView<T>& w, const ElementData<T>& d,
                                                const Vec3<T> ue[4], bool ianp, T pbar, Vec3<T> f[4]) {
  using All = AllLawTerms;
  ElementLaw<T> law;
  const index_t v = load_law(m, w, d.e, law);
  const Mat3<T> F = deformation_gradient(ue, d.dN);
  const T J = ianp ? ianp_element_forces<All>(F, d.dN, d.V, d.mu, d.K, pbar, f, law)
                   : plain_element_forces<All>(F, d.dN, d.V, d.mu, d.K, f, law);
  if (v >= 0) {
    const index_t nv = w.n_visco;
#pragma unroll
    for (int i = 0; i < kMaxProny; ++i) {
      if (i >= w.n_prony) break;
#pragma unroll
      for (int c = 0; c < kSymComponents; ++c) w.visco_q[(kSymComponents * i + c) * nv + v] = law.q[i][c];
    }
  }
  return J;
}

/// What pass 3 computes for an element (element_forces_of) before it
/// stores it (store_element_forces).
template <class T>
struct ElementForces {
  Vec3<T> f[4];
  T J;
};

template <class T>
__device__ __forceinline__ ElementForces<T> element_forces_of(const StateView<T>& s, const ElementData<T>& d,
                                                              const Packed3<T>* u, bool ianp) {
  Vec3<T> ue[4];
  corner_displacements(d, u, ue);
  ElementForces<T> out;
  if (ianp) {
    const T pbar = (s.node_p[d.c[0]] + s.node_p[d.c[1]] + s.node_p[d.c[2]] + s.node_p[d.c[3]]) / T(4);
    out.J = ianp_element_forces(ue, d.dN, d.V, d.mu, d.K, pbar, out.f);
  } else {
    out.J = plain_element_forces(ue, d.dN, d.V, d.mu, d.K, out.f);
  }
  return out;
}

template <class T>
__device__ __forceinline__ void store_element_forces(const StateView<T>& s, const ElementData<T>& d,
                                                     const ElementForces<T>& out) {
  record_if_bad(s.bad, d.e, out.J);
#pragma unroll
  for (int a = 0; a < 4; ++a) s.f_slot[d.slot[a]] = Packed3<T>::of(out.f[a]);
}

/// Pass 3 for an element: pbar = (1/4) sum_a p_a, then IANP forces (or plain
/// tet forces when the model has ianp off) into the node_elem slots of its
/// corners. An element with J <= 0, Jbar <= 0 or a non-finite J is recorded
/// in s.bad (lowest wins; its forces are zero, as core's functions return).
/// Neo-Hookean: the kernels of a model without law terms run exactly this.
template <class T>
__device__ void element_forces_at(const StateView<T>& s, const ElementData<T>& d, const Packed3<T>* u, bool ianp) {
  store_element_forces(s, d, element_forces_of(s, d, u, ianp));
}

/// The same with the law terms of core/material.hpp (a model that has any).
template <class T>
__device__ void law_element_forces_at(const ModelView<T>& m, const StateView<T>& s, const ElementData<T>& d,
                                      const Packed3<T>* u, const LawView<T>& w) {
  Vec3<T> ue[4];
  corner_displacements(d, u, ue);
  Vec3<T> f[4];
  const T pbar =
      m.ianp ? (s.node_p[d.c[0]] + s.node_p[d.c[1]] + s.node_p[d.c[2]] + s.node_p[d.c[3]]) / T(4) : T(0);
  const T J = law_element_forces(m, w, d, ue, m.ianp, pbar, f);
  record_if_bad(s.bad, d.e, J);
#pragma unroll
  for (int a = 0; a < 4; ++a) s.f_slot[d.slot[a]] = Packed3<T>::of(f[a]);
}

// kNodeLanes (the lanes that share one node in passes 2 and 4): cuda/views.hpp

/// Mask of the calling thread's node group (kNodeLanes / L threads) in its warp.
template <int L>
__device__ __forceinline__ unsigned lanes_group_mask() {
  constexpr int P = kNodeLanes / L;
  return ((1u << P) - 1) << ((threadIdx.x & 31) & ~(P - 1));
}

/// Mask of the calling lane's node group within its warp (one lane a thread).
__device__ __forceinline__ unsigned node_group_mask() { return lanes_group_mask<1>(); }

/// Total of the group's partial sums x, in a fixed pairwise order (lanes
/// j, j^1, then pairs j, j^2, ...): every lane gets the same, deterministic
/// value (a + b == b + a exactly). Differs from a sequential sum by rounding.
template <class T>
__device__ __forceinline__ T node_group_sum(T x, unsigned mask) {
#pragma unroll
  for (int o = 1; o < kNodeLanes; o <<= 1) x += __shfl_xor_sync(mask, x, o);
  return x;
}
/// node_group_sum of each component.
template <class T>
__device__ __forceinline__ Vec3<T> node_group_sum(Vec3<T> x, unsigned mask) {
  return {node_group_sum(x.x, mask), node_group_sum(x.y, mask), node_group_sum(x.z, mask)};
}

/// node_group_sum of the lanes' partial sums, acc[i] being lane p + i P's
/// (thread p of P = kNodeLanes / L): the pairs (v, v^1), (v, v^2), ... of
/// node_group_sum, by shuffles while the partner is another thread's lane
/// (o < P), then within the thread (the partner of acc[i] is acc[i ^ o / P]).
template <int L, class T>
__device__ __forceinline__ T lane_group_sums(T (&acc)[L], unsigned mask) {
  constexpr int P = kNodeLanes / L;
#pragma unroll
  for (int o = 1; o < P; o <<= 1)
#pragma unroll
    for (int i = 0; i < L; ++i) acc[i] += __shfl_xor_sync(mask, acc[i], o);
#pragma unroll
  for (int h = 1; h < L; h <<= 1)
#pragma unroll
    for (int i = 0; i < L; i += 2 * h) acc[i] += acc[i + h];
  return acc[0];
}

/// The model data of one node that passes 2 and 4 use (one lane's view).
template <class T>
struct NodeData {
  index_t a;
  index_t first, end;  ///< this lane's first slot, the node's end slot
  int lane;
  unsigned mask;
};

template <class T>
__device__ __forceinline__ NodeData<T> load_node(const ModelView<T>& m, index_t a, int lane, unsigned mask) {
  return {a, __ldg(m.node_elem_start + a) + lane, __ldg(m.node_elem_start + a + 1), lane, mask};
}

/// How many of a lane's elements pass 2 loads with its node, before the
/// wait for pass 1 (a box's nodes touch up to 24 elements: three a lane);
/// a lane's further elements are loaded after it.
inline constexpr int kPressureElements = 4;

/// The model data of one node that pass 2 uses (one lane's view): the
/// node's, and the elements of the lane's first kPressureElements slots.
template <class T>
struct PressureNode {
  NodeData<T> d;
  index_t e[kPressureElements];  ///< element of slot d.first + j kNodeLanes (0 past the node's end)
};

template <class T>
__device__ __forceinline__ PressureNode<T> load_pressure_node(const ModelView<T>& m, index_t a, int lane,
                                                              unsigned mask) {
  PressureNode<T> n{load_node(m, a, lane, mask), {}};
#pragma unroll
  for (int j = 0; j < kPressureElements; ++j) {
    const index_t k = n.d.first + j * kNodeLanes;
    n.e[j] = k < n.d.end ? incident_element(__ldg(m.node_elem + k)) : index_t(0);
  }
  return n;
}

/// Pass 2 for a node (one lane of its group): p_a = K_a sum_e (J_e - 1) V_e /
/// sum_e V_e over its elements (node_divisor = V_a / K_a), gathered from
/// pass 1's per-element values; lane 0 writes it.
template <class T>
__device__ void nodal_pressure_at(const ModelView<T>& m, const StateView<T>& s, const PressureNode<T>& n) {
  const NodeData<T>& d = n.d;
  T dv = T(0);
#pragma unroll
  for (int j = 0; j < kPressureElements; ++j)
    if (d.first + j * kNodeLanes < d.end) dv += s.elem_dv[n.e[j]];
  for (index_t k = d.first + kPressureElements * kNodeLanes; k < d.end; k += kNodeLanes)
    dv += s.elem_dv[incident_element(__ldg(m.node_elem + k))];
  dv = node_group_sum(dv, d.mask);
  if (d.lane == 0) s.node_p[d.a] = dv / __ldg(m.node_divisor + d.a);
}

/// Passes 1 and 2 as one kernel (packed_pressures_kernel) on regions of
/// fewer than this many elements: each slot's thread computes the volume
/// change of its element itself, every element once per corner, instead of
/// reading the values pass 1 wrote (elem_dv). It saves a dependent kernel
/// per step where the steps are bound by their kernels' latency and costs
/// four times pass 1's scattered loads: 100k and 1M tets lost 26-52 % fused
/// and keep the two passes (docs/cuda.md, "Passes 1 and 2 as one kernel").
inline constexpr index_t kFusedPressuresMaxElements = 10000;

/// Whether the steps over region r run passes 1 and 2 as one kernel: a
/// small region whose nodes the packed windows hold (RegionView::n_packs).
__host__ __device__ inline bool fuses_pressures(const RegionView& r) {
  return r.n_packs > 0 && r.n_elems < kFusedPressuresMaxElements;
}

/// One slot of a node in a fused pass (run_packed): its element's model
/// data, whether the region computes that element (the element pass would
/// write its value now: its force slot, its elem_dv; else the stored value
/// stays), and which of the element's corners the node is (corner 0's
/// visit does what the element pass does once: elem_dv and J_e, the
/// bad-element flag).
template <class T>
struct SlotElement {
  ElementData<T> d;
  bool computed;
  int corner;
};

/// Model and region data only (the region's element mask is written by its
/// build, before any pass runs): loaded before the wait.
/// kModuli: with mu and K (the force pass's), else the shape only.
template <class T, bool kRecomputed, bool kModuli = false>
__device__ __forceinline__ SlotElement<T> load_slot_element(const ModelView<T>& m, const RegionView& r, index_t k) {
  const index_t ec = __ldg(m.node_elem + k);
  const index_t e = incident_element(ec);
  ElementData<T> d;
  if constexpr (kModuli)
    d = load_element_moduli<T, kRecomputed>(m, e);
  else
    d = load_element_shape<T, kRecomputed>(m, e);
  return {d, !r.elem_sel || __ldg(r.elem_sel + e) != 0, incident_corner(ec)};
}

/// What the end of pass 4 reads of node a besides its forces: the applied
/// load (kLoad), the held mask and targets, the central difference's
/// constants and displacements. Pass 4 loads them with the node; the fused
/// force pass right after its wait, so that their round trip overlaps the
/// slots' arithmetic instead of following the node's sum.
/// Float's carried bits (core node_next's carry) ride in the spare fourth
/// lane of the displacement they belong to, so that they cost no memory
/// traffic: each component as a multiple of 1/1024 of the spacing of u at
/// that component, 10 bits signed, the three in bits 0-29 (bit 30 clear:
/// never an Inf or NaN pattern). |carry| is at most half a spacing, so
/// nothing saturates; the quantum drops at most 1/2048 of a spacing a step.
/// A lane written by anything else (Packed3::of, a set displacement, a
/// contact's correction) is 0: no carry.
__device__ __forceinline__ float spacing_of(float v) {
  const int e = __float_as_int(v) & 0x7f800000;
  return e > (23 << 23) ? __int_as_float(e - (23 << 23)) : 0.0f;  // 2^(exponent - 23); 0 below 2^-103
}

__device__ __forceinline__ float pack_carry(Vec3<float> u, Vec3<float> carry) {
  unsigned bits = 0;
#pragma unroll
  for (int c = 0; c < 3; ++c) {
    const float s = spacing_of(u[c]);
    const int q = s > 0.0f ? min(max(__float2int_rn(carry[c] * (1024.0f / s)), -511), 511) : 0;
    bits |= (unsigned(q) & 0x3ffu) << (10 * c);
  }
  return __uint_as_float(bits);
}

__device__ __forceinline__ Vec3<float> unpack_carry(Vec3<float> u, float w) {
  const unsigned bits = __float_as_uint(w);
  Vec3<float> carry;
#pragma unroll
  for (int c = 0; c < 3; ++c) {
    const int q = int(bits >> (10 * c) & 0x3ffu);
    carry[c] = float(q >= 512 ? q - 1024 : q) * (spacing_of(u[c]) * (1.0f / 1024.0f));
  }
  return carry;
}

template <class T>
struct NodeTail {
  Vec3<T> load, u_held, u, u_prev, carry;  // carry: float's compensation (core node_next), 0 in double
  CentralDifference<T> cd;
  std::uint8_t held;
};

template <class T, bool kLoad>
__device__ __forceinline__ NodeTail<T> load_node_tail(const ModelView<T>& m, const StateView<T>& s,
                                                      const StepBuffers<T>& b, index_t a) {
  NodeTail<T> t;
  if constexpr (kLoad) t.load = s.load[a].vec();
  t.held = s.held[a];
  t.u_held = s.u_held[a].vec();
  t.cd = {__ldg(m.cd_A + a), __ldg(m.cd_B + a), __ldg(m.cd_C + a)};
  const Packed3<T> u = b.u[a];
  t.u = u.vec();
  t.u_prev = b.u_prev[a].vec();
  if constexpr (std::is_same_v<T, float>)
    t.carry = unpack_carry(t.u, u.w);
  else
    t.carry = {T(0), T(0), T(0)};
  return t;
}

/// The end of pass 4 for node a, on one lane, once its element forces are
/// summed into f: the applied load subtracted, f stored, u_next set.
template <class T, bool kLoad>
__device__ __forceinline__ void node_update_with(const StateView<T>& s, const StepBuffers<T>& b, index_t a,
                                                 Vec3<T> f, const NodeTail<T>& t) {
  if constexpr (kLoad) f = f - t.load;
  s.f[a] = Packed3<T>::of(f);
  Vec3<T> carry = t.carry;
  Packed3<T> next = Packed3<T>::of(node_next(t.held, t.u_held, t.cd, f, t.u, t.u_prev, carry));
  if constexpr (std::is_same_v<T, float>) next.w = pack_carry(next.vec(), carry);
  b.u_next[a] = next;
}

template <class T, bool kLoad>
__device__ __forceinline__ void node_update_from(const ModelView<T>& m, const StateView<T>& s,
                                                 const StepBuffers<T>& b, index_t a, Vec3<T> f) {
  node_update_with<T, kLoad>(s, b, a, f, load_node_tail<T, kLoad>(m, s, b, a));
}

/// A force slot as pass 4 reads it, its last use in the step: evict-first
/// (`__ldcs`), so that the slots pass 4 has read leave the L2 before those
/// pass 3 wrote last, which pass 4 has yet to read (on 1M tets the 64 MB
/// of slots exceed an H100's 50 MB of L2: 1M float +1.6 %, docs/cuda.md,
/// "Passes in the order the L2 holds").
__device__ __forceinline__ Vec3<float> last_read(const Packed3<float>* p) {
  const float4 v = __ldcs(reinterpret_cast<const float4*>(p));
  return {v.x, v.y, v.z};
}
__device__ __forceinline__ Vec3<double> last_read(const Packed3<double>* p) {
  const double2 xy = __ldcs(reinterpret_cast<const double2*>(p));
  return {xy.x, xy.y, __ldcs(&p->z)};
}

/// Pass 4 for a node, L of its lanes on the calling thread (d: its first,
/// lane p; the others p + l P, P = kNodeLanes / L; L = 1: one lane,
/// kNodeLanes threads a node): f_a = sum of its corners' element forces (a
/// gather: no atomics) minus the applied load R (none when s.load is null),
/// then lane 0 sets u_next: u_held for the held components (axis mask), the
/// damped central difference for the others. Each lane sums its slots in
/// order, then lane_group_sums: the same bits for every L. kLoad: the
/// instantiation for a scene with loads (chosen at launch, so that a scene
/// without pays nothing).
template <class T, bool kLoad, int L>
__device__ void node_update_lanes_at(const ModelView<T>& m, const StateView<T>& s, const StepBuffers<T>& b,
                                     const NodeData<T>& d) {
  constexpr int P = kNodeLanes / L;
  T f[3][L];
#pragma unroll
  for (int l = 0; l < L; ++l) f[0][l] = f[1][l] = f[2][l] = T(0);
#pragma unroll 4
  for (index_t k = d.first; k < d.end; k += kNodeLanes)
#pragma unroll
    for (int l = 0; l < L; ++l)
      if (k + l * P < d.end) {
        const Vec3<T> v = last_read(s.f_slot + k + l * P);
        f[0][l] += v.x, f[1][l] += v.y, f[2][l] += v.z;
      }
  const Vec3<T> sum = {lane_group_sums<L>(f[0], d.mask), lane_group_sums<L>(f[1], d.mask),
                       lane_group_sums<L>(f[2], d.mask)};
  if (d.lane == 0) node_update_from<T, kLoad>(m, s, b, d.a, sum);
}

/// Pass 4 for a node on one lane of its group (node_update_lanes_at, L = 1).
template <class T, bool kLoad>
__device__ void node_update_at(const ModelView<T>& m, const StateView<T>& s, const StepBuffers<T>& b,
                               const NodeData<T>& d) {
  node_update_lanes_at<T, kLoad, 1>(m, s, b, d);
}

/// Blocks of the packed force kernel an SM must hold: six in float (at
/// most 80 registers a thread; 74-78 compiled, with the node's tail held
/// through the slots' arithmetic), four in double (at most 128; 124-128
/// compiled): on the kidney's whole mesh (512 windows) every block runs in
/// the first wave on an H100's or H200's 132 SMs. Eight in float (64
/// registers) spilled the tail: kidney whole mesh 182.6k steps/s against
/// 198.3k at six (docs/cuda.md, "The node's tail loaded beside the slots").
template <class T>
inline constexpr int kPackedForceMinBlocks = sizeof(T) == 4 ? 6 : 4;

/// Corner a's force of an element (a select, not an index: no local memory).
template <class T>
__device__ __forceinline__ Vec3<T> corner_force(const ElementForces<T>& out, int a) {
  return a == 0 ? out.f[0] : (a == 1 ? out.f[1] : (a == 2 ? out.f[2] : out.f[3]));
}

// ---- one kernel per pass ------------------------------------------------------
// Each lets the next pass's grid launch at once, loads its model data (and
// the region's lists, written before any pass ran), then waits for the
// previous grid (programmatic dependent launch; both calls are no-ops for a
// plain launch) before it touches the state, and does nothing in a tick
// whose region must grow first (StateView::skip). The element passes' blocks
// past the launch's first wave may wait first instead (run_element_pass).

/// A thread of a chained element pass (passes 1 and 3): load() reads its
/// element's model part, which no pass writes, and step(d) the state, then
/// computes and stores. A block of the launch's first wave (blockIdx below
/// first_wave: the blocks the device holds at once, launch_element_pass) loads
/// before its wait, so that those loads overlap the previous pass's tail. A
/// later block is scheduled only as earlier ones end, when the previous pass
/// has almost always ended too; it waits first and then issues its model and
/// state loads together, one round trip to memory fewer before its
/// arithmetic with recomputed gradients (the element's corners, then their
/// reference positions; stored gradients are indexed by the element and load
/// with the corners, so there the late path saves nothing). Both orders
/// compute the same values: only where the wait falls differs. On 1M tets
/// in float pass 3 runs about 7 waves on an H200, while 100k tets fit in one
/// (docs/cuda.md, "Later waves load after their wait"). kLate false: every
/// block loads before its wait (first_wave unused), and the late path is
/// not compiled.
template <bool kLate, class T, class Load, class Step>
__device__ __forceinline__ void run_element_pass(const StateView<T>& s, bool active, index_t first_wave,
                                                 const Load& load, const Step& step) {
  let_next_pass_launch();
  if constexpr (kLate) {
    if (index_t(blockIdx.x) >= first_wave) {
      wait_for_previous_pass();
      if (skipped(s)) return;
      if (active) step(load());
      return;
    }
  }
  decltype(load()) d;
  if (active) d = load();
  wait_for_previous_pass();
  if (skipped(s)) return;
  if (active) step(d);
}

/// Whether passes 1 and 3 let their later blocks load after their wait
/// (run_element_pass). In float 1M tets ran 1.3 % faster on an H200 (and
/// 100k, whose blocks all fit in the first wave, 3 %: the kernels' code
/// changed with the late path; not profiled). In double the late path's
/// registers cost pass 1 a block an SM (64 -> 70 registers with recomputed
/// gradients) and 100k ran up to 2.6 % slower, so double keeps every block
/// loading first, except in pass 3's streaming and law kernels
/// (docs/cuda.md, "Later waves load after their wait").
template <class T>
inline constexpr bool kLateLoads = sizeof(T) == 4;

template <class T, bool kRecomputed>
__global__ void element_pressure_kernel(ModelView<T> m, StateView<T> s, RegionView r, const Packed3<T>* u,
                                        index_t first_wave) {
  if (const std::int64_t d = slots_moved(s.slots)) {  // a group's launch: this block row's scene
    m = m.materials_moved(d * s.slots.stride);
    u = s.slot_moved(u, d);
    s = s.moved(d);
  }
  const index_t i = thread_index();
  run_element_pass<kLateLoads<T>>(
      s, i < r.n_elems, first_wave, [&] { return load_element_shape<T, kRecomputed>(m, r.elem(i)); },
      [&](const ElementData<T>& d) { element_pressure_at(s, d, u); });
}

/// Threads per block of pass 3 (and the law kernel) and of pass 1 where
/// their launch in blocks of kBlock runs in more than one wave
/// (launch_element_pass). Pass 3 in float takes 54-56 registers a thread: an SM
/// holds 36 of its warps, but only four blocks of 256 (32 warps), nine of
/// 128 or eighteen of 64 (36). Smaller blocks also free their slot when
/// their own few warps end, not the slowest of eight. On an H200, 1M tets
/// in float ran 3.9 % faster with pass 3 in blocks of 64 and pass 1 in
/// blocks of 128; pass 1 in blocks of 64 lost. 100k tets, whose launches fit one
/// wave in float, ran 2-8 % slower in smaller blocks, so they keep blocks of
/// 256 (docs/cuda.md, "Element passes of several waves in smaller blocks").
inline constexpr int kPass3WaveBlock = 64;
inline constexpr int kPass1WaveBlock = 128;
static_assert(kPass3WaveBlock % 32 == 0 && kPass1WaveBlock % 32 == 0, "whole warps");

/// Blocks of `kernel` that the current device holds at once in blocks of
/// kBlock and of kWaveBlock threads (resident_blocks), computed once per
/// kernel and device.
template <auto kKernel, int kWaveBlock>
std::pair<index_t, index_t> element_waves() {
  auto query = [] {
    return std::pair<index_t, index_t>{std::max<index_t>(1, resident_blocks(kKernel, kBlock)),
                                       std::max<index_t>(1, resident_blocks(kKernel, kWaveBlock))};
  };
  constexpr int kDevices = 64;
  static std::atomic<index_t> cache[kDevices][2] = {};
  int dev = 0;
  CUDA_CHECK(cudaGetDevice(&dev));
  if (dev >= kDevices) return query();
  std::pair<index_t, index_t> w{cache[dev][0].load(std::memory_order_relaxed),
                                cache[dev][1].load(std::memory_order_relaxed)};
  if (w.first == 0 || w.second == 0) {
    w = query();
    cache[dev][0].store(w.first, std::memory_order_relaxed);
    cache[dev][1].store(w.second, std::memory_order_relaxed);
  }
  return w;
}

/// Queues `kernel` over region r's n elements: in blocks of kBlock where
/// they fit in one wave, else of kWaveBlock (always, where
/// small_element_blocks_forced: tests; kWaveBlock == kBlock, for a kernel
/// compiled under launch bounds of kBlock: never), its first wave in those
/// blocks (at most element_first_wave_cap where set: tests; 0 where kLate
/// is false, unused) as the last argument. A launch in the smaller blocks
/// is counted in small_element_block_launches (pressures: pass 1, else
/// pass 3 or the law kernel).
template <auto kKernel, int kWaveBlock, bool kLate, class... Args>
void launch_element_pass(bool pressures, index_t n, cudaStream_t stream, Args... args) {
  const auto [wave, small_wave] = element_waves<kKernel, kWaveBlock>();
  // (a group's launch runs every scene's elements: launch_scenes block rows)
  const bool small = small_element_blocks_forced.load(std::memory_order_relaxed) ||
                     index_t(grid_for(n, kBlock)) * launch_scenes > wave;
  const int block = small ? kWaveBlock : kBlock;
  index_t first_wave = 0;
  if constexpr (kLate) {
    const index_t cap = element_first_wave_cap.load(std::memory_order_relaxed);
    first_wave = small ? small_wave : wave;
    if (cap >= 0) first_wave = std::min(first_wave, cap);
  }
  launch_chained_in(block, n, stream, kKernel, args..., first_wave);
  if (n > 0 && block != kBlock) {
    auto& c = pressures ? small_element_block_launches.pressures : small_element_block_launches.forces;
    c.fetch_add(1, std::memory_order_relaxed);
  }
}

/// Pass 1 over region r, one thread an element, chained.
template <class T, bool kRecomputed>
void enqueue_element_pressures(const ModelView<T>& m, const StateView<T>& s, const RegionView& r, const Packed3<T>* u,
                               cudaStream_t stream) {
  constexpr bool kLate = kLateLoads<T>;
  launch_element_pass<element_pressure_kernel<T, kRecomputed>, kPass1WaveBlock, kLate>(true, r.n_elems, stream, m, s, r,
                                                                                       u);
}

/// Node kernels run kNodeLanes threads per node (launch kNodeLanes * n);
/// whole groups are active or not.
template <class T>
__global__ void nodal_pressure_kernel(ModelView<T> m, StateView<T> s, RegionView r) {
  if (const std::int64_t d = slots_moved(s.slots)) {  // a group's launch: this block row's scene
    m = m.materials_moved(d * s.slots.stride);
    s = s.moved(d);
  }
  let_next_pass_launch();
  const index_t g = thread_index(), i = g / kNodeLanes;
  const bool active = i < r.n_nodes;
  PressureNode<T> d;
  if (active) d = load_pressure_node(m, r.node(i), g % kNodeLanes, node_group_mask());
  wait_for_previous_pass();
  if (skipped(s)) return;
  if (active) nodal_pressure_at(m, s, d);
}

// ---- node passes, several of a node's lanes a thread ------------------------------

/// The chained node kernels of a large region (nodal_pressure_lanes_kernel,
/// node_update_kernel with L = kThreadLanes) run kNodeLanes / L threads per
/// node, each taking L of the node's kNodeLanes lanes (lanes p, p + P, p +
/// 2P, ... for P = kNodeLanes / L threads): a thread has L times the loads
/// in flight and the pass needs L times fewer threads. Each lane's sum runs
/// in its own order and the lanes' sums are added in node_group_sum's pairs
/// (lane_group_sums), so the bits are those of kNodeLanes threads a node.
/// The steps run L = 2 on regions of several waves (runs_node_lanes): on an
/// H100, 1M tets +3-4 % and 4M +2.5 % against eight threads a node; four
/// lanes a thread gained less, and 100k tets (under one wave) lost 4 % with
/// two (docs/cuda.md, "Node passes with two lanes a thread").

/// Pass 2 with L lanes a thread: the elements of each lane's first
/// kPressureElements slots are loaded before the wait for pass 1; the same
/// sums as nodal_pressure_at. (Written once with nodal_pressure_kernel as
/// the L = 1 case, both compiled to different code and the float and
/// double steps ran 0.3-2 % slower on an H100: kept apart.)
template <class T, int L>
__global__ void nodal_pressure_lanes_kernel(ModelView<T> m, StateView<T> s, RegionView r) {
  if (const std::int64_t d = slots_moved(s.slots)) {  // a group's launch: this block row's scene
    m = m.materials_moved(d * s.slots.stride);
    s = s.moved(d);
  }
  constexpr int P = kNodeLanes / L;
  let_next_pass_launch();
  const index_t g = thread_index(), i = g / P;
  const bool active = i < r.n_nodes;
  const unsigned mask = lanes_group_mask<L>();
  PressureNode<T> n[L];
  if (active) {
    const index_t a = r.node(i);
#pragma unroll
    for (int l = 0; l < L; ++l) n[l] = load_pressure_node(m, a, g % P + l * P, mask);
  }
  wait_for_previous_pass();
  if (skipped(s) || !active) return;  // (whole groups)
  T dv[L];
#pragma unroll
  for (int l = 0; l < L; ++l) {
    dv[l] = T(0);
#pragma unroll
    for (int j = 0; j < kPressureElements; ++j)
      if (n[l].d.first + j * kNodeLanes < n[l].d.end) dv[l] += s.elem_dv[n[l].e[j]];
  }
  const index_t end = n[0].d.end;
  for (index_t k = n[0].d.first + kPressureElements * kNodeLanes; k < end; k += kNodeLanes)
#pragma unroll
    for (int l = 0; l < L; ++l)
      if (k + l * P < end) dv[l] += s.elem_dv[incident_element(__ldg(m.node_elem + k + l * P))];
  const T sum = lane_group_sums<L>(dv, mask);
  if (g % P == 0) s.node_p[n[0].d.a] = sum / __ldg(m.node_divisor + n[0].d.a);
}

/// Lanes a thread of the chained node passes on a large region
/// (runs_node_lanes).
inline constexpr int kThreadLanes = 2;

/// Whether the chained node passes over region r take kThreadLanes of a
/// node's lanes a thread (ModelView::lanes_node_min; a group's launch
/// counts every scene's nodes, launch_scenes).
template <class T>
bool runs_node_lanes(const ModelView<T>& m, const RegionView& r) {
  return index_t(launch_scenes) * r.n_nodes >= m.lanes_node_min;
}

/// Threads per block of the chained pass 4. In float its kernels take 32-44
/// registers a thread, and at 44 an SM holds 42 of their warps but five
/// blocks of 256 (40 warps); smaller blocks also free their slot when
/// their own two warps end. On an H200 100k and 1M tets in float ran 2 %
/// faster with pass 4 in blocks of 64 (in blocks of 128, 0.6 %), double
/// the same; pass 2 in blocks of 64 lost 7 %, so it keeps kBlock
/// (docs/cuda.md, "Element passes of several waves in smaller blocks").
inline constexpr int kNodeUpdateBlock = 64;
static_assert(kNodeUpdateBlock % 32 == 0, "whole warps: pass 4's lane groups and its slot drop work by warps");

/// Queues a node pass over region r (pressures: pass 2, in blocks of
/// kBlock; else pass 4, in blocks of kNodeUpdateBlock): `eight`, kNodeLanes
/// threads a node, or `lanes`, kThreadLanes lanes a thread on a large
/// region (runs_node_lanes; the same bits), counted in node_pass_launches.
template <class T, class... Params, class... Args>
void enqueue_node_pass(bool pressures, const ModelView<T>& m, const RegionView& r, cudaStream_t stream,
                       void (*eight)(Params...), void (*lanes)(Params...), Args... args) {
  if (r.n_nodes == 0) return;
  const bool by_lanes = runs_node_lanes(m, r);
  node_pass_launches.count(pressures, by_lanes);
  const int block = pressures ? kBlock : kNodeUpdateBlock;
  if (by_lanes)
    launch_chained_in(block, kNodeLanes / kThreadLanes * r.n_nodes, stream, lanes, args...);
  else
    launch_chained_in(block, kNodeLanes * r.n_nodes, stream, eight, args...);
}

/// Queues pass 2 over region r (enqueue_node_pass).
template <class T>
void enqueue_nodal_pressures(const ModelView<T>& m, const StateView<T>& s, const RegionView& r,
                             cudaStream_t stream) {
  enqueue_node_pass(true, m, r, stream, nodal_pressure_kernel<T>, nodal_pressure_lanes_kernel<T, kThreadLanes>, m, s,
                    r);
}

// ---- fused passes: a block per window of nodes, a thread per slot -------------

/// The body of a fused kernel (passes 1-2 or 3-4 in one) over region r:
/// block w takes the region's nodes of window r.packs[w] (RegionView:
/// nodes whose first slot lies in one window of ModelView::pack_span
/// slots, so that their slots span at most kPackedBlock), and thread t
/// computes slot base + t (base: the block's first node's first slot; a
/// slot of a node outside the region, between two of the block's, is
/// skipped) with value(k, x), which it leaves in shared memory. Then the
/// kNodeLanes lanes of group g add node g's values in the node passes'
/// order (lane j: slots j, j + 8, ..., from 0; then node_group_sum), and
/// its lane 0 runs finish(a, sum, prepare(a)): prepare loads what ends the
/// node's pass, for the group's first node right after the wait, beside
/// the slots' arithmetic (docs/cuda.md, "The node's tail loaded beside the
/// slots"). Each slot takes one thread, so a node of
/// 62 elements (the kidney's busiest) takes one round like a node of 4;
/// a warp per node ran 33 or more slots in two rounds (docs/cuda.md,
/// "Fused passes packed by windows"). Everything before the wait is model
/// and region data; the slot's element is loaded there too. kEarly: the
/// next kernel may launch as the block starts (programmatic dependent
/// launch); else only once the wait is over, so that its blocks, and the
/// kernels they let launch in turn, do not wait on the multiprocessors
/// while this one runs (the force pass before a contact stage's sweep).
template <class T, bool kRecomputed, bool kModuli, bool kEarly, class V, class Value, class Prepare, class Finish>
__device__ __forceinline__ void run_packed(const ModelView<T>& m, const StateView<T>& s, const RegionView& r,
                                           Value value, Prepare prepare, Finish finish) {
  __shared__ index_t node[kPackedBlock], begin[kPackedBlock], end[kPackedBlock];
  __shared__ V vals[kPackedBlock];
  if constexpr (kEarly) let_next_pass_launch();
  const int t = threadIdx.x;
  const index_t w = r.packs ? __ldg(r.packs + blockIdx.x) : index_t(blockIdx.x);
  const index_t first = __ldg(r.pack_first + w), n = __ldg(r.pack_first + w + 1) - first;  // n <= pack_span
  if (n == 0) return;  // (the whole block: a window of the whole mesh inside a node's slots)
  if (t < n) {
    const index_t a = r.node(first + t);
    node[t] = a;
    begin[t] = __ldg(m.node_elem_start + a);
    end[t] = __ldg(m.node_elem_start + a + 1);
  }
  __syncthreads();
  const index_t base = begin[0], k = base + t;
  int j = 0;  // the last of the block's nodes to start at or before slot k
  for (int step = kPackedBlock / 2; step > 0; step /= 2)
    if (j + step < n && begin[j + step] <= k) j += step;
  const bool active = k < end[j];
  SlotElement<T> x{};
  if (active) x = load_slot_element<T, kRecomputed, kModuli>(m, r, k);
  wait_for_previous_pass();
  if constexpr (!kEarly) let_next_pass_launch();
  if (skipped(s)) return;  // (the whole grid)
  const int lane = t % kNodeLanes;
  const index_t g0 = t / kNodeLanes;
  using P = decltype(prepare(index_t(0)));
  P tail{};  // what finish reads of the group's first node: loaded now, its round trip beside the slots'
  if (lane == 0 && g0 < n) tail = prepare(node[g0]);  // arithmetic, not after the sum
  V v{};
  if (active) v = value(k, x);
  vals[t] = v;
  __syncthreads();
  const unsigned mask = node_group_mask();
  for (index_t g = g0; g < n; g += kPackedBlock / kNodeLanes) {  // (uniform over a group)
    V acc{};
    for (index_t q = begin[g] + lane; q < end[g]; q += kNodeLanes) acc = acc + vals[q - base];
    acc = node_group_sum(acc, mask);
    if (lane == 0) finish(node[g], acc, g == g0 ? tail : prepare(node[g]));
  }
}

/// Passes 1 and 2 as one kernel (fuses_pressures; run_packed), the same
/// arithmetic in the same order: each slot gets the volume change pass 1
/// computes (stored with J_e by corner 0's visit, so that the pass arrays
/// end as the two passes leave them) or, for an element outside the
/// region, the element's stored value, read as pass 2 reads it.
template <class T, bool kRecomputed>
__global__ void __launch_bounds__(kPackedBlock)
    packed_pressures_kernel(ModelView<T> m, StateView<T> s, RegionView r, const Packed3<T>* u) {
  if (const std::int64_t d = slots_moved(s.slots)) {  // a group's launch: this block row's scene
    m = m.materials_moved(d * s.slots.stride);
    u = s.slot_moved(u, d);
    s = s.moved(d);
  }
  run_packed<T, kRecomputed, false, true, T>(
      m, s, r,
      [&](index_t, const SlotElement<T>& x) {
        if (!x.computed) return s.elem_dv[x.d.e];
        T J;
        const T v = element_volume_change(x.d, u, J);
        if (x.corner == 0) {
          s.elem_dv[x.d.e] = v;
          s.elem_J[x.d.e] = J;
        }
        return v;
      },
      [&](index_t a) { return __ldg(m.node_divisor + a); },
      [&](index_t a, T dv, T divisor) { s.node_p[a] = dv / divisor; });
}

/// Passes 3 and 4 as one kernel (Stepper::fuses_forces; run_packed), the
/// same arithmetic in the same order: each slot gets the force pass 3
/// computes for that corner (the element's four, as pass 3 computes them,
/// and corner 0's visit records a bad element as pass 3 does) or, for an
/// element outside the region, the slot's own value (zero since the
/// region's build, clear_outside_forces_kernel; returning the zero without
/// the load made the kidney's whole-mesh steps 1.5 % slower on an H100,
/// docs/cuda.md, "The fused force pass stores no slots"); lane 0 of the node's group ends pass 4. The computed
/// forces stay in shared memory: no pass reads them from the slots (a
/// separate pass 4 reads the slots its own pass 3 wrote; Backend::node_update
/// refuses to run without one), and not storing them made the kidney's
/// steps 2.5 % faster (docs/cuda.md, "The fused force pass stores no slots").
template <class T, bool kRecomputed, bool kLoad, bool kEarly>
__global__ void __launch_bounds__(kPackedBlock, kPackedForceMinBlocks<T>)
    packed_forces_kernel(ModelView<T> m, StateView<T> s, RegionView r, StepBuffers<T> b) {
  if (const std::int64_t d = slots_moved(s.slots)) {  // a group's launch: this block row's scene
    m = m.materials_moved(d * s.slots.stride);
    b = b.moved(d * s.slots.stride);
    s = s.moved(d);
  }
  run_packed<T, kRecomputed, true, kEarly, Vec3<T>>(
      m, s, r,
      [&](index_t k, const SlotElement<T>& x) {
        if (!x.computed) return s.f_slot[k].vec();
        const ElementForces<T> out = element_forces_of(s, x.d, b.u, m.ianp);
        if (x.corner == 0) record_if_bad(s.bad, x.d.e, out.J);
        return corner_force(out, x.corner);
      },
      [&](index_t a) { return load_node_tail<T, kLoad>(m, s, b, a); },
      [&](index_t a, Vec3<T> f, const NodeTail<T>& tail) { node_update_with<T, kLoad>(s, b, a, f, tail); });
}

/// Queues passes 1 and 2 over region r at displacements u as the steps run
/// them: one kernel on a small region (fuses_pressures), else the two; with
/// programmatic dependent launch, for the steps and for the reduction alike
/// (chained, a one-step advance_reduce on the slabs of `tissue bench`'s
/// contact_step is 0.7-2 us shorter on an H100 than with plain launches).
template <class T>
void enqueue_pressures(const ModelView<T>& m, const StateView<T>& s, const RegionView& r, const Packed3<T>* u,
                       cudaStream_t stream) {
  with_gradients(m, r, [&](auto recomputed) {
    constexpr bool kRecomputed = decltype(recomputed)::value;
    // a group's launch counts every scene's elements (launch_scenes): the fused kernel pays for its
    // fourfold loads only on a small launch
    if (fuses_pressures(r) && index_t(launch_scenes) * r.n_elems < kFusedPressuresMaxElements) {
      launch_chained_in(kPackedBlock, index_t(kPackedBlock) * r.n_packs, stream,
                        packed_pressures_kernel<T, kRecomputed>, m, s, r, u);
    } else {
      enqueue_element_pressures<T, kRecomputed>(m, s, r, u, stream);
      enqueue_nodal_pressures(m, s, r, stream);
    }
  });
}

/// Pass 3's element for thread i of its kernel: the region's elements in
/// reverse order. Pass 1 ends on the region's last elements and pass 4
/// starts on its first nodes, so pass 3 starts where pass 1's model loads
/// are still in L2 and ends on the first elements, whose force slots (the
/// first nodes', under the meshers' Morton numbering) pass 4 then reads
/// first. On 1M tets, whose 64 MB of force slots exceed an H100's 50 MB of
/// L2, a step is 5 % shorter (docs/cuda.md, "Passes in the order the L2
/// holds"); no result changes (each element's forces are its own, and the
/// lowest bad element wins in any order). The chained kernels of pass 3 use
/// it; the pass 3 beside a region check (small regions) and the persistent
/// kernels' pass 3 (run_steps) keep the forward order.
__device__ __forceinline__ index_t pass3_elem(const RegionView& r, index_t i) { return r.elem(r.n_elems - 1 - i); }

template <class T, bool kRecomputed, bool kLate>
__device__ __forceinline__ void element_forces_thread(const ModelView<T>& m, const StateView<T>& s,
                                                      const RegionView& r, const Packed3<T>* u, index_t first_wave) {
  const index_t i = thread_index();
  run_element_pass<kLate>(
      s, i < r.n_elems, first_wave, [&] { return load_element<T, kRecomputed>(m, pass3_elem(r, i)); },
      [&](const ElementData<T>& d) { element_forces_at(s, d, u, m.ianp); });
}

template <class T, bool kRecomputed>
__global__ void element_forces_kernel(ModelView<T> m, StateView<T> s, RegionView r, const Packed3<T>* u,
                                      index_t first_wave) {
  if (const std::int64_t d = slots_moved(s.slots)) {  // a group's launch: this block row's scene
    m = m.materials_moved(d * s.slots.stride);
    u = s.slot_moved(u, d);
    s = s.moved(d);
  }
  element_forces_thread<T, kRecomputed, kLateLoads<T>>(m, s, r, u, first_wave);
}

/// Blocks of kBlock an SM that pass 3's streaming kernel is compiled for
/// (0: the precision has none). In double element_forces_kernel takes 104
/// registers a thread, so an SM holds two blocks: too few loads in flight
/// where the step's arrays stream from memory. Three blocks (80 registers,
/// some spilled) ran 1M and 4M tets 9-12 % faster on an H200 and 100k
/// tets, whose arrays stay in the L2, about 10 % slower; in float (54 registers,
/// four blocks) five blocks gained nothing at 1M (docs/cuda.md, "Later
/// waves load after their wait").
template <class T>
inline constexpr int kStreamingForceBlocks = sizeof(T) == 8 ? 3 : 0;

/// Pass 3 where the region's force slots exceed half the L2
/// (streams_slots), in double: the same thread as element_forces_kernel
/// under launch bounds of kStreamingForceBlocks blocks an SM, its later
/// blocks loading after their wait (run_element_pass).
template <class T, bool kRecomputed>
__global__ void __launch_bounds__(kBlock, kStreamingForceBlocks<T> > 0 ? kStreamingForceBlocks<T> : 1)
    element_forces_streaming_kernel(ModelView<T> m, StateView<T> s, RegionView r, const Packed3<T>* u,
                                    index_t first_wave) {
  if (const std::int64_t d = slots_moved(s.slots)) {  // a group's launch: this block row's scene
    m = m.materials_moved(d * s.slots.stride);
    u = s.slot_moved(u, d);
    s = s.moved(d);
  }
  element_forces_thread<T, kRecomputed, true>(m, s, r, u, first_wave);
}

/// Pass 3 of a checked tick's first step when that step starts at pass 3
/// (Stepper's StepStart::kPass3BesideCheck; a model without law terms): the
/// previous kernel is the region's reach check, which writes nothing pass 3
/// reads (u and the nodal pressures are those the previous graph left), so
/// the forces are computed while the check runs, and the kernel waits for
/// it only before it stores them: a tick the check refuses stores nothing.
/// Pass 4 waits for this kernel, and so for the check. Reading before the
/// wait is safe because the check is a plain launch (everything queued
/// before it has finished when it starts; DeviceContact::enqueue_reach_check).
/// The same arithmetic as element_forces_kernel.
template <class T, bool kRecomputed>
__global__ void element_forces_beside_check_kernel(ModelView<T> m, StateView<T> s, RegionView r,
                                                   const Packed3<T>* u) {
  if (const std::int64_t d = slots_moved(s.slots)) {  // a group's launch: this block row's scene
    m = m.materials_moved(d * s.slots.stride);
    u = s.slot_moved(u, d);
    s = s.moved(d);
  }
  let_next_pass_launch();
  const index_t i = thread_index();
  const bool active = i < r.n_elems;
  ElementData<T> d;
  ElementForces<T> out;
  if (active) {
    d = load_element<T, kRecomputed>(m, r.elem(i));
    out = element_forces_of(s, d, u, m.ianp);
  }
  wait_for_previous_pass();
  if (skipped(s)) return;
  if (active) store_element_forces(s, d, out);
}

/// Pass 3 of a model with law terms (core/material.hpp), its later blocks
/// loading after their wait in both precisions: its 218 registers a thread
/// in double (126 in float) leave an SM one block (two), so even 100k tets
/// run several waves, and the late path costs no occupancy (docs/cuda.md,
/// "Later waves load after their wait").
template <class T, bool kRecomputed>
__global__ void law_element_forces_kernel(ModelView<T> m, StateView<T> s, RegionView r, const Packed3<T>* u,
                                          LawView<T> w, index_t first_wave) {
  if (const std::int64_t d = slots_moved(s.slots)) {  // a group's launch: this block row's scene
    m = m.materials_moved(d * s.slots.stride);
    w = w.moved(d * s.slots.stride);
    u = s.slot_moved(u, d);
    s = s.moved(d);
  }
  const index_t i = thread_index();
  run_element_pass<true>(
      s, i < r.n_elems, first_wave, [&] { return load_element<T, kRecomputed>(m, pass3_elem(r, i)); },
      [&](const ElementData<T>& d) { law_element_forces_at(m, s, d, u, w); });
}

/// Drops from the L2, without writing them back to memory, the 128-byte
/// lines that lie wholly inside the force slots [lo, hi) (PTX
/// `discard.global.L2`), the warp's lanes a line each. For slots read for
/// the last time in the step: over the whole mesh the next step's pass 3
/// writes every slot before any pass reads one, and a region's build clears
/// the slots of the elements it leaves out.
template <class T>
__device__ __forceinline__ void discard_slots(const Packed3<T>* f_slot, index_t lo, index_t hi) {
  constexpr std::uintptr_t kLine = 128;
  const auto base = reinterpret_cast<std::uintptr_t>(f_slot);
  const std::uintptr_t from = (base + std::uintptr_t(lo) * sizeof(Packed3<T>) + kLine - 1) & ~(kLine - 1);
  const std::uintptr_t to = (base + std::uintptr_t(hi) * sizeof(Packed3<T>)) & ~(kLine - 1);
  for (std::uintptr_t p = from + kLine * (threadIdx.x & 31); p < to; p += kLine * 32)
    asm volatile("discard.global.L2 [%0], 128;" ::"l"(p) : "memory");
}

/// Pass 4 with L of a node's lanes a thread (kNodeLanes / L threads a node;
/// launch kNodeLanes / L * n); whole groups are active or not. Over the
/// whole mesh of a model whose slots exceed half the L2
/// (ModelView::discard_slots) each warp then drops its nodes' slot lines
/// from the L2 (discard_slots): pass 3 left them dirty there, and a dirty
/// line read for the last time need not go back to memory.
template <class T, bool kLoad, int L>
__global__ void node_update_kernel(ModelView<T> m, StateView<T> s, RegionView r, StepBuffers<T> b) {
  if (const std::int64_t d = slots_moved(s.slots)) {  // a group's launch: this block row's scene
    m = m.materials_moved(d * s.slots.stride);
    b = b.moved(d * s.slots.stride);
    s = s.moved(d);
  }
  constexpr int P = kNodeLanes / L;
  let_next_pass_launch();
  const index_t g = thread_index(), i = g / P;
  const bool active = i < r.n_nodes;
  NodeData<T> d;
  if (active) d = load_node(m, r.node(i), g % P, lanes_group_mask<L>());
  wait_for_previous_pass();
  if (skipped(s)) return;
  if (active) node_update_lanes_at<T, kLoad, L>(m, s, b, d);
  if (m.discard_slots && !r.nodes) {  // the whole mesh: the warp's nodes, and so their slots, are consecutive
    __syncwarp();  // every lane's slots are summed
    const unsigned lo = __reduce_min_sync(~0u, active ? unsigned(d.first - d.lane) : ~0u);
    const unsigned hi = __reduce_max_sync(~0u, active ? unsigned(d.end) : 0u);
    if (lo < hi) discard_slots(s.f_slot, index_t(lo), index_t(hi));  // (a warp past the region: none)
  }
}

/// Queues pass 4 over region r from buffers b (enqueue_node_pass); kLoad:
/// the state has an applied load.
template <class T, bool kLoad>
void enqueue_node_update(const ModelView<T>& m, const StateView<T>& s, const RegionView& r, StepBuffers<T> b,
                         cudaStream_t stream) {
  enqueue_node_pass(false, m, r, stream, node_update_kernel<T, kLoad, 1>, node_update_kernel<T, kLoad, kThreadLanes>, m,
                    s, r, b);
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

/// `steps` TLED steps; every pass is a grid-stride loop over the region
/// (node passes over kNodeLanes lanes per node: the stride is a multiple of
/// kNodeLanes, so a group's lanes always iterate together) and the barrier
/// separates passes (and steps); with tools, each step ends with the
/// contact stage (cuda/contact.cuh) over the surface. The buffers rotate per
/// step. from_pass3: the first step starts at pass 3 (Stepper's StepStart).
template <class T, bool kLaw, bool kRecomputed, class Barrier>
__device__ void run_steps(const ModelView<T>& m, const StateView<T>& s, const RegionView& r, StepBuffers<T> b,
                          int steps, const ContactTools<T>* tools, const LawView<T>& w, bool from_pass3,
                          Barrier barrier) {
  const index_t first = thread_index(), stride = thread_stride();
  const index_t node_items = kNodeLanes * r.n_nodes;
  const int lane = first % kNodeLanes;
  const unsigned mask = node_group_mask();
  for (int k = 0; k < steps; ++k) {
    if (k > 0 || !from_pass3) {  // (uniform over the grid)
      for (index_t i = first; i < r.n_elems; i += stride)
        element_pressure_at(s, load_element_shape<T, kRecomputed>(m, r.elem(i)), b.u);
      barrier();
      for (index_t g = first; g < node_items; g += stride)
        nodal_pressure_at(m, s, load_pressure_node(m, r.node(g / kNodeLanes), lane, mask));
      barrier();
    }
    for (index_t i = first; i < r.n_elems; i += stride) {
      if constexpr (kLaw)
        law_element_forces_at(m, s, load_element<T, kRecomputed>(m, r.elem(i)), b.u, w);
      else
        element_forces_at(s, load_element<T, kRecomputed>(m, r.elem(i)), b.u, m.ianp);
    }
    barrier();
    for (index_t g = first; g < node_items; g += stride) {
      if (s.load)  // (a uniform branch)
        node_update_at<T, true>(m, s, b, load_node(m, r.node(g / kNodeLanes), lane, mask));
      else
        node_update_at<T, false>(m, s, b, load_node(m, r.node(g / kNodeLanes), lane, mask));
    }
    if (tools) {  // the contact stage
      barrier();
      for (index_t t = first - first % 32; t < m.n_tris; t += stride)  // a warp's 32 triangles together
        sweep_warp_triangles(m, s, *tools, k, b.u_next, t + first % 32);
      barrier();
      for (index_t i = first; i < m.n_surf; i += stride) gather_contact_at(m, s, *tools, k, b.u, b.u_next, i);
    }
    b = b.rotated();
    if (k + 1 < steps) barrier();
  }
}

/// Threads per block of the cooperative grid kernel: small blocks spread a
/// small region over many SMs (pass 3 is compute-heavy).
inline constexpr int kGridBlock = 256;

/// Threads per block of the cluster kernel: 1024 in float (a 16-block
/// cluster then covers 16k items, one per thread), 512 in double (its pass 3
/// needs ~128 registers per thread).
template <class T>
inline constexpr int kClusterBlock = sizeof(T) == 4 ? 1024 : 512;

// whole warps: the contact sweep hands a warp's 32 triangles to its lane groups (sweep_warp_triangles)
static_assert(kGridBlock % 32 == 0 && kClusterBlock<float> % 32 == 0 && kClusterBlock<double> % 32 == 0);

/// kLaw: the instantiation for a model with law terms (core/material.hpp),
/// chosen at launch like pass 3's kernels; kRecomputed as the pass kernels'.
template <class T, bool kLaw, bool kRecomputed>
__global__ void __launch_bounds__(kGridBlock)
    persistent_grid_kernel(ModelView<T> m, StateView<T> s, RegionView r, StepBuffers<T> b, int steps,
                           const ContactTools<T>* tools, LawView<T> w, int from_pass3) {
  run_steps<T, kLaw, kRecomputed>(m, s, r, b, steps, tools, w, from_pass3 != 0, GridBarrier{});
}

template <class T, bool kLaw, bool kRecomputed>
__global__ void __launch_bounds__(kClusterBlock<T>)
    persistent_cluster_kernel(ModelView<T> m, StateView<T> s, RegionView r, StepBuffers<T> b, int steps,
                              const ContactTools<T>* tools, LawView<T> w, int from_pass3) {
  run_steps<T, kLaw, kRecomputed>(m, s, r, b, steps, tools, w, from_pass3 != 0, ClusterBarrier{});
}

}  // namespace tissue::gpu
