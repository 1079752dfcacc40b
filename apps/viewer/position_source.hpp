// Feeds the renderer's tissue vertex buffer from the backend. The display
// thread never touches the backend itself: it posts Backend::write_positions
// to the haptic loop, which runs it between two ticks.
//  - host backends (cpu): write_positions into a host staging array, then
//    glBufferSubData;
//  - the cuda backend: the vertex buffer is registered with CUDA
//    (cudaGraphicsGLRegisterBuffer); each frame maps it
//    (cudaGraphicsMapResources, cudaGraphicsResourceGetMappedPointer) and
//    posts write_positions(device pointer): a kernel writes X + u straight
//    into the buffer, nothing crosses the host. Built when TISSUE_HAVE_CUDA
//    (apps/viewer/position_source_cuda.cpp). Should registration fail (a GL
//    context on another GPU, or Mesa), it falls back to a device staging
//    buffer copied through the host, and says so.
#pragma once

#include <memory>
#include <string>

#include "apps/viewer/renderer.hpp"
#include "haptics/haptic_loop.hpp"

namespace tissue::viewer {

class PositionSource {
 public:
  virtual ~PositionSource() = default;
  /// Writes the current deformed positions into the renderer's buffer
  /// (display thread, GL context current; waits for the haptic thread).
  virtual void update(HapticLoop& loop) = 0;
  /// How positions travel, for the overlay and reports.
  virtual std::string path() const = 0;
};

/// Posts write_positions(dst) to the haptic thread and waits for it; it
/// writes only while the mesh still has `n_nodes` nodes, the size `dst` was
/// made for (a cut that lands first leaves the frame as it was: the display
/// then makes its buffers anew). Returns whether it wrote.
bool post_positions(HapticLoop& loop, float* dst, index_t n_nodes);

/// The source for a backend by name ("cpu", "cuda"); GL context current.
std::unique_ptr<PositionSource> make_position_source(Renderer& renderer, const std::string& backend);

#if defined(TISSUE_VIEWER_CUDA_GL)
/// CUDA-OpenGL interop source (position_source_cuda.cpp).
std::unique_ptr<PositionSource> make_cuda_position_source(Renderer& renderer);
#endif

}  // namespace tissue::viewer
