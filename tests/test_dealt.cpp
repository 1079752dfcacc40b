// How the cuda backend's contact merge deals its items to warps
// (cuda/dealt.hpp): a pure function of the thread, checked on the host.
#include <gtest/gtest.h>

#include <vector>

#include "cuda/dealt.hpp"

namespace tissue::gpu {
namespace {

TEST(Dealt, EveryItemOnceRunsInOneWarpNeighbouringRunsInOthers) {
  for (index_t threads : {32, 256, 1792, 3584, 65536}) {
    for (int run : {1, 2, 4, 8, 16, 32}) {
      SCOPED_TRACE(testing::Message() << threads << " threads, runs of " << run);
      const index_t warps = threads / 32;
      std::vector<index_t> thread_of(threads, -1);
      for (index_t t = 0; t < threads; ++t) {
        const index_t i = dealt_item(t, threads, run);
        ASSERT_GE(i, 0);
        ASSERT_LT(i, threads);
        ASSERT_EQ(thread_of[i], -1) << "item " << i << " dealt twice";
        thread_of[i] = t;
      }
      for (index_t i = 0; i + 1 < threads; ++i) {
        const index_t a = thread_of[i], b = thread_of[i + 1];
        if ((i + 1) % run != 0) {  // within a run: the next lane of the same warp
          ASSERT_EQ(b, a + 1) << "item " << i;
        } else if (warps > 1) {  // the next run: the next warp (the first again after the last)
          ASSERT_EQ(b / 32, (a / 32 + 1) % warps) << "item " << i;
        }
      }
    }
  }
  for (index_t t = 0; t < 4096; ++t) EXPECT_EQ(dealt_item(t, 4096, 32), t) << "runs of 32 are the plain order";
}

}  // namespace
}  // namespace tissue::gpu
