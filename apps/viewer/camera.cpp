#include "apps/viewer/camera.hpp"

#include <algorithm>
#include <cmath>

namespace tissue::viewer {
namespace {

Vec3<double> unit(Vec3<double> v) {
  const double n = norm(v);
  return n > 0 ? (1.0 / n) * v : Vec3<double>{0, 0, 1};
}

/// Rotation of v about unit axis k by angle a (Rodrigues).
Vec3<double> rotate(Vec3<double> v, Vec3<double> k, double a) {
  const double c = std::cos(a), s = std::sin(a);
  return c * v + s * cross(k, v) + ((1 - c) * dot(k, v)) * k;
}

/// Any unit vector orthogonal to unit d.
Vec3<double> orthogonal(Vec3<double> d) {
  const Vec3<double> a = std::abs(d.x) < 0.9 ? Vec3<double>{1, 0, 0} : Vec3<double>{0, 1, 0};
  return unit(cross(d, a));
}

}  // namespace

Mat4 Mat4::identity() { return {{1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}}; }

Mat4 operator*(const Mat4& a, const Mat4& b) {
  Mat4 c;
  for (int col = 0; col < 4; ++col)
    for (int row = 0; row < 4; ++row) {
      float s = 0;
      for (int k = 0; k < 4; ++k) s += a.m[4 * k + row] * b.m[4 * col + k];
      c.m[4 * col + row] = s;
    }
  return c;
}

Mat4 glyph_matrix(Vec3<double> at, Vec3<double> axis, double s, double length) {
  const Vec3<double> z = unit(axis), x = orthogonal(z), y = cross(z, x);
  Mat4 m = Mat4::identity();
  for (int r = 0; r < 3; ++r) {
    m.m[0 + r] = float(s * x[r]);
    m.m[4 + r] = float(s * y[r]);
    m.m[8 + r] = float(length * z[r]);
    m.m[12 + r] = float(at[r]);
  }
  return m;
}

Mat4 Camera::view() const {
  const Vec3<double> f = forward, r = right(), u = up, e = eye();
  Mat4 v = Mat4::identity();
  for (int c = 0; c < 3; ++c) {
    v.m[4 * c + 0] = float(r[c]);
    v.m[4 * c + 1] = float(u[c]);
    v.m[4 * c + 2] = float(-f[c]);
  }
  v.m[12] = float(-dot(r, e));
  v.m[13] = float(-dot(u, e));
  v.m[14] = float(dot(f, e));
  return v;
}

Mat4 Camera::projection() const {
  const double aspect = double(width) / std::max(1, height), t = 1.0 / std::tan(0.5 * fov_y);
  const double n = 0.02 * distance, f = 20.0 * distance;
  Mat4 p{};
  p.m[0] = float(t / aspect);
  p.m[5] = float(t);
  p.m[10] = float(-(f + n) / (f - n));
  p.m[11] = -1;
  p.m[14] = float(-2 * f * n / (f - n));
  return p;
}

void Camera::project(Vec3<double> p, double* x, double* y, double* z) const {
  const Vec3<double> d = p - eye();
  const double depth = dot(d, forward), t = 1.0 / std::tan(0.5 * fov_y);
  const double aspect = double(width) / std::max(1, height);
  const double ndc_x = depth > 0 ? t / aspect * dot(d, right()) / depth : 0;
  const double ndc_y = depth > 0 ? t * dot(d, up) / depth : 0;
  *x = 0.5 * (ndc_x + 1) * width;
  *y = 0.5 * (1 - ndc_y) * height;
  if (z) *z = depth;
}

Vec3<double> Camera::ray(double x, double y) const {
  const double t = std::tan(0.5 * fov_y), aspect = double(width) / std::max(1, height);
  const double ndc_x = 2 * x / width - 1, ndc_y = 1 - 2 * y / height;
  return unit(forward + (ndc_x * t * aspect) * right() + (ndc_y * t) * up);
}

Vec3<double> Camera::unproject_on_plane(double x, double y, Vec3<double> on) const {
  const Vec3<double> e = eye(), r = ray(x, y);
  const double denom = dot(r, forward);
  if (std::abs(denom) < 1e-12) return on;
  return e + (dot(on - e, forward) / denom) * r;
}

void Camera::orbit(double yaw, double pitch) {
  forward = unit(rotate(forward, up, yaw));
  const Vec3<double> r = right();
  forward = unit(rotate(forward, r, pitch));
  up = unit(cross(r, forward));
}

void Camera::pan(double dx, double dy) {
  const double per_pixel = 2 * distance * std::tan(0.5 * fov_y) / std::max(1, height);
  target = target + (-dx * per_pixel) * right() + (dy * per_pixel) * up;
}

Camera frame_camera(Vec3<double> center, double size, Vec3<double> look, double yaw, double tilt, int width,
                    int height) {
  Camera c;
  c.width = width;
  c.height = height;
  c.target = center;
  const Vec3<double> world_up = {0, 0, 1};
  Vec3<double> f = unit(rotate(unit(look), world_up, yaw));
  // tilt about the axis orthogonal to look and to the world's up (or any, if
  // parallel), so that the eye rises above the look direction
  Vec3<double> axis = cross(world_up, f);
  axis = norm(axis) > 1e-6 ? unit(axis) : orthogonal(f);
  f = unit(rotate(f, axis, tilt));
  c.forward = f;
  Vec3<double> up = world_up - dot(world_up, f) * f;
  c.up = norm(up) > 1e-6 ? unit(up) : orthogonal(f);
  c.distance = 0.5 * size / std::tan(0.5 * c.fov_y);
  return c;
}

}  // namespace tissue::viewer
