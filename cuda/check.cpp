#include "cuda/check.hpp"

#include <fmt/format.h>

#include <atomic>
#include <string>

#include "cuda/device_array.hpp"

namespace tissue::gpu {

void throw_cuda_error(cudaError_t err, const char* expr, const char* file, int line) {
  throw CudaError(fmt::format("{}:{}: CUDA error {} ({}) in {}", file, line, cudaGetErrorName(err),
                              cudaGetErrorString(err), expr));
}

}  // namespace tissue::gpu

namespace tissue::gpu {
namespace {

std::atomic<std::size_t> g_held{0};
std::atomic<std::size_t> g_limit{0};

std::string mib(std::size_t bytes) { return fmt::format("{:.1f} MiB", double(bytes) / (1024.0 * 1024.0)); }

}  // namespace

void* device_allocate(std::size_t bytes) {
  const std::size_t held = g_held.load(), limit = g_limit.load();
  if (limit > 0 && held + bytes > limit)
    throw OutOfDeviceMemory(fmt::format(
        "out of GPU memory: an array of {} ({} bytes) on top of the {} the cuda backend holds exceeds the limit of {} "
        "set by the host (set_device_memory_limit)",
        mib(bytes), bytes, mib(held), mib(limit)));
  void* p = nullptr;
  const cudaError_t err = cudaMalloc(&p, bytes);
  if (err == cudaErrorMemoryAllocation) {
    (void)cudaGetLastError();  // clears the sticky-free allocation error
    std::size_t free = 0, total = 0;
    cudaMemGetInfo(&free, &total);
    throw OutOfDeviceMemory(
        fmt::format("out of GPU memory: an array of {} ({} bytes) on top of the {} the cuda backend holds; the GPU has "
                    "{} free of {}",
                    mib(bytes), bytes, mib(held), mib(free), mib(total)));
  }
  if (err != cudaSuccess) throw_cuda_error(err, "cudaMalloc", __FILE__, __LINE__);
  g_held += bytes;
  return p;
}

void device_free(void* p, std::size_t bytes) noexcept {
  cudaFree(p);  // no throw from a destructor path
  g_held -= bytes;
}

std::size_t device_bytes_held() { return g_held.load(); }

void set_device_memory_limit(std::size_t bytes) { g_limit = bytes; }

}  // namespace tissue::gpu
