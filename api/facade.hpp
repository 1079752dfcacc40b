// What the facade's Simulation and Batch share (api/ only): a Session's
// report as a TickResult, fields in the facade's layout, argument checks.
#pragma once

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "core/backend.hpp"
#include "core/cut.hpp"
#include "core/scheduler.hpp"
#include "core/vec.hpp"
#include "scene/scene.hpp"
#include "tissue/simulation.hpp"

namespace tissue::facade {

inline Vec3<double> vec(const Vector3& a) {
  return {a[0], a[1], a[2]};
}
inline Vector3 arr(const Vec3<double>& v) {
  return {v.x, v.y, v.z};
}
inline bool finite3(const Vector3& a) {
  return std::isfinite(a[0]) && std::isfinite(a[1]) && std::isfinite(a[2]);
}

/// An interleaved copy (x y z per item) of a component-major array (all x, then all y, ...).
template <class T>
std::vector<T> interleave(const std::vector<T>& soa, std::size_t components) {
  const std::size_t n = soa.size() / components;
  std::vector<T> out(soa.size());
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t c = 0; c < components; ++c) out[components * i + c] = soa[c * n + i];
  return out;
}

/// The scene of a host's mesh: one material on every element, the fixed
/// nodes, and each tool parked above the body (one waypoint) until the host
/// moves it. Throws std::invalid_argument for counts that do not divide.
scene::Scene mesh_scene(const MeshScene& m);

/// The cut options of a method name ("snap-split", "snap", "split");
/// throws std::invalid_argument naming the name otherwise.
CutOptions cut_options(const std::string& method);

/// The scene's bodies as the facade gives them: its <body>s, or one body
/// "body" of all n_nodes and n_elems.
inline std::vector<BodyRange> body_ranges(const scene::Scene& s, std::size_t n_nodes, std::size_t n_elems) {
  if (s.bodies.empty()) return {{"body", 0, n_nodes, 0, n_elems}};
  std::vector<BodyRange> out;
  for (const scene::Body& b : s.bodies)
    out.push_back({b.name, std::size_t(b.first_node), std::size_t(b.n_nodes), std::size_t(b.first_element),
                   std::size_t(b.n_elements)});
  return out;
}

/// The backend's body contacts after its last step in the facade's terms:
/// each triangle's corners from the model's tris (3 x n_tris, corner k of
/// triangle t at k n_tris + t), each node's body from the ranges (bodies
/// ascending by first_node, as body_ranges gives them).
inline std::vector<BodyContact> body_contacts(Backend& backend, const TissueModel<double>& m,
                                              const std::vector<BodyRange>& bodies) {
  const auto body_of = [&](index_t node) {
    const auto after = std::upper_bound(bodies.begin(), bodies.end(), std::size_t(node),
                                        [](std::size_t a, const BodyRange& b) { return a < b.first_node; });
    return int(after - bodies.begin()) - 1;
  };
  std::vector<BodyContact> out;
  for (const BodyContactNode& c : backend.body_contacts()) {
    BodyContact b;
    b.node = std::int32_t(c.node);
    for (int k = 0; k < 3; ++k) b.triangle[k] = std::int32_t(m.tris[std::size_t(k) * m.n_tris + c.tri]);
    b.body = body_of(c.node);
    b.other_body = body_of(b.triangle[0]);
    b.depth = c.gap;
    out.push_back(b);
  }
  return out;
}

/// Writes the facade's view of a tick report after `ticks` ticks into out,
/// reusing its tool list (the tick loop allocates nothing once it has the
/// scene's tool count).
inline void set_tick_result(TickResult& out, const TickReport& r, long ticks) {
  out.tick = ticks;
  out.time = r.time;
  out.steps = r.steps;
  out.tools.resize(std::size_t(r.n_tools));
  for (int k = 0; k < r.n_tools; ++k) {
    const ToolReport& t = r.tools[k];
    out.tools[k] = {arr(t.tip), arr(t.axis), arr(t.force), int(t.contact_nodes), int(t.grasped), t.grasp, t.cut};
  }
  out.max_displacement = r.max_disp;
  out.residual = r.residual;
  out.equilibrium = r.equilibrium;
  out.region_nodes = int(r.region_nodes);
  out.region_elements = int(r.region_elems);
}

/// Values field f has for n_nodes nodes and n_elems elements.
inline std::size_t field_size(Field f, std::size_t n_nodes, std::size_t n_elems) {
  return (field_per_element(f) ? n_elems : n_nodes) * std::size_t(field_components(f));
}

/// Writes field f of a download into out (x y z per node for vectors;
/// positions add rest, the interleaved reference positions). out holds
/// field_size values (checked by the caller). A stored field is the
/// download's array of core/store.hpp's output list that names it.
inline void copy_field(const Fields& s, std::span<const double> rest, Field f, std::span<double> out) {
  const std::size_t nn = rest.size() / 3;
  const auto copy = [&](const std::vector<double>& v, int components, bool add_rest) {
    if (components == 1) {
      std::copy(v.begin(), v.end(), out.begin());
      return;
    }
    for (std::size_t i = 0; i < nn; ++i)  // component-major -> x y z per node
      for (std::size_t c = 0; c < 3; ++c) out[3 * i + c] = v[c * nn + i] + (add_rest ? rest[3 * i + c] : 0.0);
  };
  switch (f) {
#define TISSUE_OUTPUT_CASE(member, vtu, field, per, components, unit) \
  case Field::field:                                                  \
    return copy(s.member, components, false);
    TISSUE_OUTPUT_ARRAYS(TISSUE_OUTPUT_CASE)
#undef TISSUE_OUTPUT_CASE
    case Field::Position:  // derived: X + u
      return copy(s.u, 3, true);
  }
}

}  // namespace tissue::facade
