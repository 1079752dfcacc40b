#include "cuda/reduce.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>

#include <cuda/atomic>

#include "core/contact.hpp"
#include "core/energy.hpp"
#include "core/node_rules.hpp"
#include "cuda/block_sum.cuh"
#include "cuda/launch.cuh"
#include "cuda/tled.cuh"

namespace tissue::gpu {
namespace {

constexpr int kReduceBlock = 128;
static_assert(kReduceBlock % 32 == 0 && kReduceBlock >= 64, "the last block combines on two warps");
constexpr int kMaxReduceBlocks = 1024;
/// Blocks an SM holds of a group's reduction (reduce_kernel). Compiled for
/// one wave, the kernel takes 246 registers a thread in float: two blocks
/// an SM, 12.5 % occupancy over the ~100 waves of 256 kidneys, and 481 us
/// of a 2 ms tick on an H200 (ncu). Four blocks an SM, with a group's
/// element and node passes sized by every scene's items, took 256 kidneys
/// from 492k to 556k scene-steps/s (docs/batch.md).
constexpr int kGroupReduceBlocks = 4;

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

__device__ ToolPartial empty_tool() {
  ToolPartial p;
  p.reaction[0] = p.reaction[1] = p.reaction[2] = 0;
  p.contact = p.grasped = p.rigid = p.outside = p.pad = 0;
  p.rigid_first = -1;
  return p;
}

__device__ void empty_partial(ContactPartial& p) {
  for (int t = 0; t < kMaxTools; ++t) p.tool[t] = empty_tool();
}

__device__ void combine(ToolPartial& a, const ToolPartial& b) {
  for (int c = 0; c < 3; ++c) a.reaction[c] += b.reaction[c];
  a.contact += b.contact;
  a.grasped += b.grasped;
  a.rigid += b.rigid;
  a.outside += b.outside;
  if (b.rigid_first >= 0 && (a.rigid_first < 0 || b.rigid_first < a.rigid_first)) a.rigid_first = b.rigid_first;
}

__device__ void combine(ContactPartial& a, const ContactPartial& b) {
  for (int t = 0; t < kMaxTools; ++t) combine(a.tool[t], b.tool[t]);
}

/// The block's sum of one contact partial per thread, in thread 0, over the
/// tools in `used` (a bit per tool, the same in every thread): the others
/// hold nothing in any thread, and their sum is their empty partial.
__device__ ContactPartial block_reduce(ContactPartial c, unsigned used) {
  __shared__ ToolPartial sh[kMaxTools][kReduceBlock / 32];
#pragma unroll
  for (int t = 0; t < kMaxTools; ++t)
    if (used >> t & 1u)
      c.tool[t] = block_sum<kReduceBlock>(c.tool[t], empty_tool(), sh[t],
                                          [](ToolPartial& a, const ToolPartial& b) { combine(a, b); });
  return c;
}

/// Surface node a's contact share (core contact_reaction) for its tool;
/// returns the tool's bit (0 when the node is in no contact: nothing added).
/// The tool index is data: each tool's entry is updated under a test of a
/// constant index, so the partial stays in registers (indexing it by the
/// tool put the whole struct in local memory: 176 bytes of stack, and the
/// reduction kernel took 19 us on the kidney on an H100).
template <class T>
__device__ unsigned accumulate_contact(const ModelView<T>& m, const StateView<T>& s, const ContactTools<T>* tools,
                                       index_t a, ContactPartial& p) {
  const int t = s.contact_tool[a];
  const std::uint8_t kind = s.contact[a];
  if (t < 0 || t >= kMaxTools || kind == kNoContact) return 0;
  const T mu = kind == kPushed && tools && t < tools->n_tools ? tools->tool[t].friction : T(0);
  const Vec3<T> r = contact_reaction(kind, s.f[a].vec(), s.contact_normal[a].vec(), fixed_axes(m.node_flags[a]), mu);
#pragma unroll
  for (int k = 0; k < kMaxTools; ++k) {
    if (k != t) continue;
    ToolPartial& q = p.tool[k];
    q.reaction[0] += double(r.x);
    q.reaction[1] += double(r.y);
    q.reaction[2] += double(r.z);
    q.contact += (kind == kPushed || kind == kGrasped) ? 1 : 0;
    q.grasped += kind == kGrasped ? 1 : 0;
    if (kind == kRigidContact) {
      if (q.rigid_first < 0 || a < q.rigid_first) q.rigid_first = a;
      ++q.rigid;
    }
    q.outside += kind == kOutsideRegion ? 1 : 0;
  }
  return 1u << t;
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

/// Block b's partial, written by another block (made visible by the release
/// of its count),
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
  const ElementData<T> d = load_element_moduli<T, kRecomputed>(m, e);
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
    p.energy += double(element_strain_energy<LawTerms<FibreTerm>>(F, J, Jbar, d.V, d.mu, d.K, law));
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
/// copy); key: the bad flag's value (loaded at the kernel's start), which
/// it clears.
__device__ void write_result(const ReducePartial& sum, const ContactPartial& c, unsigned long long key,
                             unsigned long long* bad, Reductions* out, Reductions* host_out) {
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
    const ToolPartial& q = c.tool[t];
    tr.reaction = {q.reaction[0], q.reaction[1], q.reaction[2]};
    tr.contact = q.contact;
    tr.grasped = q.grasped;
    tr.rigid = q.rigid;
    tr.rigid_first = q.rigid_first;
    tr.outside = q.outside;
    finite = finite && isfinite(tr.reaction.x + tr.reaction.y + tr.reaction.z);
  }
  r.finite = finite;
  *out = r;
  if (host_out) *host_out = r;  // visible to the host once the stream has finished
}

/// Block i's partials for lanes' blocks i, i + 32, ..., i + 32 (kAhead - 1)
/// loaded together (one round trip to L2 for the kidney's blocks, not one
/// per block), then combined into p in block order: the same sums as one at
/// a time. `take(b)` says whether block b has a partial (the others add
/// nothing).
template <int kAhead, class P, class Take>
__device__ void combine_columns(P& p, const int* words, int lane, int blocks, Take take) {
  for (int i0 = lane; i0 < blocks; i0 += 32 * kAhead) {
    P q[kAhead];
    bool has[kAhead];
#pragma unroll
    for (int j = 0; j < kAhead; ++j) {
      has[j] = i0 + 32 * j < blocks && take(i0 + 32 * j);
      if (has[j]) q[j] = load_columns<P>(words, i0 + 32 * j);
    }
#pragma unroll
    for (int j = 0; j < kAhead; ++j)
      if (has[j]) combine(p, q[j]);
  }
}

/// Every reduction in one launch (before: a partial kernel, a final block
/// and the contact's kernel, 3 launches). The region's nodes, its elements
/// and the surface nodes are one list of items, a thread each (before: each
/// thread took a node, then an element, then a surface node, one after the
/// other); each block sums its threads' partials (the contact sums only in
/// the few blocks that met a node in contact, and only for the tools they
/// met), and the last block to finish combines every block's partials in
/// block order. 128 threads a block, so that each block's shuffles are few.
///
/// The last block's combine: its warp 0 combines the region partials and
/// its warp 1 the contact partials at once, lane i the blocks i, i + 32, ...
/// in that order, then five shuffle levels. A block that met no contact
/// stores no contact partial (its touched word is 0) and is not read; nor
/// are the tools no block met summed: they would add +0 and counts of 0
/// (the sums start at +0, which adding +0 leaves as it is). The count of
/// finished blocks is a release-acquire atomic (before: a sequentially
/// consistent fence in every block's thread 0 and in the last block).
///
/// On the kidney on an H100, a tick in contact: 14.3 us alone on the GPU
/// (ncu) before, 10.3 us now. Before, globaltimer stamps in a scratch build
/// (not under the profiler) split its 10.5-11.4 us into the three item loops
/// one after the other 2.9-4.6, the block sums 2.7 (1.6 of it the contact
/// partial's four tools), the count's fence 0.8, the last block's loads and
/// shuffles on one warp 2.3 and the result 0.7. (Earlier still: 19 us with
/// the contact partial in local memory and summed by every block; on the
/// 100k slab's 396 blocks, 28 us with the partials in rows, 19 us in
/// columns.)
/// kMinBlocks: the blocks an SM must hold at once. One scene's reduction
/// runs in one wave and keeps every register it wants (246 a thread in
/// float: two blocks an SM); a group's (launch_scenes scenes, dozens of
/// waves) runs kGroupReduceBlocks an SM. The same arithmetic either way.
template <class T, bool kRecomputed, int kMinBlocks>
__global__ void __launch_bounds__(kReduceBlock, kMinBlocks)
    reduce_kernel(ModelView<T> m, StateView<T> s, RegionView r, FrontView front, StepBuffers<T> b,
                  const T* energy_node_p, LawView<T> w, const ContactTools<T>* tools, int* partial, int* contact,
                  unsigned* touched_tools, unsigned* done, Reductions* out, Reductions* host_out) {
  if (const std::int64_t d = slots_moved(s.slots)) {  // a group's launch: this block row's scene (no host_out)
    m = m.materials_moved(d * s.slots.stride);
    w = w.moved(d * s.slots.stride);
    b = b.moved(d * s.slots.stride);
    energy_node_p = s.slot_moved(energy_node_p, d);
    partial = s.slot_moved(partial, d);
    contact = s.slot_moved(contact, d);
    touched_tools = s.slot_moved(touched_tools, d);
    done = s.slot_moved(done, d);
    out = s.slot_moved(out, d);
    tools = s.tools_moved(tools, d);
    s = s.moved(d);
  }
  if (skipped(s)) return;  // every block: the count stays at 0
  // the bad flag as the steps' pass 3 left it (the kernels before this one have finished; only the last
  // block's thread 0 uses it: loaded now, its round trip overlaps the sums)
  const unsigned long long bad_key = threadIdx.x == 0 ? __ldcg(s.bad) : ~0ull;
  const index_t nn = r.n_nodes, ne = r.n_elems, items = r.n_nodes + r.n_elems + m.n_surf;
  ReducePartial p = zero_partial();
  ContactPartial c;
  empty_partial(c);
  unsigned mine = 0;  // a bit per tool this thread met
  for (index_t i = thread_index(); i < items; i += thread_stride()) {
    if (i < nn)
      accumulate_node(m, s, b, front, r.node(i), p);
    else if (i < nn + ne)
      add_element_energy<T, kRecomputed>(m, energy_node_p, b.u, r.elem(i - nn), w, p);
    else
      mine |= accumulate_contact(m, s, tools, m.surf_nodes[i - nn - ne], c);
  }
  p = block_reduce(p);
  unsigned used = 0;  // the tools any thread of the block met: the same in every thread
#pragma unroll
  for (int t = 0; t < kMaxTools; ++t) used |= __syncthreads_or(int(mine >> t & 1u)) ? 1u << t : 0u;
  if (used) c = block_reduce(c, used);
  __shared__ bool last;
  __shared__ ContactPartial contact_sum;
  if (threadIdx.x == 0) {
    store_columns(p, partial, int(blockIdx.x));
    if (used) store_columns(c, contact, int(blockIdx.x));
    touched_tools[blockIdx.x] = used;
    // release: this thread's partials are visible to whoever sees the count; acquire: the last block
    // sees every block's
    last = cuda::atomic_ref<unsigned, cuda::thread_scope_device>(*done).fetch_add(1u, cuda::memory_order_acq_rel) ==
           gridDim.x - 1;
  }
  __syncthreads();  // the last block's other threads are ordered after thread 0's acquire
  if (!last || threadIdx.x >= 64) return;
  const int lane = int(threadIdx.x) % 32, blocks = int(gridDim.x);
  if (threadIdx.x < 32) {
    p = zero_partial();
    combine_columns<4>(p, partial, lane, blocks, [](int) { return true; });
    p = warp_sum(p, [](ReducePartial& a, const ReducePartial& q) { combine(a, q); });
  } else {
    empty_partial(c);
    unsigned met = 0;  // the tools this lane's blocks met (each block's word read once)
    combine_columns<2>(c, contact, lane, blocks, [&](int i) {
      const unsigned tools = __ldcg(touched_tools + i);
      met |= tools;
      return tools != 0;
    });
#pragma unroll
    for (int off = 16; off > 0; off /= 2) met |= __shfl_xor_sync(0xffffffffu, met, off);  // every lane's
#pragma unroll
    for (int t = 0; t < kMaxTools; ++t)
      if (met >> t & 1u) c.tool[t] = warp_sum(c.tool[t], [](ToolPartial& a, const ToolPartial& q) { combine(a, q); });
    if (lane == 0) contact_sum = c;
  }
  // warps 0 and 1 only (the others have left): contact_sum is written before thread 0 reads it. Not
  // .aligned: the two warps reach it from different branches.
  asm volatile("barrier.sync 1, 64;" ::: "memory");
  if (threadIdx.x != 0) return;
  write_result(p, contact_sum, bad_key, s.bad, out, host_out);
  *done = 0;  // for the next launch
}

}  // namespace

template <class T>
void Reducer<T>::allocate(cudaStream_t stream) {
  partial_.allocate(size_t(kWords<ReducePartial>) * kMaxReduceBlocks);
  contact_partial_.allocate(size_t(kWords<ContactPartial>) * kMaxReduceBlocks);
  touched_.allocate(kMaxReduceBlocks);
  done_.allocate(1);
  done_.fill_bytes(0, stream);  // on the stream the kernel runs on: ordered before its first launch
  result_.allocate(1);
  // every byte of the result is defined (its padding too: compute-sanitizer's
  // initcheck reads the whole struct when it comes back)
  result_.fill_bytes(0, stream);
  result_host_.allocate(1);
}

template <class T>
Reductions Reducer<T>::run(const ModelView<T>& m, const StateView<T>& s, const StateView<T>& scratch,
                           const RegionView& r, FrontView front, StepBuffers<T> b, const ContactTools<T>* tools,
                           Transfers& log, cudaStream_t stream) {
  enqueue(m, s, scratch, r, front, b, tools, stream);
  log.to_host(result_host_.data(), result_.data(), sizeof(Reductions), stream);
  return result_host_[0];
}

template <class T>
void Reducer<T>::enqueue(const ModelView<T>& m, const StateView<T>& s, const StateView<T>& scratch,
                         const RegionView& r, FrontView front, StepBuffers<T> b, const ContactTools<T>* tools,
                         cudaStream_t stream, bool to_host) {
  if (runs_passes(m, r)) {  // nodal pressures at the current u, into the scratch set
    // as the steps run them (the same bits either way)
    enqueue_pressures(m, scratch, r, static_cast<const Packed3<T>*>(b.u), stream);
  }
  const index_t items = std::max(r.n_nodes + r.n_elems + m.n_surf, index_t(1));
  const int blocks = std::min(grid_for(items, kReduceBlock), kMaxReduceBlocks);
  // a plain launch: chained, the kidney's ticks were 1-2 % longer on an H100 (likely, not profiled:
  // its blocks resident and waiting while the passes before it run; docs/cuda.md, "The reduction's
  // passes chained")
  with_gradients(m, r, [&](auto recomputed) {  // the energies with the gradients of the steps
    const auto kernel = launch_scenes > 1 ? reduce_kernel<T, decltype(recomputed)::value, kGroupReduceBlocks>
                                          : reduce_kernel<T, decltype(recomputed)::value, 1>;
    launch_blocks(blocks, kReduceBlock, stream, kernel, m, s, r, front, b,
                  static_cast<const T*>(scratch.node_p), law_, tools, partial_.data(), contact_partial_.data(), touched_.data(), done_.data(),
                  result_.data(), to_host ? result_host_.device() : nullptr);
  });
}

template class Reducer<float>;
template class Reducer<double>;

}  // namespace tissue::gpu
