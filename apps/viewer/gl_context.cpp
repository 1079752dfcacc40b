#include "apps/viewer/gl_context.hpp"

// clang-format off
#include <GL/glew.h>
#include <GLFW/glfw3.h>
#include <EGL/egl.h>
#include <EGL/eglext.h>
// clang-format on

#include <fmt/format.h>

#include <algorithm>
#include <cstdlib>
#include <stdexcept>
#include <string>

namespace tissue::viewer {
namespace {

void glfw_error(int code, const char* text) { fmt::print(stderr, "tissue view: GLFW error {:#x}: {}\n", code, text); }

/// GLEW after a context is current. With an EGL context GLEW's GLX part
/// reports GLEW_ERROR_NO_GLX_DISPLAY after loading every core function; that
/// is harmless, so only a missing core 3.3 entry point counts as failure.
void init_glew() {
  glewExperimental = GL_TRUE;
  const GLenum e = glewInit();
  if (e != GLEW_OK && e != GLEW_ERROR_NO_GLX_DISPLAY)
    throw std::runtime_error(fmt::format("tissue view: glewInit failed: {}",
                                         reinterpret_cast<const char*>(glewGetErrorString(e))));
  if (!glGenVertexArrays || !glGenFramebuffers || !glCreateShader)
    throw std::runtime_error("tissue view: the OpenGL context lacks OpenGL 3.3 core functions");
  glGetError();  // glewInit may leave GL_INVALID_ENUM behind on core profiles
}

std::string egl_error(const char* what) { return fmt::format("tissue view: EGL: {} failed (error {:#x})", what, eglGetError()); }

}  // namespace

ContextKind parse_context_kind(const std::string& s) {
  if (s == "window") return ContextKind::Window;
  if (s == "hidden") return ContextKind::HiddenWindow;
  if (s == "egl") return ContextKind::Egl;
  throw std::invalid_argument(fmt::format("--gl '{}' is none of window, hidden, egl", s));
}

GlContext::GlContext(ContextKind kind, int width, int height, const std::string& title)
    : kind_(kind), width_(width), height_(height) {
  if (kind == ContextKind::Egl) {
    auto query_devices = reinterpret_cast<PFNEGLQUERYDEVICESEXTPROC>(eglGetProcAddress("eglQueryDevicesEXT"));
    auto platform_display =
        reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(eglGetProcAddress("eglGetPlatformDisplayEXT"));
    if (!query_devices || !platform_display)
      throw std::runtime_error("tissue view: EGL lacks EGL_EXT_device_enumeration / EGL_EXT_platform_device");
    EGLDeviceEXT devices[16];
    EGLint n = 0;
    if (!query_devices(16, devices, &n) || n == 0) throw std::runtime_error(egl_error("eglQueryDevicesEXT (no device)"));
    // GPUs first (a CUDA-capable one first of all, for interop), software
    // rasterisers (Mesa's llvmpipe device) last; the first that initialises
    auto query_string =
        reinterpret_cast<PFNEGLQUERYDEVICESTRINGEXTPROC>(eglGetProcAddress("eglQueryDeviceStringEXT"));
    auto rank = [&](EGLDeviceEXT dev) {
      const char* ext = query_string ? query_string(dev, EGL_EXTENSIONS) : nullptr;
      const std::string e = ext ? ext : "";
      if (e.find("EGL_NV_device_cuda") != std::string::npos) return 0;
      if (e.find("EGL_MESA_device_software") != std::string::npos) return 2;
      return 1;
    };
    std::stable_sort(devices, devices + n, [&](EGLDeviceEXT a, EGLDeviceEXT b) { return rank(a) < rank(b); });
    EGLDisplay display = EGL_NO_DISPLAY;
    for (EGLint i = 0; i < n && display == EGL_NO_DISPLAY; ++i) {
      EGLDisplay d = platform_display(EGL_PLATFORM_DEVICE_EXT, devices[i], nullptr);
      EGLint major = 0, minor = 0;
      if (d != EGL_NO_DISPLAY && eglInitialize(d, &major, &minor)) display = d;
    }
    if (display == EGL_NO_DISPLAY) throw std::runtime_error(egl_error("eglInitialize on every device"));
    egl_display_ = display;
    if (!eglBindAPI(EGL_OPENGL_API)) throw std::runtime_error(egl_error("eglBindAPI(EGL_OPENGL_API)"));
    const EGLint config_attr[] = {EGL_SURFACE_TYPE, EGL_PBUFFER_BIT, EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT,
                                  EGL_RED_SIZE,     8,               EGL_GREEN_SIZE,      8,
                                  EGL_BLUE_SIZE,    8,               EGL_DEPTH_SIZE,      24,
                                  EGL_NONE};
    EGLConfig config = nullptr;
    EGLint n_config = 0;
    if (!eglChooseConfig(display, config_attr, &config, 1, &n_config) || n_config == 0)
      throw std::runtime_error(egl_error("eglChooseConfig (pbuffer, OpenGL)"));
    const EGLint pbuffer_attr[] = {EGL_WIDTH, 1, EGL_HEIGHT, 1, EGL_NONE};
    egl_surface_ = eglCreatePbufferSurface(display, config, pbuffer_attr);
    const EGLint context_attr[] = {EGL_CONTEXT_MAJOR_VERSION, 3, EGL_CONTEXT_MINOR_VERSION, 3,
                                   EGL_CONTEXT_OPENGL_PROFILE_MASK, EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT, EGL_NONE};
    egl_context_ = eglCreateContext(display, config, EGL_NO_CONTEXT, context_attr);
    if (!egl_context_) throw std::runtime_error(egl_error("eglCreateContext (OpenGL 3.3 core)"));
    if (!eglMakeCurrent(display, egl_surface_, egl_surface_, egl_context_))
      throw std::runtime_error(egl_error("eglMakeCurrent"));
  } else {
    glfwSetErrorCallback(glfw_error);
    if (!glfwInit())
      throw std::runtime_error(fmt::format(
          "tissue view: GLFW could not initialise (DISPLAY='{}'): run under an X server, e.g. `xvfb-run -a tissue view "
          "...`, or use --gl egl for pictures without one",
          std::getenv("DISPLAY") ? std::getenv("DISPLAY") : ""));
    glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
    glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
    glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
    glfwWindowHint(GLFW_VISIBLE, kind == ContextKind::Window ? GLFW_TRUE : GLFW_FALSE);
    glfwWindowHint(GLFW_SAMPLES, kind == ContextKind::Window ? 4 : 0);
    window_ = glfwCreateWindow(width, height, title.c_str(), nullptr, nullptr);
    if (!window_) {
      glfwTerminate();
      throw std::runtime_error("tissue view: no OpenGL 3.3 core window could be created");
    }
    glfwMakeContextCurrent(window_);
    glfwSwapInterval(1);
  }
  init_glew();
}

GlContext::~GlContext() {
  if (kind_ == ContextKind::Egl) {
    EGLDisplay d = egl_display_;
    eglMakeCurrent(d, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    if (egl_context_) eglDestroyContext(d, egl_context_);
    if (egl_surface_) eglDestroySurface(d, egl_surface_);
    eglTerminate(d);
  } else {
    glfwDestroyWindow(window_);
    glfwTerminate();
  }
}

bool GlContext::should_close() const { return window_ && glfwWindowShouldClose(window_); }

void GlContext::swap_buffers() {
  if (window_) glfwSwapBuffers(window_);
}

void GlContext::framebuffer_size(int* w, int* h) const {
  if (window_) {
    glfwGetFramebufferSize(window_, w, h);
  } else {
    *w = width_;
    *h = height_;
  }
}

std::string GlContext::renderer() const {
  return fmt::format("{} | {}", reinterpret_cast<const char*>(glGetString(GL_VERSION)),
                     reinterpret_cast<const char*>(glGetString(GL_RENDERER)));
}

}  // namespace tissue::viewer
