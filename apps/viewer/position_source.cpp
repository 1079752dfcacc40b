#include "apps/viewer/position_source.hpp"

#include <fmt/format.h>

#include <stdexcept>
#include <vector>

namespace tissue::viewer {
namespace {

/// Host backends: write_positions into a host array, then glBufferSubData.
class HostPositions : public PositionSource {
 public:
  explicit HostPositions(Renderer& r) : renderer_(r), staging_(3 * size_t(r.n_nodes())) {}
  void update(HapticLoop& loop) override {
    if (post_positions(loop, staging_.data(), renderer_.n_nodes())) renderer_.upload_positions(staging_.data());
  }
  std::string path() const override { return "host: write_positions -> glBufferSubData"; }

 private:
  Renderer& renderer_;
  std::vector<float> staging_;
};

}  // namespace

bool post_positions(HapticLoop& loop, float* dst, index_t n_nodes) {
  bool wrote = false;
  loop.post([&](Engine& sim) {
        if (sim.model->n_nodes != n_nodes) return;
        sim.backend->write_positions(dst);
        wrote = true;
      }).get();
  return wrote;
}

std::unique_ptr<PositionSource> make_position_source(Renderer& renderer, const std::string& backend) {
  if (backend == "cuda") {
#if defined(TISSUE_VIEWER_CUDA_GL)
    return make_cuda_position_source(renderer);
#else
    throw std::runtime_error(
        "tissue view: this build has no CUDA-OpenGL path (configure with a CUDA toolkit, TISSUE_WITH_CUDA=AUTO/ON)");
#endif
  }
  return std::make_unique<HostPositions>(renderer);
}

}  // namespace tissue::viewer
