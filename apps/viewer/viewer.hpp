// `tissue view <scene>`: the interactive viewer (display loop on the main
// thread, haptic loop on its own) and its headless modes: one picture
// (--screenshot), or the display loop rendering offscreen through EGL for a
// given time (--gl egl --seconds S), which measures the haptic loop beside a
// running display on a machine without X (the GPU machine).
#pragma once

#include <string>

#include "scene/scene.hpp"

namespace tissue::viewer {

struct ViewOptions {
  std::string scene;                     ///< scene file or @kidney (for messages)
  std::string backend, precision, depth; ///< overrides of the scene's solver ("" keeps it)
  std::string device;                    ///< scripted | mouse | phantom; "": mouse, or the scene's tool for pictures
  std::string screenshot;                ///< PNG path: render offscreen after `ticks` ticks, then quit
  long ticks = -1;                       ///< ticks before the picture (< 0: the scripted path's length)
  int width = 960, height = 720;         ///< window or picture (pixels)
  std::string gl;                        ///< window | hidden | egl; "": window, or hidden / egl for pictures
  std::string hide;                      ///< comma-separated: tool, region, overlay
  std::string field = "none";            ///< surface colour: none | displacement | pressure | J (field_view.hpp)
  std::string shading = "smooth";        ///< smooth (per-vertex normals) | flat (per-face)
  std::string mouse_events;              ///< scripted mouse input for pictures (mouse_controller.hpp)
  double seconds = 0;                    ///< close after this long (0: when the window closes; required without one)
  bool repeat = false;                   ///< scripted device: play the path over and over
  bool scalpel = false;                  ///< the first tool is a blade, its button cuts (LiveParams::scalpel)
  double mouse_speed = 0.25;             ///< fastest the mouse moves the tool (m/s)
  double arrow_scale = 0;                ///< force arrow length (m per N); 0: 1.5 x the organ's diagonal
  double fps = 60;                       ///< interactive: most frames per second (the display yields the rest)
  bool realtime = true;                  ///< SCHED_FIFO for the haptic thread (HapticLoop::Options::realtime), as
                                        ///< haptic servo loops run (OpenHaptics' scheduler); falls back when refused
};

/// Runs the viewer on a loaded scene; returns the exit code. Throws for bad
/// options, scene, GL or device errors (messages name what failed).
int run_view(const ViewOptions& o, scene::Scene scene);

}  // namespace tissue::viewer
