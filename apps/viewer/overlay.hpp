// The Dear ImGui overlay: what runs (backend, precision, GL, how positions
// reach the vertex buffer), how fast (TLED steps/s, haptic rate, tick
// percentiles and jitter, late ticks), what the tool feels (force, contact,
// region size), and controls for E, nu, region depth and precision that the
// haptic loop applies between ticks (the tools' friction live, without a
// rebuild); the field the surface is coloured by
// with its legend, and each tool's force over the last seconds. Uses Debian's libimgui (core) with the
// GLFW and OpenGL 3 backends compiled from libimgui-dev's example sources;
// without a GLFW window (EGL) it feeds ImGui the display size itself.
#pragma once

#include <optional>
#include <string>

#include "apps/viewer/field_view.hpp"
#include "haptics/haptic_loop.hpp"

struct GLFWwindow;

namespace tissue::viewer {

/// Facts that do not change every frame.
struct OverlayFacts {
  std::string backend, device_name, gl, positions;
  index_t n_nodes = 0, n_elems = 0, n_tris = 0;
  bool uniform_material = true;  ///< false: several materials; E/nu apply to all
};

/// What the display shows besides the snapshot: the surface's field (with
/// its range, for the legend) and each tool's recent force (for the plot).
struct DisplayState {
  const NodeField* field = nullptr;     ///< null or kind None: the organ's colour, no legend
  const ForceHistory* forces = nullptr; ///< null: no plot
  bool smooth = true;                   ///< the surface is shaded smoothly (per-vertex normals)
};

/// What the user asked for in this frame.
struct OverlayActions {
  std::optional<LiveParams> apply;  ///< rebuild with these parameters
  bool reset = false;               ///< rebuild with the running parameters (tissue at rest)
  std::optional<FieldKind> field;   ///< colour the surface by this field from now on
  std::optional<double> friction;   ///< every tool's friction coefficient, live (HapticLoop::set_friction)
  std::optional<bool> smooth;       ///< shade the surface smoothly (true) or flat from now on
  bool scalpel = false;             ///< toggle the scalpel (a rebuild: LiveParams::scalpel)
};

class Overlay {
 public:
  /// `window` null: no GLFW input (headless pictures). GL context current.
  explicit Overlay(GLFWwindow* window);
  ~Overlay();
  Overlay(const Overlay&) = delete;
  Overlay& operator=(const Overlay&) = delete;

  /// Builds and renders the panel into the bound framebuffer (w x h pixels).
  OverlayActions draw(const OverlayFacts& facts, const HapticSnapshot& snap, const std::string& status, int w, int h,
                      const DisplayState& display = {});
  /// True while ImGui uses the mouse (the tool and camera must not).
  bool wants_mouse() const;
  /// The panel's last rectangle (pixels: x0, y0, x1, y1).
  void panel_rect(float r[4]) const;

 private:
  /// The rows of what runs, how fast and what each tool feels.
  static void show_status(const OverlayFacts& f, const HapticSnapshot& s);
  /// The material controls (E, nu, fibre, Prony) on edit_; true when one changed.
  bool edit_material(const OverlayFacts& f);
  /// The region and precision controls on edit_; true when one changed.
  bool edit_region_and_precision();
  /// The tools' friction slider (applied live, no rebuild): the new value when it moved.
  std::optional<double> edit_friction(const HapticSnapshot& s);

  bool glfw_ = false;
  bool editing_ = false;  ///< the controls hold the user's values, not the running ones
  LiveParams edit_;
  std::optional<double> friction_sent_;  ///< the slider's last value until the snapshot carries it
  float rect_[4] = {0, 0, 0, 0};
};

}  // namespace tissue::viewer
