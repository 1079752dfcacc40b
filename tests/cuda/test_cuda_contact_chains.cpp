// The contact stage's chains timed alone (cuda/contact_chains.cu, the bench's
// contact_chains row): what they time is a real contact -- both triangles
// pass the stage's test, the sweeps propose the corrections core's sweep
// proposes on the host, the merges are core's on the host -- and each part
// takes cycles in proportion to its work.
#include <gtest/gtest.h>

#include <cstdio>

#include "backends/registry.hpp"
#include "cuda/cuda_backend.hpp"
#include "tests/cuda/cuda_test_support.hpp"

namespace tissue::cuda_test {
namespace {

void expect_a_real_contact(const CudaContactChains& c, double apart) {
  EXPECT_TRUE(c.touching);
  // a 2 mm probe 0.5 mm deep: corners pushed out of the tip, and a face moved back by a few tenths of a mm
  EXPECT_GT(c.pushed_dx, 1e-4);
  EXPECT_LT(c.pushed_dx, 1e-3);
  EXPECT_GT(c.face_dx, 1e-4);
  EXPECT_LT(c.face_dx, 1e-3);
  // the lane groups' proposals are core's (to rounding: docs/cuda.md, "Float division and square root")
  EXPECT_LE(c.pushed_apart, apart * c.pushed_dx);
  EXPECT_LE(c.face_apart, apart * c.face_dx);
  for (int m = 0; m < 3; ++m) {
    // proposals of 0.104 mm within 17 degrees of each other: at least the longest, at most their sum
    EXPECT_GE(c.merged_dx[m], 1.04e-4 * (1 - 1e-5)) << c.merge_counts[m];
    EXPECT_LE(c.merged_dx[m], c.merge_counts[m] * 1.05e-4) << c.merge_counts[m];
    EXPECT_GT(c.merge_cycles[m], 0);
  }
  EXPECT_LE(c.merged_apart, apart * 1.04e-4);  // the merges are core's on the host, to rounding
  EXPECT_GT(c.clock_mhz, 100);
  EXPECT_GT(c.test_cycles, 0);
  // sweeping a touching triangle does far more than testing it, and node contact then face contact (two
  // deepest-point searches) more than face contact alone
  EXPECT_GT(c.sweep_face_cycles, 2 * c.test_cycles);
  EXPECT_GT(c.sweep_pushed_cycles, c.sweep_face_cycles);
}

TEST(ContactChains, TimeARealContactInBothPrecisions) {
  SKIP_WITHOUT_GPU();
  for (Precision p : {Precision::Float, Precision::Double}) {
    SCOPED_TRACE(p == Precision::Float ? "float" : "double");
    const CudaContactChains c = cuda_contact_chains(p, 200);
    std::printf(
        "[measured] %s at %.0f MHz, cycles: test %.0f, sweep corners inside %.0f, face only %.0f, merge "
        "3/6/8 %.0f/%.0f/%.0f; corrections %.3g / %.3g m\n",
        p == Precision::Float ? "float" : "double", c.clock_mhz, c.test_cycles, c.sweep_pushed_cycles,
        c.sweep_face_cycles, c.merge_cycles[0], c.merge_cycles[1], c.merge_cycles[2], c.pushed_dx, c.face_dx);
    expect_a_real_contact(c, p == Precision::Float ? 1e-4 : 1e-12);
  }
}

TEST(ContactChains, BenchRowNamesEachPart) {
  SKIP_WITHOUT_GPU();
  const auto times = contact_chain_times("cuda", Precision::Float);
  const auto value = [&](const std::string& name) {
    for (const auto& [n, v] : times)
      if (n == name) return v;
    ADD_FAILURE() << "no " << name;
    return 0.0;
  };
  const double clock = value("clock_mhz");
  ASSERT_GT(clock, 0);
  for (const char* part : {"test", "sweep_corners_inside", "sweep_face_only", "merge_3", "merge_6", "merge_8"})
    EXPECT_NEAR(value(std::string(part) + "_us"), value(std::string(part) + "_cycles") / clock, 1e-9) << part;
  EXPECT_NEAR(value("chain_per_step_us"), value("test_us") + value("sweep_corners_inside_us") + value("merge_6_us"),
              1e-9);
  EXPECT_TRUE(contact_chain_times("cpu", Precision::Float).empty());
}

}  // namespace
}  // namespace tissue::cuda_test
