// An OpenGL 3.3 core context: a GLFW window (shown for interactive use,
// hidden for offscreen pictures under X, e.g. Xvfb with Mesa), or EGL on a
// GPU without any X server (EGL_EXT_platform_device + a 1x1 pbuffer; the
// pictures are drawn into a framebuffer object either way). GL functions
// come from GLEW.
#pragma once

#include <string>

struct GLFWwindow;

namespace tissue::viewer {

enum class ContextKind {
  Window,        ///< visible GLFW window (needs an X display)
  HiddenWindow,  ///< invisible GLFW window (needs an X display; Xvfb will do)
  Egl,           ///< headless EGL device context (no X)
};

/// Parses "window" | "hidden" | "egl"; throws std::invalid_argument.
ContextKind parse_context_kind(const std::string& s);

class GlContext {
 public:
  /// Creates the context and makes it current on the calling thread; throws
  /// std::runtime_error saying what failed (no display, no GL 3.3, ...).
  GlContext(ContextKind kind, int width, int height, const std::string& title);
  ~GlContext();
  GlContext(const GlContext&) = delete;
  GlContext& operator=(const GlContext&) = delete;

  ContextKind kind() const { return kind_; }
  GLFWwindow* window() const { return window_; }  ///< null for EGL
  bool should_close() const;
  void swap_buffers();
  /// Framebuffer size of the window (pixels); the requested size for EGL.
  void framebuffer_size(int* w, int* h) const;
  std::string renderer() const;  ///< "GL_VERSION | GL_RENDERER"

 private:
  ContextKind kind_;
  GLFWwindow* window_ = nullptr;
  void* egl_display_ = nullptr;
  void* egl_context_ = nullptr;
  void* egl_surface_ = nullptr;
  int width_, height_;
};

}  // namespace tissue::viewer
