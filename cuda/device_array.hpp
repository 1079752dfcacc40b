// RAII ownership of device memory, pinned host memory, streams and events,
// and the one place where host<->device copies are made (and counted).
// DeviceArray is the single owning array type of the cuda backend; kernels
// never see it, only the raw pointers of views (cuda/views.hpp).
#pragma once

#include <cuda_runtime.h>

#include <cstddef>
#include <cstdint>
#include <utility>

#include "core/backend.hpp"
#include "cuda/check.hpp"

namespace tissue::gpu {

/// The GPU memory the cuda backend could not get. what() names the bytes
/// asked for, the bytes its arrays already hold, and the GPU's free and
/// total memory (or the limit set).
struct OutOfDeviceMemory : CudaError {
  using CudaError::CudaError;
};

/// cudaMalloc of `bytes` through the backend's accounting: throws
/// OutOfDeviceMemory when the GPU (or the limit) cannot hold it.
void* device_allocate(std::size_t bytes);
/// cudaFree of device_allocate's memory of `bytes` (noexcept).
void device_free(void* p, std::size_t bytes) noexcept;
/// Bytes the cuda backend's arrays hold now (all backends of the process).
std::size_t device_bytes_held();
/// Caps the bytes the cuda backend's arrays may hold together (0: no cap
/// but the GPU's own); a host that shares the GPU with its renderer sets it.
void set_device_memory_limit(std::size_t bytes);

/// One device allocation cut into `slots` equal slots of `stride` bytes, one
/// per scene of a group stepped as one (cuda/scene_group.hpp). While a
/// thread holds a SlotScope, device_allocate on that thread takes its
/// arrays from the slot in turn (each aligned to 256 bytes) instead of
/// cudaMalloc; scenes of one model then allocate the same arrays at the
/// same offsets of their slots, so that scene k's array is scene 0's moved
/// by k strides. An array that no longer fits its slot is allocated apart
/// (that scene is then stepped alone). device_free of slot memory frees
/// nothing: the arena is freed whole. Move-only; the bytes are counted
/// (device_bytes_held) once, at construction.
class SceneArena {
 public:
  SceneArena(int slots, std::size_t stride);
  SceneArena(const SceneArena&) = delete;
  SceneArena& operator=(const SceneArena&) = delete;
  ~SceneArena();
  int slots() const { return slots_; }
  std::size_t stride() const { return stride_; }
  char* slot(int k) const { return base_ + std::size_t(k) * stride_; }

  /// Places the calling thread's device allocations in slot k until it ends.
  class SlotScope {
   public:
    SlotScope(const SceneArena& arena, int k);
    SlotScope(const SlotScope&) = delete;
    SlotScope& operator=(const SlotScope&) = delete;
    ~SlotScope();

   private:
    char *saved_begin_, *saved_cursor_, *saved_end_;
  };

 private:
  char* base_ = nullptr;
  int slots_ = 0;
  std::size_t stride_ = 0;
};

/// Owns n elements of T in device memory (cudaMalloc); move-only.
/// Contents are uninitialised after allocate().
template <class T>
class DeviceArray {
 public:
  DeviceArray() = default;
  explicit DeviceArray(std::size_t n) { allocate(n); }
  DeviceArray(const DeviceArray&) = delete;
  DeviceArray& operator=(const DeviceArray&) = delete;
  DeviceArray(DeviceArray&& o) noexcept : ptr_(std::exchange(o.ptr_, nullptr)), n_(std::exchange(o.n_, 0)) {}
  DeviceArray& operator=(DeviceArray&& o) noexcept {
    if (this != &o) {
      release();
      ptr_ = std::exchange(o.ptr_, nullptr);
      n_ = std::exchange(o.n_, 0);
    }
    return *this;
  }
  ~DeviceArray() { release(); }

  /// Frees the old storage and allocates n elements (n = 0: none). Out of
  /// memory (the GPU's, or the limit of set_device_memory_limit) throws
  /// OutOfDeviceMemory naming the bytes asked, held and free.
  void allocate(std::size_t n) {
    release();
    if (n > 0) ptr_ = static_cast<T*>(device_allocate(n * sizeof(T)));
    n_ = n;
  }
  /// Sets every byte of the array to `byte` (asynchronous on stream).
  void fill_bytes(int byte, cudaStream_t stream) {
    if (n_ > 0) CUDA_CHECK(cudaMemsetAsync(ptr_, byte, bytes(), stream));
  }

  T* data() { return ptr_; }
  const T* data() const { return ptr_; }
  std::size_t size() const { return n_; }
  std::size_t bytes() const { return n_ * sizeof(T); }

