#include "apps/viewer/mouse_controller.hpp"

#include <fmt/format.h>

#include <cmath>
#include <cstdio>
#include <sstream>
#include <stdexcept>

namespace tissue::viewer {

MouseController::MouseController(Camera& camera, MouseDevice& device, double wheel_step)
    : camera_(camera), device_(device), wheel_step_(wheel_step) {}

void MouseController::press(MouseButton b, double x, double y) {
  dragging_[int(b)] = true;
  last_x_ = x;
  last_y_ = y;
  if (b == MouseButton::Left) {
    drag_tip_ = device_.target();
    drag_anchor_ = camera_.unproject_on_plane(x, y, drag_tip_);
  }
  if (b == MouseButton::Right) device_.set_grasp(true);
}

void MouseController::release(MouseButton b) {
  dragging_[int(b)] = false;
  if (b == MouseButton::Left) dragging_[int(MouseButton::Orbit)] = false;  // shift may be up by now
  if (b == MouseButton::Right) device_.set_grasp(false);
}

void MouseController::move(double x, double y) {
  const double dx = x - last_x_, dy = y - last_y_;
  last_x_ = x;
  last_y_ = y;
  if (dragging_[int(MouseButton::Left)])
    device_.set_target(drag_tip_ + (camera_.unproject_on_plane(x, y, drag_tip_) - drag_anchor_));
  if (dragging_[int(MouseButton::Orbit)]) camera_.orbit(-0.006 * dx, -0.006 * dy);
  if (dragging_[int(MouseButton::Middle)]) camera_.pan(dx, dy);
}

void MouseController::wheel(double notches, bool shift) {
  if (shift) {
    camera_.distance *= std::pow(0.9, notches);
    return;
  }
  // along the eye's ray through the tip: the tool moves into the screen where it is seen
  const Vec3<double> tip = device_.target(), ray = tip - camera_.eye();
  const Vec3<double> dir = norm(ray) > 0 ? (1.0 / norm(ray)) * ray : camera_.forward;
  device_.set_target(tip + (notches * wheel_step_) * dir);
}

std::vector<MouseEvent> parse_mouse_events(const std::string& text) {
  std::vector<MouseEvent> events;
  std::stringstream all(text);
  std::string item;
  while (std::getline(all, item, ';')) {
    if (item.find_first_not_of(" \t") == std::string::npos) continue;
    MouseEvent e;
    char kind[16] = {0};
    int used = 0;
    const auto bad = [&](const char* rule) {
      return std::invalid_argument(fmt::format("--mouse-events: '{}': {}", item, rule));
    };
    if (std::sscanf(item.c_str(), " %ld %15s %n", &e.tick, kind, &used) < 2) throw bad("expected '<tick> <kind> ...'");
    const char* rest = item.c_str() + used;
    const std::string k = kind;
    int tail = 0;
    if (k == "wheel") {
      e.kind = MouseEvent::Kind::Wheel;
      if (std::sscanf(rest, "%lf %n", &e.a, &tail) != 1) throw bad("expected 'wheel <notches>'");
    } else if (k == "drag") {
      e.kind = MouseEvent::Kind::Drag;
      if (std::sscanf(rest, "%lf , %lf %lf , %lf %n", &e.a, &e.b, &e.c, &e.d, &tail) != 4)
        throw bad("expected 'drag <x0>,<y0> <x1>,<y1>' in pixels");
    } else if (k == "orbit") {
      e.kind = MouseEvent::Kind::Orbit;
      if (std::sscanf(rest, "%lf , %lf %n", &e.a, &e.b, &tail) != 2) throw bad("expected 'orbit <dx>,<dy>' in pixels");
    } else if (k == "grasp" || k == "release") {
      e.kind = k == "grasp" ? MouseEvent::Kind::Grasp : MouseEvent::Kind::Release;
      std::sscanf(rest, " %n", &tail);
    } else {
      throw bad("the kind is none of wheel, drag, orbit, grasp, release");
    }
    if (rest[tail] != '\0') throw bad("unexpected text after the event");
    if (e.tick < 0) throw bad("the tick must be >= 0");
    if (!events.empty() && e.tick < events.back().tick) throw bad("events must come in tick order");
    events.push_back(e);
  }
  return events;
}

void apply(MouseController& c, const MouseEvent& e) {
  switch (e.kind) {
    case MouseEvent::Kind::Wheel:
      c.wheel(e.a, false);
      break;
    case MouseEvent::Kind::Drag:
      c.press(MouseButton::Left, e.a, e.b);
      c.move(0.5 * (e.a + e.c), 0.5 * (e.b + e.d));
      c.move(e.c, e.d);
      c.release(MouseButton::Left);
      break;
    case MouseEvent::Kind::Orbit:
      c.press(MouseButton::Orbit, 0, 0);
      c.move(e.a, e.b);
      c.release(MouseButton::Orbit);
      break;
    case MouseEvent::Kind::Grasp:
      c.press(MouseButton::Right, 0, 0);
      break;
    case MouseEvent::Kind::Release:
      c.release(MouseButton::Right);
      break;
  }
}

}  // namespace tissue::viewer
