#include "cuda/check.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <atomic>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

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

/// The slot this thread allocates from (SceneArena::SlotScope): null when none.
thread_local char* t_slot_begin = nullptr;
thread_local char* t_slot_cursor = nullptr;
thread_local char* t_slot_end = nullptr;

/// Every live arena's [begin, end): device_free leaves their memory alone.
std::mutex g_arenas_mutex;
std::vector<std::pair<char*, char*>> g_arenas;

bool in_arena(const void* p) {
  const char* c = static_cast<const char*>(p);
  std::lock_guard<std::mutex> lock(g_arenas_mutex);
  return std::any_of(g_arenas.begin(), g_arenas.end(), [&](const auto& a) { return c >= a.first && c < a.second; });
}

/// The next 256-byte aligned `bytes` of this thread's slot, or null when none is set or it is full.
void* slot_allocate(std::size_t bytes) {
  if (!t_slot_begin) return nullptr;
  const std::size_t at = (std::size_t(t_slot_cursor - t_slot_begin) + 255) & ~std::size_t(255);
  if (at + bytes > std::size_t(t_slot_end - t_slot_begin)) return nullptr;
  t_slot_cursor = t_slot_begin + at + bytes;
  return t_slot_begin + at;
}

}  // namespace

SceneArena::SceneArena(int slots, std::size_t stride) : slots_(slots), stride_((stride + 255) & ~std::size_t(255)) {
  base_ = static_cast<char*>(device_allocate(std::size_t(slots_) * stride_));
  std::lock_guard<std::mutex> lock(g_arenas_mutex);
  g_arenas.emplace_back(base_, base_ + std::size_t(slots_) * stride_);
}

SceneArena::~SceneArena() {
  {
    std::lock_guard<std::mutex> lock(g_arenas_mutex);
    g_arenas.erase(std::remove(g_arenas.begin(), g_arenas.end(), std::pair{base_, base_ + std::size_t(slots_) * stride_}),
                   g_arenas.end());
  }
  device_free(base_, std::size_t(slots_) * stride_);
}

SceneArena::SlotScope::SlotScope(const SceneArena& arena, int k)
    : saved_begin_(t_slot_begin), saved_cursor_(t_slot_cursor), saved_end_(t_slot_end) {
  t_slot_begin = t_slot_cursor = arena.slot(k);
  t_slot_end = arena.slot(k) + arena.stride();
}

SceneArena::SlotScope::~SlotScope() {
  t_slot_begin = saved_begin_;
  t_slot_cursor = saved_cursor_;
  t_slot_end = saved_end_;
}

void* device_allocate(std::size_t bytes) {
  if (void* p = slot_allocate(bytes)) return p;
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
  if (in_arena(p)) return;  // a slot's array: the arena is freed whole
  cudaFree(p);  // no throw from a destructor path
  g_held -= bytes;
}

std::size_t device_bytes_held() { return g_held.load(); }

void set_device_memory_limit(std::size_t bytes) { g_limit = bytes; }

}  // namespace tissue::gpu
