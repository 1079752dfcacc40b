#include "core/tool.hpp"

#include <fmt/format.h>

#include <cmath>

namespace tissue {

std::string tool_shape_error(const ToolShape& t, double body_extent) {
  if (!std::isfinite(t.radius) || !(t.radius > 0))
    return fmt::format("tool '{}': radius = {} m must be finite and > 0 (the radius is the loaded patch)", t.name,
                       t.radius);
  if (body_extent > 0 && 2 * t.radius > body_extent)
    return fmt::format(
        "tool '{}': radius = {} m is larger than the body (its largest extent is {:.4g} m): a tool's diameter must "
        "not exceed the body it touches; check the unit of the radius and of the mesh",
        t.name, t.radius, body_extent);
  if (!std::isfinite(t.shaft) || !(t.shaft >= 0))
    return fmt::format("tool '{}': shaft-length = {} m must be finite and >= 0 (0 = a sphere)", t.name, t.shaft);
  if (const std::string e = tool_friction_error(t.name, t.friction); !e.empty()) return e;
  return {};
}

std::string tool_friction_error(const std::string& name, double friction) {
  if (!std::isfinite(friction) || !(friction >= 0))
    return fmt::format("tool '{}': friction = {} must be finite and >= 0 (Coulomb's mu; 0 = frictionless)", name,
                       friction);
  return {};
}

}  // namespace tissue
