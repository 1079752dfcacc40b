// One error check for every CUDA runtime call: CUDA_CHECK(expr) throws
// tissue::gpu::CudaError naming the call, the CUDA error and the source file
// and line. Included only by cuda/ sources (it pulls in the CUDA runtime).
#pragma once

#include <cuda_runtime.h>

#include <stdexcept>

namespace tissue::gpu {

/// A CUDA runtime call failed; what() names the call, error, file and line.
struct CudaError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

/// Throws CudaError for err (not cudaSuccess) raised by `expr` at file:line.
[[noreturn]] void throw_cuda_error(cudaError_t err, const char* expr, const char* file, int line);

}  // namespace tissue::gpu

#define CUDA_CHECK(expr)                                                                       \
  do {                                                                                         \
    const cudaError_t tissue_cuda_err_ = (expr);                                               \
    if (tissue_cuda_err_ != cudaSuccess)                                                       \
      ::tissue::gpu::throw_cuda_error(tissue_cuda_err_, #expr, __FILE__, __LINE__);            \
  } while (0)
