// An orbit camera and the 4x4 matrix math the renderer needs (no GL here):
// view and projection matrices, projecting a scene point to pixels, and the
// ray through a pixel (for dragging the tool in the view plane).
#pragma once

#include "core/vec.hpp"

namespace tissue::viewer {

/// Column-major 4x4 float matrix, as OpenGL takes it: m[4 * col + row].
struct Mat4 {
  float m[16];
  static Mat4 identity();
};
Mat4 operator*(const Mat4& a, const Mat4& b);

/// Translation, then uniform scale s, then the rotation taking +z to unit
/// `axis`: the model matrix of a glyph (sphere, cylinder, cone) placed at
/// `at`, pointing along `axis`, sized s (m).
Mat4 glyph_matrix(Vec3<double> at, Vec3<double> axis, double s, double length);

/// Camera orbiting `target` at `distance` (m); `forward` (unit) is the
/// viewing direction, `up` (unit, orthogonal to forward) the screen's up.
struct Camera {
  Vec3<double> target = {0, 0, 0};
  double distance = 0.3;
  Vec3<double> forward = {0, 0, -1};
  Vec3<double> up = {0, 1, 0};
  double fov_y = 0.61;  ///< vertical field of view (rad), 35 degrees
  int width = 960, height = 720;  ///< framebuffer (pixels)

  Vec3<double> eye() const { return target - distance * forward; }
  Vec3<double> right() const { return cross(forward, up); }
  Mat4 view() const;
  Mat4 projection() const;

  /// Pixel (x right, y down from the top-left corner) of scene point p; z
  /// receives the depth along forward (m, <= 0 behind the eye).
  void project(Vec3<double> p, double* x, double* y, double* z) const;
  /// Unit direction from the eye through pixel (x, y).
  Vec3<double> ray(double x, double y) const;
  /// The point of the plane through `on`, normal to forward, under pixel (x, y).
  Vec3<double> unproject_on_plane(double x, double y, Vec3<double> on) const;

  /// Turns the view about `up` by yaw and about `right` by pitch (rad).
  void orbit(double yaw, double pitch);
  /// Moves the target by (dx, dy) pixels in the view plane.
  void pan(double dx, double dy);
};

/// A camera framing a box of diagonal `size` around `center`, looking along
/// `look` (unit) turned by `yaw` radians about the world's up (+z), then
/// tilted down by `tilt` radians (the eye rises above the look direction).
Camera frame_camera(Vec3<double> center, double size, Vec3<double> look, double yaw, double tilt, int width,
                    int height);

}  // namespace tissue::viewer
