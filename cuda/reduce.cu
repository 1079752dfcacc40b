#include "cuda/reduce.hpp"

#include <algorithm>
#include <cmath>

#include "core/energy.hpp"
#include "cuda/block_sum.cuh"
#include "cuda/launch.cuh"
#include "cuda/tled.cuh"

namespace tissue::gpu {
namespace {

constexpr int kReduceBlock = 256;
constexpr int kMaxReduceBlocks = 1024;

__device__ ReducePartial zero_partial() {
  ReducePartial p;
  for (int c = 0; c < 3; ++c) p.reaction[c] = p.internal[c] = 0;
  p.free2 = p.held2 = p.kinetic = p.max_disp = p.front_disp = p.energy = 0;
  p.visco_power = p.visco_stored = 0;
  p.nonfinite = 0;
  return p;
}

__device__ void combine(ReducePartial& a, const ReducePartial& b) {
  for (int c = 0; c < 3; ++c) {
    a.reaction[c] += b.reaction[c];
    a.internal[c] += b.internal[c];
  }
  a.free2 += b.free2;
  a.held2 += b.held2;
  a.kinetic += b.kinetic;
  a.max_disp = fmax(a.max_disp, b.max_disp);
  a.front_disp = fmax(a.front_disp, b.front_disp);
  a.energy += b.energy;
  a.visco_power += b.visco_power;
  a.visco_stored += b.visco_stored;
  a.nonfinite += b.nonfinite;
}

/// The block's sum of one partial per thread, in thread 0 (cuda/block_sum.cuh;
/// before: a shared-memory tree with a __syncthreads per level, 7 us for the
/// final combine of 34 partials on the kidney).
__device__ ReducePartial block_reduce(const ReducePartial& mine) {
  __shared__ ReducePartial sh[kReduceBlock / 32];
  return block_sum<kReduceBlock>(mine, zero_partial(), sh,
                                 [](ReducePartial& a, const ReducePartial& b) { combine(a, b); });
}

/// Node a's share (core node_terms) and its front-ring displacement.
template <class T>
__device__ void accumulate_node(const ModelView<T>& m, const StateView<T>& s, const StepBuffers<T>& b,
                                const FrontView& front, index_t a, ReducePartial& p) {
  const NodeTerms t = node_terms(s.f[a].vec(), b.u[a].vec(), b.u_prev[a].vec(), double(m.mass[a]), m.dt,
                                 s.role[a] == kInner, s.held[a], s.driven[a], s.contact[a], s.contact_normal[a].vec());
  for (int c = 0; c < 3; ++c) {
    p.reaction[c] += t.reaction[c];
    p.internal[c] += t.internal[c];
  }
  p.free2 += t.free2;
  p.held2 += t.held2;
  p.kinetic += t.kinetic;
  p.max_disp = fmax(p.max_disp, t.disp);
  if (front.ring && front.ring[a] == front.depth) p.front_disp = fmax(p.front_disp, t.disp);
  if (!t.finite) ++p.nonfinite;
}

/// Element e's strain energy V W(Fbar) (core/energy.hpp) and, for a
/// viscoelastic element, its Prony power and stored energy (core/energy.hpp
/// element_prony_energy) at the current u, added to p; node_p: nodal
/// pressures at the current u (IANP only).
template <class T>
__device__ void add_element_energy(const ModelView<T>& m, const T* node_p, const Packed3<T>* u, index_t e,
                                   const LawView<T>& w, ReducePartial& p) {
  const ElementData<T> d = load_element(m, e);
  Vec3<T> ue[4];
  corner_displacements(d, u, ue);
  const Mat3<T> F = deformation_gradient(ue, d.dN);
  const T J = det(F);
  T Jbar = J;
  if (m.ianp) {
    const T pbar = (node_p[d.c[0]] + node_p[d.c[1]] + node_p[d.c[2]] + node_p[d.c[3]]) / T(4);
    Jbar = T(1) + pbar / d.K;
  }
  if (w.fibre) {  // the fibre term's energy (core/material.hpp)
    ElementLaw<T> law;
    load_fibre(w.fibre, m.n_elems, e, law);
    p.energy += double(element_strain_energy<LawTerms<true, false>>(F, J, Jbar, d.V, d.mu, d.K, law));
  } else {
    p.energy += double(element_strain_energy(F, J, Jbar, d.V, d.mu, d.K));
  }
  const index_t slot = w.visco_slot ? w.visco_slot[e] : index_t(-1);
  if (slot < 0) return;
  T q[kMaxProny][kSymComponents];
  double g[kMaxProny], tau[kMaxProny];
  const index_t nv = w.n_visco;
  for (int i = 0; i < kMaxProny; ++i) {
    const bool in = i < w.n_prony;
    g[i] = in ? w.prony_g[i * nv + slot] : 0.0;
    tau[i] = in ? w.prony_tau[i * nv + slot] : 1.0;
    for (int c = 0; c < kSymComponents; ++c) q[i][c] = in ? w.visco_q[(kSymComponents * i + c) * nv + slot] : T(0);
  }
  const PronyEnergy pe = element_prony_energy(F, J, Jbar, d.V, d.mu, q, g, tau);
  p.visco_power += pe.power;
  p.visco_stored += pe.stored;
}

template <class T>
__global__ void __launch_bounds__(kReduceBlock)
    reduce_partial_kernel(ModelView<T> m, StateView<T> s, RegionView r, FrontView front, StepBuffers<T> b,
                          const T* energy_node_p, LawView<T> w, ReducePartial* out) {
  ReducePartial p = zero_partial();
  for (index_t i = thread_index(); i < r.n_nodes; i += thread_stride()) accumulate_node(m, s, b, front, r.node(i), p);
  for (index_t i = thread_index(); i < r.n_elems; i += thread_stride())
    add_element_energy(m, energy_node_p, b.u, r.elem(i), w, p);
  const ReducePartial sum = block_reduce(p);
  if (threadIdx.x == 0) out[blockIdx.x] = sum;
}

__global__ void __launch_bounds__(kReduceBlock)
    reduce_final_kernel(int n_partial, const ReducePartial* partial, unsigned long long* bad, Reductions* out) {
  ReducePartial p = zero_partial();
  for (int i = threadIdx.x; i < n_partial; i += kReduceBlock) combine(p, partial[i]);
  const ReducePartial sum = block_reduce(p);
  if (threadIdx.x != 0) return;
  Reductions r;
  r.reaction = {sum.reaction[0], sum.reaction[1], sum.reaction[2]};
  r.internal = {sum.internal[0], sum.internal[1], sum.internal[2]};
  r.free_force2 = sum.free2;
  r.held_force2 = sum.held2;
  r.kinetic = sum.kinetic;
  r.max_disp = sum.max_disp;
  r.front_disp = sum.front_disp;
  r.strain_energy = sum.energy;
  r.visco_power = sum.visco_power;
  r.visco_stored = sum.visco_stored;
  const unsigned long long key = *bad;
  if (key != ~0ull) {
    r.bad_elem = static_cast<index_t>(key >> 32);
    r.bad_J = __uint_as_float(static_cast<unsigned>(key & 0xffffffffu));
    *bad = ~0ull;
  }
  double all = r.free_force2 + r.held_force2 + r.kinetic + r.max_disp + r.visco_power + r.visco_stored;
  for (int c = 0; c < 3; ++c) all += r.reaction[c] + r.internal[c];
  r.finite = sum.nonfinite == 0 && isfinite(all);
  *out = r;
}

}  // namespace

template <class T>
void Reducer<T>::allocate(index_t n_nodes, index_t n_elems) {
  partial_.allocate(kMaxReduceBlocks);
  result_.allocate(1);
  // every byte of the result is defined (its padding too: compute-sanitizer's
  // initcheck reads the whole struct when it comes back)
  CUDA_CHECK(cudaMemset(result_.data(), 0, result_.bytes()));
  result_host_.allocate(1);
  dv_slot_.allocate(4 * size_t(n_elems));
  elem_J_.allocate(n_elems);
  node_p_.allocate(n_nodes);
}

template <class T>
Reductions Reducer<T>::run(const ModelView<T>& m, const StateView<T>& s, const RegionView& r, FrontView front,
                           StepBuffers<T> b, DeviceContact<T>& contact, Transfers& log, cudaStream_t stream) {
  enqueue(m, s, r, front, b, contact, stream);
  log.to_host(result_host_.data(), result_.data(), sizeof(Reductions), stream);
  return result_host_[0];
}

template <class T>
void Reducer<T>::enqueue(const ModelView<T>& m, const StateView<T>& s, const RegionView& r, FrontView front,
                         StepBuffers<T> b, DeviceContact<T>& contact, cudaStream_t stream) {
  if (m.ianp && r.n_elems > 0) {  // nodal pressures at the current u, into scratch
    // pass 1 below rewrites the region's elements' slots; the others must be the state's (a whole-mesh
    // region rewrites every slot, so the copy is only needed for a limited one)
    if (r.n_elems < m.n_elems)
      CUDA_CHECK(cudaMemcpyAsync(dv_slot_.data(), s.dv_slot, dv_slot_.bytes(), cudaMemcpyDeviceToDevice, stream));
    StateView<T> e = s;
    e.dv_slot = dv_slot_.data();
    e.elem_J = elem_J_.data();
    e.node_p = node_p_.data();
    launch(r.n_elems, stream, element_pressure_kernel<T>, m, e, r, static_cast<const Packed3<T>*>(b.u));
    launch(kNodeLanes * r.n_nodes, stream, nodal_pressure_kernel<T>, m, e, r);
  }
  const int blocks = std::min(grid_for(std::max(r.n_nodes, r.n_elems), kReduceBlock), kMaxReduceBlocks);
  launch_blocks(blocks, kReduceBlock, stream, reduce_partial_kernel<T>, m, s, r, front, b,
                static_cast<const T*>(node_p_.data()), law_, partial_.data());
  launch_blocks(1, kReduceBlock, stream, reduce_final_kernel, blocks, partial_.data(), s.bad, result_.data());
  contact.reduce(m, s, result_.data(), stream);
}

template class Reducer<float>;
template class Reducer<double>;

}  // namespace tissue::gpu
