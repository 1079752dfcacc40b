// Mouse input -> tool and camera, independent of the windowing library (the
// GLFW callbacks and the scripted events of headless runs both call it):
//   left drag     moves the tool tip in the view plane (the plane through the
//                 tip, normal to the viewing direction), relative to where
//                 the drag started;
//   wheel         pushes the tip along the viewing direction (the eye's ray
//                 through the tip, so the tool stays under the cursor; away
//                 from the eye for wheel-up), one `wheel_step` per notch;
//   right button  the grasp button (held: the nodes in contact when it went
//                 down stick to the tool; released: they let go);
//   shift + left drag  orbits the camera about its target (MouseButton::Orbit);
//   middle drag   pans the camera;
//   shift + wheel zooms.
#pragma once

#include <string>
#include <vector>

#include "apps/viewer/camera.hpp"
#include "apps/viewer/mouse_device.hpp"

namespace tissue::viewer {

enum class MouseButton { Left, Right, Middle, Orbit };

class MouseController {
 public:
  /// Both must outlive the controller; wheel_step in m per notch.
  MouseController(Camera& camera, MouseDevice& device, double wheel_step);

  void press(MouseButton b, double x, double y);
  void release(MouseButton b);
  void move(double x, double y);
  void wheel(double notches, bool shift);

 private:
  Camera& camera_;
  MouseDevice& device_;
  double wheel_step_;
  bool dragging_[4] = {false, false, false, false};
  double last_x_ = 0, last_y_ = 0;
  Vec3<double> drag_tip_ = {}, drag_anchor_ = {};
};

/// One scripted mouse event of a headless run, applied before tick `tick`.
struct MouseEvent {
  long tick = 0;
  enum class Kind { Wheel, Drag, Orbit, Grasp, Release } kind = Kind::Wheel;
  double a = 0, b = 0, c = 0, d = 0;  ///< wheel: notches; drag: x0 y0 x1 y1 (pixels); orbit: dx dy (pixels)
};

/// Parses "<tick> wheel <notches>; <tick> drag <x0>,<y0> <x1>,<y1>; <tick> orbit <dx>,<dy>;
/// <tick> grasp; <tick> release" (events in tick order; grasp and release press and
/// release the right button). Throws std::invalid_argument quoting the bad event.
std::vector<MouseEvent> parse_mouse_events(const std::string& text);

/// Plays one event through the controller, as a user would with the mouse.
void apply(MouseController& c, const MouseEvent& e);

}  // namespace tissue::viewer
