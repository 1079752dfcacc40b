#include "cuda/reduce.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "core/contact.hpp"
#include "core/energy.hpp"
#include "core/node_rules.hpp"
#include "cuda/block_sum.cuh"
#include "cuda/launch.cuh"
#include "cuda/tled.cuh"

namespace tissue::gpu {
namespace {

constexpr int kReduceBlock = 128;
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

__device__ void empty_partial(ContactPartial& p) {
  for (int t = 0; t < kMaxTools; ++t) {
    p.reaction[t][0] = p.reaction[t][1] = p.reaction[t][2] = 0;
    p.contact[t] = p.grasped[t] = p.rigid[t] = p.outside[t] = 0;
    p.rigid_first[t] = -1;
  }
}

__device__ void combine(ContactPartial& a, const ContactPartial& b) {
  for (int t = 0; t < kMaxTools; ++t) {
    for (int c = 0; c < 3; ++c) a.reaction[t][c] += b.reaction[t][c];
    a.contact[t] += b.contact[t];
    a.grasped[t] += b.grasped[t];
    a.rigid[t] += b.rigid[t];
    a.outside[t] += b.outside[t];
    if (b.rigid_first[t] >= 0 && (a.rigid_first[t] < 0 || b.rigid_first[t] < a.rigid_first[t]))
      a.rigid_first[t] = b.rigid_first[t];
  }
}

/// The block's sum of one contact partial per thread, in thread 0.
__device__ ContactPartial block_reduce(const ContactPartial& mine) {
  __shared__ ContactPartial sh[kReduceBlock / 32];
  ContactPartial empty;
  empty_partial(empty);
  return block_sum<kReduceBlock>(mine, empty, sh, [](ContactPartial& a, const ContactPartial& b) { combine(a, b); });
}

/// Surface node a's contact share (core contact_reaction) for its tool;
/// false when it is in no contact (nothing added).
/// The tool index is data: each tool's entry is updated under a test of a
/// constant index, so the partial stays in registers (indexing it by the
/// tool put the whole struct in local memory: 176 bytes of stack, and the
/// reduction kernel took 19 us on the kidney on an H100).
template <class T>
__device__ bool accumulate_contact(const ModelView<T>& m, const StateView<T>& s, index_t a, ContactPartial& p) {
  const int t = s.contact_tool[a];
  const std::uint8_t kind = s.contact[a];
  if (t < 0 || t >= kMaxTools || kind == kNoContact) return false;
  const Vec3<T> r = contact_reaction(kind, s.f[a].vec(), s.contact_normal[a].vec(), fixed_axes(m.node_flags[a]));
#pragma unroll
  for (int k = 0; k < kMaxTools; ++k) {
    if (k != t) continue;
    p.reaction[k][0] += double(r.x);
    p.reaction[k][1] += double(r.y);
    p.reaction[k][2] += double(r.z);
    p.contact[k] += (kind == kPushed || kind == kGrasped) ? 1 : 0;
    p.grasped[k] += kind == kGrasped ? 1 : 0;
    if (kind == kRigidContact) {
      if (p.rigid_first[k] < 0 || a < p.rigid_first[k]) p.rigid_first[k] = a;
      ++p.rigid[k];
    }
    p.outside[k] += kind == kOutsideRegion ? 1 : 0;
  }
  return true;
}

/// Block partials are kept as columns: word k of block b's partial at
/// words[k * kMaxReduceBlocks + b], so that when the lanes of a warp read one
/// word of 32 consecutive blocks' partials they read one 128-byte line (a
/// partial per block in a row made each such read touch 32 lines: at 100k
/// surface triangles, 396 blocks, the last block's combine was most of the
/// kernel's 28 us).
template <class P>
constexpr int kWords = int(sizeof(P) / sizeof(int));

template <class P>
__device__ void store_columns(const P& p, int* words, int b) {
  static_assert(sizeof(P) % sizeof(int) == 0);
  int w[kWords<P>];
  memcpy(w, &p, sizeof(P));
  for (int k = 0; k < kWords<P>; ++k) words[k * kMaxReduceBlocks + b] = w[k];
}

/// Block b's partial, written by another block (made visible by its fence),
/// read from L2 (never a stale line of this SM's L1).
template <class P>
__device__ P load_columns(const int* words, int b) {
  int w[kWords<P>];
  for (int k = 0; k < kWords<P>; ++k) w[k] = __ldcg(words + k * kMaxReduceBlocks + b);
  P out;
  memcpy(&out, w, sizeof(P));
  return out;
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
template <class T, bool kRecomputed>
__device__ void add_element_energy(const ModelView<T>& m, const T* node_p, const Packed3<T>* u, index_t e,
                                   const LawView<T>& w, ReducePartial& p) {
  const ElementData<T> d = load_element<T, kRecomputed>(m, e);
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

/// Thread 0 of the block that finishes last: the result from the combined
/// partials (region sums `sum`, contact sums `c`) into out and, unless null,
/// into host_out (mapped host memory: the tick graph's download without a
/// copy); reads and clears the bad flag.
__device__ void write_result(const ReducePartial& sum, const ContactPartial& c, unsigned long long* bad,
                             Reductions* out, Reductions* host_out) {
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
  for (int k = 0; k < 3; ++k) all += r.reaction[k] + r.internal[k];
  bool finite = sum.nonfinite == 0 && isfinite(all);
  for (int t = 0; t < kMaxTools; ++t) {
    ToolReduction& tr = r.tools[t];
    tr.reaction = {c.reaction[t][0], c.reaction[t][1], c.reaction[t][2]};
    tr.contact = c.contact[t];
    tr.grasped = c.grasped[t];
    tr.rigid = c.rigid[t];
    tr.rigid_first = c.rigid_first[t];
    tr.outside = c.outside[t];
    finite = finite && isfinite(tr.reaction.x + tr.reaction.y + tr.reaction.z);
  }
  r.finite = finite;
  *out = r;
  if (host_out) *host_out = r;  // visible to the host once the stream has finished
}

/// Every reduction in one launch (before: a partial kernel, a final block
/// and the contact's kernel, 3 launches). Each block sums its share of the
/// region's nodes and elements and of the surface nodes (the contact sums
/// only where one of its threads met a node in contact: almost no block);
/// the last block to finish combines every block's partials in block order,
/// on its first warp. 128 threads a block, so that each block's shuffles
/// are few. (On the kidney on an H100 the busiest multiprocessor spent
/// 14.3 us in this kernel with 256-thread blocks, its contact partial in
/// local memory, every block summing it; 13.1 us as it is. On the 100k
/// slab's 396 blocks, 28 us with the partials in rows, 19 us in columns.)
template <class T, bool kRecomputed>
__global__ void __launch_bounds__(kReduceBlock)
    reduce_kernel(ModelView<T> m, StateView<T> s, RegionView r, FrontView front, StepBuffers<T> b,
                  const T* energy_node_p, LawView<T> w, int* partial, int* contact, unsigned* done,
                  Reductions* out, Reductions* host_out) {
  if (skipped(s)) return;  // every block: the count stays at 0
  ReducePartial p = zero_partial();
  for (index_t i = thread_index(); i < r.n_nodes; i += thread_stride()) accumulate_node(m, s, b, front, r.node(i), p);
  for (index_t i = thread_index(); i < r.n_elems; i += thread_stride())
    add_element_energy<T, kRecomputed>(m, energy_node_p, b.u, r.elem(i), w, p);
  ContactPartial c;
  empty_partial(c);
  bool touched = false;
  for (index_t i = thread_index(); i < m.n_surf; i += thread_stride())
    touched = accumulate_contact(m, s, m.surf_nodes[i], c) || touched;
  p = block_reduce(p);
  if (__syncthreads_or(touched)) c = block_reduce(c);  // the same answer for every thread: no divergence
  __shared__ bool last;
  if (threadIdx.x == 0) {
    store_columns(p, partial, int(blockIdx.x));
    store_columns(c, contact, int(blockIdx.x));
    __threadfence();  // the partials are visible before the count says so
    last = atomicAdd(done, 1u) == gridDim.x - 1;
  }
  __syncthreads();
  if (!last || threadIdx.x >= 32) return;
  __threadfence();
  p = zero_partial();
  empty_partial(c);
  for (int i = int(threadIdx.x); i < int(gridDim.x); i += 32) {
    combine(p, load_columns<ReducePartial>(partial, i));
    combine(c, load_columns<ContactPartial>(contact, i));
  }
  p = warp_sum(p, [](ReducePartial& a, const ReducePartial& q) { combine(a, q); });
  c = warp_sum(c, [](ContactPartial& a, const ContactPartial& q) { combine(a, q); });
  if (threadIdx.x != 0) return;
  write_result(p, c, s.bad, out, host_out);
  *done = 0;  // for the next launch
}

}  // namespace

template <class T>
void Reducer<T>::allocate(index_t n_nodes, index_t n_elems, cudaStream_t stream) {
  partial_.allocate(size_t(kWords<ReducePartial>) * kMaxReduceBlocks);
  contact_partial_.allocate(size_t(kWords<ContactPartial>) * kMaxReduceBlocks);
  done_.allocate(1);
  done_.fill_bytes(0, stream);  // on the stream the kernel runs on: ordered before its first launch
  result_.allocate(1);
  // every byte of the result is defined (its padding too: compute-sanitizer's
  // initcheck reads the whole struct when it comes back)
  result_.fill_bytes(0, stream);
  result_host_.allocate(1);
  dv_slot_.allocate(4 * size_t(n_elems));
  elem_J_.allocate(n_elems);
  node_p_.allocate(n_nodes);
}

template <class T>
Reductions Reducer<T>::run(const ModelView<T>& m, const StateView<T>& s, const RegionView& r, FrontView front,
                           StepBuffers<T> b, Transfers& log, cudaStream_t stream) {
  enqueue(m, s, r, front, b, stream);
  log.to_host(result_host_.data(), result_.data(), sizeof(Reductions), stream);
  return result_host_[0];
}

template <class T>
void Reducer<T>::enqueue(const ModelView<T>& m, const StateView<T>& s, const RegionView& r, FrontView front,
                         StepBuffers<T> b, cudaStream_t stream, bool to_host) {
  if (m.ianp && r.n_elems > 0) {  // nodal pressures at the current u, into scratch
    // pass 1 below rewrites the region's elements' slots; the others must be the state's (a whole-mesh
    // region rewrites every slot, so the copy is only needed for a limited one)
    if (r.n_elems < m.n_elems)
      CUDA_CHECK(cudaMemcpyAsync(dv_slot_.data(), s.dv_slot, dv_slot_.bytes(), cudaMemcpyDeviceToDevice, stream));
    StateView<T> e = s;
    e.dv_slot = dv_slot_.data();
    e.elem_J = elem_J_.data();
    e.node_p = node_p_.data();
    with_gradients(m, r, [&](auto recomputed) {
      launch(r.n_elems, stream, element_pressure_kernel<T, decltype(recomputed)::value>, m, e, r,
             static_cast<const Packed3<T>*>(b.u));
    });
    launch(kNodeLanes * r.n_nodes, stream, nodal_pressure_kernel<T>, m, e, r);
  }
  const index_t items = std::max({r.n_nodes, r.n_elems, m.n_surf, index_t(1)});
  const int blocks = std::min(grid_for(items, kReduceBlock), kMaxReduceBlocks);
  with_gradients(m, r, [&](auto recomputed) {  // the energies with the gradients of the steps
    launch_blocks(blocks, kReduceBlock, stream, reduce_kernel<T, decltype(recomputed)::value>, m, s, r, front, b,
                  static_cast<const T*>(node_p_.data()), law_, partial_.data(), contact_partial_.data(), done_.data(),
                  result_.data(), to_host ? result_host_.device() : nullptr);
  });
}

template class Reducer<float>;
template class Reducer<double>;

}  // namespace tissue::gpu
