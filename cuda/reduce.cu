#include "cuda/reduce.hpp"

#include <algorithm>
#include <cmath>

#include "cuda/launch.cuh"

namespace tissue::gpu {
namespace {

constexpr int kReduceBlock = 256;
constexpr int kMaxReduceBlocks = 1024;

__device__ ReducePartial zero_partial() {
  ReducePartial p;
  for (int c = 0; c < 3; ++c) p.reaction[c] = p.internal[c] = 0;
  p.free2 = p.held2 = p.kinetic = p.max_disp = 0;
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
  a.nonfinite += b.nonfinite;
}

/// Tree reduction of one value per thread in shared memory (fixed order).
__device__ ReducePartial block_reduce(ReducePartial mine) {
  __shared__ ReducePartial sh[kReduceBlock];
  sh[threadIdx.x] = mine;
  __syncthreads();
  for (int w = kReduceBlock / 2; w > 0; w /= 2) {
    if (threadIdx.x < w) combine(sh[threadIdx.x], sh[threadIdx.x + w]);
    __syncthreads();
  }
  return sh[0];
}

template <class T>
__device__ void accumulate(const ModelView<T>& m, const StateView<T>& s, const StepBuffers<T>& b, index_t a,
                           ReducePartial& p) {
  const Packed3<T> fp = s.f[a], up = b.u[a], pp = b.u_prev[a];
  const double f[3] = {fp.x, fp.y, fp.z};
  const double u[3] = {up.x, up.y, up.z};
  const double inv_dt = 1.0 / m.dt;
  const double v[3] = {(u[0] - double(pp.x)) * inv_dt, (u[1] - double(pp.y)) * inv_dt,
                       (u[2] - double(pp.z)) * inv_dt};
  const double f2 = f[0] * f[0] + f[1] * f[1] + f[2] * f[2];
  const double v2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
  if (s.driven[a])
    for (int c = 0; c < 3; ++c) p.reaction[c] += f[c];
  if (s.role[a] == kInner) {
    for (int c = 0; c < 3; ++c) p.internal[c] += f[c];
    (s.held[a] ? p.held2 : p.free2) += f2;
  }
  p.kinetic += 0.5 * double(m.mass[a]) * v2;
  const double d = sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2]);
  p.max_disp = fmax(p.max_disp, d);
  if (!isfinite(d) || !isfinite(f2) || !isfinite(v2)) ++p.nonfinite;
}

template <class T>
__global__ void __launch_bounds__(kReduceBlock)
    reduce_partial_kernel(ModelView<T> m, StateView<T> s, RegionView r, StepBuffers<T> b, ReducePartial* out) {
  ReducePartial p = zero_partial();
  for (index_t i = thread_index(); i < r.n_nodes; i += thread_stride()) accumulate(m, s, b, r.node(i), p);
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
  const unsigned long long key = *bad;
  if (key != ~0ull) {
    r.bad_elem = static_cast<index_t>(key >> 32);
    r.bad_J = __uint_as_float(static_cast<unsigned>(key & 0xffffffffu));
    *bad = ~0ull;
  }
  double all = r.free_force2 + r.held_force2 + r.kinetic + r.max_disp;
  for (int c = 0; c < 3; ++c) all += r.reaction[c] + r.internal[c];
  r.finite = sum.nonfinite == 0 && isfinite(all);
  *out = r;
}

}  // namespace

template <class T>
void Reducer<T>::allocate() {
  partial_.allocate(kMaxReduceBlocks);
  result_.allocate(1);
  result_host_.allocate(1);
}

template <class T>
Reductions Reducer<T>::run(const ModelView<T>& m, const StateView<T>& s, const RegionView& r, StepBuffers<T> b,
                           Transfers& log, cudaStream_t stream) {
  const int blocks = std::min(grid_for(r.n_nodes, kReduceBlock), kMaxReduceBlocks);
  launch_blocks(blocks, kReduceBlock, stream, reduce_partial_kernel<T>, m, s, r, b, partial_.data());
  launch_blocks(1, kReduceBlock, stream, reduce_final_kernel, blocks, partial_.data(), s.bad, result_.data());
  log.to_host(result_host_.data(), result_.data(), sizeof(Reductions), stream);
  return result_host_[0];
}

template class Reducer<float>;
template class Reducer<double>;

}  // namespace tissue::gpu
