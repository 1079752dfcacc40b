// Surfaces the meshing tests generate (no data files): closed icospheres
// mapped onto ellipsoids, boxes, and the damage that real segmented surfaces
// carry (holes, folds, duplicated vertices, zero-area triangles).
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <utility>

#include "io/surface_import.hpp"

namespace tissue::test {

/// Closed, outward ellipsoid with semi-axes r (m) centred at c: an
/// icosahedron subdivided `levels` times (20 * 4^levels triangles), every
/// vertex pushed onto the ellipsoid radially.
inline io::SurfaceMesh ellipsoid(std::array<double, 3> c, std::array<double, 3> r, int levels) {
  const double t = (1 + std::sqrt(5.0)) / 2;
  std::vector<std::array<double, 3>> v = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                                          {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  std::vector<std::array<index_t, 3>> f = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                           {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                           {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                           {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int l = 0; l < levels; ++l) {
    std::map<std::pair<index_t, index_t>, index_t> mid;
    auto midpoint = [&](index_t a, index_t b) {
      const auto key = std::minmax(a, b);
      if (auto it = mid.find(key); it != mid.end()) return it->second;
      v.push_back({(v[a][0] + v[b][0]) / 2, (v[a][1] + v[b][1]) / 2, (v[a][2] + v[b][2]) / 2});
      return mid[key] = index_t(v.size() - 1);
    };
    std::vector<std::array<index_t, 3>> g;
    for (const auto& tri : f) {
      const index_t a = midpoint(tri[0], tri[1]), b = midpoint(tri[1], tri[2]), d = midpoint(tri[2], tri[0]);
      g.insert(g.end(), {{tri[0], a, d}, {tri[1], b, a}, {tri[2], d, b}, {a, b, d}});
    }
    f.swap(g);
  }
  io::SurfaceMesh s;
  for (const auto& p : v) {
    const double n = std::sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2]);
    for (int k = 0; k < 3; ++k) s.vertices.push_back(c[k] + r[k] * p[k] / n);
  }
  for (const auto& tri : f) s.triangles.insert(s.triangles.end(), tri.begin(), tri.end());
  return s;
}

/// The ellipsoid of ellipsoid() with a groove cut across its top: along
/// the plane x = c.x, `depth` (m) deep at its bottom and about `width` (m)
/// wide (a Gaussian of that full width at half depth), fading out below the
/// equator: the narrow fold of a real organ's surface, steeper than the
/// elements a coarse target asks for. `levels` must resolve the width.
inline io::SurfaceMesh grooved_ellipsoid(std::array<double, 3> c, std::array<double, 3> r, int levels, double depth,
                                         double width) {
  io::SurfaceMesh s = ellipsoid(c, r, levels);
  const double sigma = width / 2.3548;  // full width at half maximum
  for (index_t v = 0; v < s.n_vertices(); ++v) {
    double* p = &s.vertices[3 * v];
    const double x = p[0] - c[0], y = p[1] - c[1], z = p[2] - c[2];
    const double rr = std::sqrt(x * x + y * y + z * z);
    const double top = std::clamp(z / r[2] * 2, 0.0, 1.0);  // 0 below the equator, 1 above half the height
    const double cut = depth * top * std::exp(-x * x / (2 * sigma * sigma));
    const double k = (rr - cut) / rr;
    p[0] = c[0] + x * k, p[1] = c[1] + y * k, p[2] = c[2] + z * k;
  }
  return s;
}

/// Appends the closed, outward box [lo, lo + side]^3 (12 triangles).
inline void add_box(io::SurfaceMesh& s, double lo, double side) {
  static constexpr int kQuads[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4},
                                       {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};
  const index_t base = s.n_vertices();
  for (int v = 0; v < 8; ++v)
    for (int a = 0; a < 3; ++a) s.vertices.push_back(lo + side * ((v >> a) & 1));
  for (const auto& q : kQuads)
    s.triangles.insert(s.triangles.end(),
                       {base + q[0], base + q[1], base + q[2], base + q[0], base + q[2], base + q[3]});
}

/// Appends every vertex and triangle of `b` to `a` (two bodies in one surface).
inline void append(io::SurfaceMesh& a, const io::SurfaceMesh& b) {
  const index_t base = a.n_vertices();
  a.vertices.insert(a.vertices.end(), b.vertices.begin(), b.vertices.end());
  for (index_t v : b.triangles) a.triangles.push_back(base + v);
}

/// Removes every triangle that uses vertex v: a hole bounded by v's link.
inline void cut_fan(io::SurfaceMesh& s, index_t v) {
  std::vector<index_t> kept;
  for (index_t t = 0; t < s.n_triangles(); ++t) {
    const index_t* c = &s.triangles[3 * t];
    if (c[0] != v && c[1] != v && c[2] != v) kept.insert(kept.end(), c, c + 3);
  }
  s.triangles.swap(kept);
}

/// Moves vertex v by d (m): far enough, its fan folds through its neighbours'.
inline void move_vertex(io::SurfaceMesh& s, index_t v, std::array<double, 3> d) {
  for (int k = 0; k < 3; ++k) s.vertices[3 * v + k] += d[k];
}

/// Every triangle gets its own three vertices (as STL stores them): the
/// surface is a soup until the duplicated vertices are merged.
inline io::SurfaceMesh unshare_vertices(const io::SurfaceMesh& s) {
  io::SurfaceMesh out;
  for (index_t t = 0; t < s.n_triangles(); ++t)
    for (int k = 0; k < 3; ++k) {
      const index_t v = s.triangles[3 * t + k];
      out.vertices.insert(out.vertices.end(), s.vertices.begin() + 3 * v, s.vertices.begin() + 3 * v + 3);
      out.triangles.push_back(3 * t + k);
    }
  return out;
}

/// Splits the first triangle (a, b, c) at the midpoint m of its edge ab into
/// (a, m, c) and (m, b, c) and closes the seam with the zero-area triangle
/// (a, b, m): the surface stays closed and gains one degenerate triangle.
inline void add_zero_area_triangle(io::SurfaceMesh& s) {
  const index_t a = s.triangles[0], b = s.triangles[1], c = s.triangles[2];
  const index_t m = s.n_vertices();
  for (int k = 0; k < 3; ++k) s.vertices.push_back((s.vertices[3 * a + k] + s.vertices[3 * b + k]) / 2);
  s.triangles[1] = m;  // (a, m, c)
  s.triangles.insert(s.triangles.end(), {m, b, c, a, b, m});
}

/// Multiplies every coordinate by `factor` (a surface written in another unit).
inline io::SurfaceMesh scaled(io::SurfaceMesh s, double factor) {
  for (double& x : s.vertices) x *= factor;
  return s;
}

}  // namespace tissue::test
