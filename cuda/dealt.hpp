// How a launch deals its items to its warps (cuda/launch.cuh dealt_index):
// a pure function of the thread, kept apart from the kernels so that the
// host tests can check it (tests/test_dealt.cpp).
#pragma once

#include "core/hd.hpp"

namespace tissue::gpu {

/// The item of thread t of a launch of `threads` threads (whole warps of
/// 32) when its items are dealt to the warps in runs of `run` (a divisor of
/// 32): run r (items r run .. r run + run - 1) goes to warp r mod W of the
/// W = threads / 32 warps, lanes (r div W) run .. + run - 1. Neighbouring
/// runs land in different warps, a run's items in neighbouring lanes of one.
/// Covers [0, threads) once; run = 32 is the plain t.
TISSUE_HD index_t dealt_item(index_t t, index_t threads, int run) {
  const index_t lane = t % 32, warp = t / 32, warps = threads / 32;
  return ((lane / run) * warps + warp) * run + lane % run;
}

}  // namespace tissue::gpu
