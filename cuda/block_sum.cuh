// The block sum of the reduction kernels (cuda/reduce.cu, cuda/contact.cu):
// each thread holds a partial (a trivially copyable struct of sums, counts,
// maxima); the warps combine theirs by shuffles, then warp 0 combines the
// warps' results. The tree has a fixed shape, so the sums come out in the
// same order every run (deterministic). nvcc only.
#pragma once

#include <cstring>
#include <type_traits>

namespace tissue::gpu {

/// p as held by the lane `off` above (word by word: any trivially copyable
/// partial, doubles as their two halves).
template <class P>
__device__ __forceinline__ P shuffle_down(const P& p, int off) {
  static_assert(std::is_trivially_copyable_v<P> && sizeof(P) % sizeof(int) == 0);
  constexpr int kWords = int(sizeof(P) / sizeof(int));
  int w[kWords];
  std::memcpy(w, &p, sizeof(P));
#pragma unroll
  for (int k = 0; k < kWords; ++k) w[k] = __shfl_down_sync(0xffffffffu, w[k], off);
  P o;
  std::memcpy(&o, w, sizeof(P));
  return o;
}

/// The warp's combined partial (valid in lane 0) of every lane's p: five
/// shuffle levels in a fixed order. Every lane of the warp must call it.
template <class P, class Combine>
__device__ __forceinline__ P warp_sum(P p, Combine combine) {
#pragma unroll
  for (int off = 16; off > 0; off /= 2) combine(p, shuffle_down(p, off));
  return p;
}

/// The block's combined partial (valid in thread 0) of every thread's p, for
/// blocks of kBlock threads (a multiple of 32, at most 1024): combine(a, b)
/// adds b into a, `empty` adds nothing, sh is kBlock / 32 partials of shared
/// memory. Every thread of the block must call it.
template <int kBlock, class P, class Combine>
__device__ P block_sum(P p, const P& empty, P* sh, Combine combine) {
  static_assert(kBlock % 32 == 0 && kBlock <= 1024);
  constexpr int kWarps = kBlock / 32;
  p = warp_sum(p, combine);
  const int warp = int(threadIdx.x) / 32, lane = int(threadIdx.x) % 32;
  if (lane == 0) sh[warp] = p;
  __syncthreads();
  if (warp != 0) return p;
  p = lane < kWarps ? sh[lane] : empty;
  return warp_sum(p, combine);
}

}  // namespace tissue::gpu
