#include "cuda/check.hpp"

#include <fmt/format.h>

namespace tissue::gpu {

void throw_cuda_error(cudaError_t err, const char* expr, const char* file, int line) {
  throw CudaError(fmt::format("{}:{}: CUDA error {} ({}) in {}", file, line, cudaGetErrorName(err),
                              cudaGetErrorString(err), expr));
}

}  // namespace tissue::gpu
