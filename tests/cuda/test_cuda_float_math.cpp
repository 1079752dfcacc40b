// The float division and square root of the cuda kernels, as the build chose
// them (TISSUE_CUDA_FAST_FLOAT_MATH): measured on the device against the
// host's IEEE operations, and reported as chosen (docs/cuda.md, "Float
// division and square root").
#include <gtest/gtest.h>

#include <cstdio>

#include "backends/registry.hpp"
#include "cuda/cuda_backend.hpp"
#include "tests/cuda/cuda_test_support.hpp"

namespace tissue::cuda_test {
namespace {

TEST(FloatMath, KernelsDivideAndTakeRootsAsTheBuildSays) {
  SKIP_WITHOUT_GPU();
  const CudaFloatMathProbe p = cuda_probe_float_math();
  std::printf("[measured] %s build, %ld operands: x/y differs from IEEE in %ld (at most %ld ulp), sqrt in %ld "
              "(at most %ld ulp); denormals %s\n",
              cuda_fast_float_math() ? "approximate" : "ieee", long(p.samples), p.div_differ, p.div_ulps_max,
              p.sqrt_differ, p.sqrt_ulps_max, p.flushes_denormals ? "flushed" : "kept");
  ASSERT_EQ(p.samples, index_t(1) << 20);
  EXPECT_EQ(p.flushes_denormals, cuda_fast_float_math());  // -ftz=true comes with the approximate forms
  if (cuda_fast_float_math()) {
    // the approximate forms were asked for: some results must show it, else the flags never reached the kernels
    EXPECT_GT(p.div_differ, 0);
    EXPECT_GT(p.sqrt_differ, 0);
    // x/y with -prec-div=false: 2 ulp, the CUDA C++ Programming Guide's bound (its table of
    // single-precision functions), reached on an H100; sqrtf with -prec-sqrt=false: 1 ulp measured there
    // (these operands), the bound leaving one more
    EXPECT_LE(p.div_ulps_max, 2);
    EXPECT_LE(p.sqrt_ulps_max, 2);
  } else {
    EXPECT_EQ(p.div_differ, 0);
    EXPECT_EQ(p.sqrt_differ, 0);
  }
}

TEST(FloatMath, BackendsReportIt) {
  SKIP_WITHOUT_GPU();
  const auto f = create_backend("cuda", Precision::Float), d = create_backend("cuda", Precision::Double);
  EXPECT_EQ(float_math(*f), cuda_fast_float_math() ? "approximate" : "ieee");
  EXPECT_EQ(float_math(*d), "ieee");  // the flags touch single precision only
  EXPECT_EQ(float_math(*create_backend("cpu", Precision::Float)), "ieee");
  bool listed = false;
  for (const BackendInfo& b : list_backends())
    if (b.name == "cuda") {
      listed = true;
      EXPECT_EQ(b.float_math, cuda_fast_float_math() ? "approximate" : "ieee");
    }
  EXPECT_TRUE(listed);
}

}  // namespace
}  // namespace tissue::cuda_test