 private:
  void release() noexcept {
    if (ptr_) device_free(ptr_, n_ * sizeof(T));  // no throw from a destructor path
    ptr_ = nullptr;
    n_ = 0;
  }
  T* ptr_ = nullptr;
  std::size_t n_ = 0;
};

/// Owns n elements of T in page-locked host memory (cudaMallocHost), the
/// staging area for the small per-tick copies; move-only.
template <class T>
class PinnedArray {
 public:
  PinnedArray() = default;
  PinnedArray(const PinnedArray&) = delete;
  PinnedArray& operator=(const PinnedArray&) = delete;
  ~PinnedArray() { release(); }

  /// n elements (0: none), mapped into the device's address space: a kernel
  /// may write them (device()) and the host read them once the kernel is
  /// known to have finished, with no copy.
  void allocate(std::size_t n) {
    release();
    if (n > 0) {
      CUDA_CHECK(cudaHostAlloc(reinterpret_cast<void**>(&ptr_), n * sizeof(T), cudaHostAllocMapped));
      CUDA_CHECK(cudaHostGetDevicePointer(reinterpret_cast<void**>(&device_), ptr_, 0));
    }
    n_ = n;
  }
  T* data() { return ptr_; }
  /// The same memory as a device pointer (written over the bus).
  T* device() { return device_; }
  T& operator[](std::size_t i) { return ptr_[i]; }
  std::size_t size() const { return n_; }

 private:
  void release() noexcept {
    if (ptr_) cudaFreeHost(ptr_);
    ptr_ = nullptr;
    device_ = nullptr;
    n_ = 0;
  }
  T* ptr_ = nullptr;
  T* device_ = nullptr;
  std::size_t n_ = 0;
};

/// Owns a non-blocking CUDA stream.
class Stream {
 public:
  Stream() { CUDA_CHECK(cudaStreamCreateWithFlags(&s_, cudaStreamNonBlocking)); }
  Stream(const Stream&) = delete;
  Stream& operator=(const Stream&) = delete;
  ~Stream() { cudaStreamDestroy(s_); }
  cudaStream_t get() const { return s_; }
  void sync() const { CUDA_CHECK(cudaStreamSynchronize(s_)); }

 private:
  cudaStream_t s_ = nullptr;
};

/// Owns a CUDA event (timing enabled).
class Event {
 public:
  Event() { CUDA_CHECK(cudaEventCreate(&e_)); }
  Event(const Event&) = delete;
  Event& operator=(const Event&) = delete;
  ~Event() { cudaEventDestroy(e_); }
  cudaEvent_t get() const { return e_; }
  void record(cudaStream_t s) { CUDA_CHECK(cudaEventRecord(e_, s)); }
  void sync() const { CUDA_CHECK(cudaEventSynchronize(e_)); }
  /// Milliseconds from `start` to this event (both recorded and complete).
  float since(const Event& start) const {
    float ms = 0;
    CUDA_CHECK(cudaEventElapsedTime(&ms, start.e_, e_));
    return ms;
  }

 private:
  cudaEvent_t e_ = nullptr;
};

/// Makes and counts every host<->device copy of a backend (calls and bytes).
/// Device->host copies are synchronous with respect to the stream (the
/// caller reads the result next). Host->device copies come in two kinds:
/// to_device() is asynchronous and its (pinned) source must stay valid until
/// the stream reaches it (the backend guards its staging with an event);
/// to_device_now() waits for the copy, for pageable sources.
class Transfers {
 public:
  void to_device(void* dst, const void* src, std::size_t bytes, cudaStream_t s) {
    if (bytes == 0) return;
    CUDA_CHECK(cudaMemcpyAsync(dst, src, bytes, cudaMemcpyHostToDevice, s));
    count_to_device(bytes);
  }
  void to_device_now(void* dst, const void* src, std::size_t bytes, cudaStream_t s) {
    to_device(dst, src, bytes, s);
    CUDA_CHECK(cudaStreamSynchronize(s));
  }
  void to_host(void* dst, const void* src, std::size_t bytes, cudaStream_t s) {
    if (bytes == 0) return;
    CUDA_CHECK(cudaMemcpyAsync(dst, src, bytes, cudaMemcpyDeviceToHost, s));
    CUDA_CHECK(cudaStreamSynchronize(s));
    count_to_host(bytes);
  }
  /// Counts a copy made elsewhere (a graph's memcpy node).
  void count_to_device(std::size_t bytes) {
    ++c_.h2d;
    c_.h2d_bytes += bytes;
  }
  void count_to_host(std::size_t bytes) {
    ++c_.d2h;
    c_.d2h_bytes += bytes;
  }
  const TransferCounters& counters() const { return c_; }

 private:
  TransferCounters c_;
};

}  // namespace tissue::gpu
