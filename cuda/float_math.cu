// How this build's kernels divide and take square roots in single
// precision (TISSUE_CUDA_FAST_FLOAT_MATH, the top-level CMakeLists.txt), and a
// measurement of it on the device against the host's IEEE operations.
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <stdexcept>
#include <vector>

#include "cuda/cuda_backend.hpp"
#include "cuda/device_array.hpp"
#include "cuda/launch.cuh"

namespace tissue {
namespace gpu {
namespace {

// Compiled with the library's flags, as every kernel that steps the tissue.
__global__ void float_math_kernel(index_t n, const float* a, const float* b, float* quotient, float* root) {
  const index_t i = thread_index();
  if (i >= n) return;
  quotient[i] = a[i] / b[i];
  root[i] = std::sqrt(a[i]);
}

// a * b for a product below the smallest normal float (denormal, or 0 where flushed)
__global__ void denormal_kernel(const float* a, const float* b, float* product) { *product = *a * *b; }

/// Distance in ulps of two finite floats of the same sign.
long ulps_apart(float x, float y) {
  if (std::signbit(x) != std::signbit(y)) return -1;
  return std::labs(long(std::bit_cast<std::int32_t>(x)) - long(std::bit_cast<std::int32_t>(y)));
}

}  // namespace
}  // namespace gpu

bool cuda_fast_float_math() { return TISSUE_CUDA_FAST_FLOAT_MATH != 0; }

CudaFloatMathProbe cuda_probe_float_math(index_t samples) {
  std::string why;
  if (!cuda_available(&why)) throw std::runtime_error("cuda_probe_float_math: " + why);
  if (samples <= 0) throw std::invalid_argument("cuda_probe_float_math: samples must be positive");
  // operands with random mantissas and exponents in [-20, 20] (xorshift64: the same every run)
  std::vector<float> a(samples), b(samples);
  std::uint64_t state = 0x9e3779b97f4a7c15ull;
  const auto next = [&] {
    state ^= state << 13;
    state ^= state >> 7;
    state ^= state << 17;
    return state;
  };
  const auto operand = [&] {
    const std::uint64_t r = next();
    const int exponent = int(r % 41) - 20;
    return std::ldexp(1.0f + float(r >> 40 & 0x7fffff) * 0x1p-23f, exponent);
  };
  for (index_t i = 0; i < samples; ++i) {
    a[i] = operand();
    b[i] = operand();
  }
  gpu::DeviceArray<float> da(samples), db(samples), dq(samples), dr(samples);
  const std::size_t bytes = std::size_t(samples) * sizeof(float);
  CUDA_CHECK(cudaMemcpy(da.data(), a.data(), bytes, cudaMemcpyHostToDevice));
  CUDA_CHECK(cudaMemcpy(db.data(), b.data(), bytes, cudaMemcpyHostToDevice));
  gpu::launch(samples, nullptr, gpu::float_math_kernel, samples, da.data(), db.data(), dq.data(), dr.data());
  std::vector<float> q(samples), r(samples);
  CUDA_CHECK(cudaMemcpy(q.data(), dq.data(), bytes, cudaMemcpyDeviceToHost));
  CUDA_CHECK(cudaMemcpy(r.data(), dr.data(), bytes, cudaMemcpyDeviceToHost));
  CudaFloatMathProbe p;
  p.samples = samples;
  const float tiny[3] = {1e-20f, 1e-20f, -1.0f};  // their product, 1e-40, is a denormal
  float product = -1;
  gpu::DeviceArray<float> dt(3);
  CUDA_CHECK(cudaMemcpy(dt.data(), tiny, sizeof(tiny), cudaMemcpyHostToDevice));
  gpu::launch_blocks(1, 1, nullptr, gpu::denormal_kernel, dt.data(), dt.data() + 1, dt.data() + 2);
  CUDA_CHECK(cudaMemcpy(&product, dt.data() + 2, sizeof(float), cudaMemcpyDeviceToHost));
  p.flushes_denormals = product == 0.0f;
  for (index_t i = 0; i < samples; ++i) {
    const long dq_ulps = gpu::ulps_apart(q[i], a[i] / b[i]), dr_ulps = gpu::ulps_apart(r[i], std::sqrt(a[i]));
    if (dq_ulps < 0 || dr_ulps < 0 || !std::isfinite(q[i]) || !std::isfinite(r[i]))
      throw std::runtime_error("cuda_probe_float_math: a result of the wrong sign or not finite");
    p.div_differ += dq_ulps != 0;
    p.sqrt_differ += dr_ulps != 0;
    p.div_ulps_max = std::max(p.div_ulps_max, dq_ulps);
    p.sqrt_ulps_max = std::max(p.sqrt_ulps_max, dr_ulps);
  }
  return p;
}

}  // namespace tissue
