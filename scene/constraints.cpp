#include "scene/constraints.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

namespace tissue::scene {
namespace {

bool in_box(const double* x, const Constraint& c, double tol) {
  for (int k = 0; k < 3; ++k)
    if (x[k] < c.lo[k] - tol || x[k] > c.hi[k] + tol) return false;
  return true;
}

bool above_plane(const double* x, const Constraint& c, double tol) {
  const double len = std::sqrt(c.normal[0] * c.normal[0] + c.normal[1] * c.normal[1] + c.normal[2] * c.normal[2]);
  if (!(len > 0)) return false;
  double d = 0;
  for (int k = 0; k < 3; ++k) d += (x[k] - c.point[k]) * c.normal[k];
  return d / len >= -tol;
}

std::string triple(const double* v) {
  return fmt::format("({}, {}, {})", v[0], v[1], v[2]);
}

}  // namespace

double selection_tolerance(std::span<const double> nodes) {
  double extent = 0;
  for (int k = 0; k < 3; ++k) {
    double lo = INFINITY, hi = -INFINITY;
    for (size_t i = k; i < nodes.size(); i += 3) {
      lo = std::min(lo, nodes[i]);
      hi = std::max(hi, nodes[i]);
    }
    if (hi >= lo) extent = std::max(extent, hi - lo);
  }
  return 1e-9 * extent;
}

std::vector<index_t> constrained_nodes(const Constraint& c, std::span<const double> nodes, double tol,
                                       std::span<const Body> bodies) {
  index_t lo = 0, hi = static_cast<index_t>(nodes.size() / 3);
  if (c.body >= 0 && std::size_t(c.body) < bodies.size()) {
    const Body& b = bodies[std::size_t(c.body)];
    lo = std::max(lo, b.first_node);
    hi = std::min(hi, b.first_node + b.n_nodes);
  }
  std::vector<index_t> out;
  if (c.kind == Constraint::Kind::Nodes) {
    for (index_t i : c.nodes)
      if (i >= lo && i < hi) out.push_back(i);
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
    return out;
  }
  for (index_t i = lo; i < hi; ++i) {
    const double* x = nodes.data() + 3 * size_t(i);
    if (c.kind == Constraint::Kind::Box ? in_box(x, c, tol) : above_plane(x, c, tol)) out.push_back(i);
  }
  return out;
}

std::string describe(const Constraint& c) {
  switch (c.kind) {
    case Constraint::Kind::Nodes:
      return "fixed nodes";
    case Constraint::Kind::Box:
      return fmt::format("fixed box min {} max {}", triple(c.lo), triple(c.hi));
    case Constraint::Kind::Plane:
      return fmt::format("fixed plane point {} normal {}", triple(c.point), triple(c.normal));
  }
  return "fixed";
}

}  // namespace tissue::scene
