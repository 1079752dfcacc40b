// The CUDA-OpenGL interop path of position_source.hpp (built only with
// TISSUE_HAVE_CUDA). Compiled as C++ against the CUDA runtime: the kernel
// that writes the buffer is the cuda backend's write_positions.
#include <GL/glew.h>
// cuda_gl_interop.h needs the GL types declared first
#include <cuda_gl_interop.h>
#include <cuda_runtime.h>
#include <fmt/format.h>

#include <stdexcept>
#include <vector>

#include "apps/viewer/position_source.hpp"

namespace tissue::viewer {
namespace {

void check(cudaError_t e, const char* what) {
  if (e != cudaSuccess)
    throw std::runtime_error(fmt::format("tissue view: {} failed: {} ({})", what, cudaGetErrorString(e),
                                         cudaGetErrorName(e)));
}

/// The vertex buffer registered with CUDA and written by the backend's kernel.
class InteropPositions : public PositionSource {
 public:
  explicit InteropPositions(Renderer& r) : n_nodes_(r.n_nodes()), bytes_(3 * sizeof(float) * size_t(r.n_nodes())) {
    check(cudaGraphicsGLRegisterBuffer(&resource_, r.position_buffer(), cudaGraphicsRegisterFlagsWriteDiscard),
          "cudaGraphicsGLRegisterBuffer");
  }
  ~InteropPositions() override { cudaGraphicsUnregisterResource(resource_); }

  void update(HapticLoop& loop) override {
    check(cudaGraphicsMapResources(1, &resource_, 0), "cudaGraphicsMapResources");
    void* ptr = nullptr;
    size_t size = 0;
    try {
      check(cudaGraphicsResourceGetMappedPointer(&ptr, &size, resource_), "cudaGraphicsResourceGetMappedPointer");
      if (size < bytes_)
        throw std::runtime_error(fmt::format("tissue view: mapped vertex buffer holds {} bytes, {} needed", size, bytes_));
      float* dst = static_cast<float*>(ptr);
      // the backend's kernel writes X + u into the buffer and synchronises its stream
      post_positions(loop, dst, n_nodes_);
    } catch (...) {
      cudaGraphicsUnmapResources(1, &resource_, 0);
      throw;
    }
    check(cudaGraphicsUnmapResources(1, &resource_, 0), "cudaGraphicsUnmapResources");
  }
  std::string path() const override { return "CUDA-GL interop: write_positions kernel -> mapped VBO (no host copy)"; }

 private:
  cudaGraphicsResource* resource_ = nullptr;
  index_t n_nodes_;
  size_t bytes_;
};

/// Fallback: a device staging array copied through the host.
class StagedPositions : public PositionSource {
 public:
  StagedPositions(Renderer& r, std::string why) : renderer_(r), host_(3 * size_t(r.n_nodes())), why_(std::move(why)) {
    check(cudaMalloc(&device_, host_.size() * sizeof(float)), "cudaMalloc (position staging)");
  }
  ~StagedPositions() override { cudaFree(device_); }
  void update(HapticLoop& loop) override {
    if (!post_positions(loop, device_, renderer_.n_nodes())) return;
    check(cudaMemcpy(host_.data(), device_, host_.size() * sizeof(float), cudaMemcpyDeviceToHost),
          "cudaMemcpy (positions to host)");
    renderer_.upload_positions(host_.data());
  }
  std::string path() const override { return "staged through the host (interop unavailable: " + why_ + ")"; }

 private:
  Renderer& renderer_;
  std::vector<float> host_;
  float* device_ = nullptr;
  std::string why_;
};

}  // namespace

std::unique_ptr<PositionSource> make_cuda_position_source(Renderer& renderer) {
  try {
    return std::make_unique<InteropPositions>(renderer);
  } catch (const std::exception& e) {
    cudaGetLastError();  // clear the registration error
    fmt::print(stderr, "tissue view: warning: {}; copying positions through the host instead\n", e.what());
    return std::make_unique<StagedPositions>(renderer, e.what());
  }
}

}  // namespace tissue::viewer
