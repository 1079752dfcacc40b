#include "scene/fibre_field.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "scene/validate.hpp"

namespace tissue::scene {
namespace {

using Field = Material::FibreField;

bool finite(Vec3<double> v) { return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z); }

/// "<csv>:<line>: material 'm', fibre file '<name>' (<fibre> at scene:line): <what>".
[[noreturn]] void fail_row(const Scene& s, const Material& m, const Material::FibreRow& row, size_t index,
                           const std::string& what) {
  const std::string& csv = m.fibre_file_path.empty() ? m.fibre_file : m.fibre_file_path;
  const std::string where = row.line > 0 ? fmt::format("{}:{}", csv, row.line) : fmt::format("{}: row {}", csv, index);
  throw SceneError(fmt::format("{}: material '{}', fibre file '{}' (<fibre> at {}): {}", where, m.name, m.fibre_file,
                               location(s, m.fibre_line ? m.fibre_line : m.line), what));
}

/// Row index per element for a File material (-1 = not listed), checking
/// every row in file order.
std::vector<int> file_rows(const Scene& s, const Material& m, index_t ne) {
  std::vector<int> row_of(ne, -1);
  for (size_t r = 0; r < m.fibre_rows.size(); ++r) {
    const Material::FibreRow& row = m.fibre_rows[r];
    const index_t e = row.element;
    if (e < 0 || e >= ne)
      fail_row(s, m, row, r,
               fmt::format("element {} is out of range (the mesh has {} elements, ids 0..{}; ids are 0-based as in "
                           "the mesh)",
                           e, ne, ne - 1));
    if (row_of[e] >= 0) {
      const Material::FibreRow& first = m.fibre_rows[row_of[e]];
      fail_row(s, m, row, r,
               fmt::format("element {} is listed twice (first {}); give each element one direction", e,
                           first.line > 0 ? fmt::format("at line {}", first.line)
                                          : fmt::format("as row {}", row_of[e])));
    }
    const Vec3<double> a = row.dir;
    if (!finite(a) || !(norm(a) > 0))
      fail_row(s, m, row, r,
               fmt::format("element {}: fibre direction ({}, {}, {}) must be finite and non-zero", e, a.x, a.y, a.z));
    row_of[e] = int(r);
  }
  return row_of;
}

Vec3<double> centroid(const Scene& s, index_t e) {
  Vec3<double> c = {0, 0, 0};
  for (int a = 0; a < 4; ++a) {
    const size_t i = 3 * size_t(s.tets[4 * size_t(e) + a]);
    c = c + Vec3<double>{s.nodes[i], s.nodes[i + 1], s.nodes[i + 2]};
  }
  return 0.25 * c;
}

/// The mesh's bounding-box diagonal (m).
double mesh_size(const Scene& s) {
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (size_t k = 0; k < s.nodes.size(); ++k) {
    lo[k % 3] = std::min(lo[k % 3], s.nodes[k]);
    hi[k % 3] = std::max(hi[k % 3], s.nodes[k]);
  }
  return std::hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
}

}  // namespace

std::string_view to_string(Material::FibreField field) {
  switch (field) {
    case Field::Uniform:
      return "uniform";
    case Field::Circumferential:
      return "circumferential";
    case Field::Radial:
      return "radial";
    case Field::File:
      return "file";
  }
  return "?";
}

std::optional<Material::FibreField> parse_fibre_field(std::string_view name) {
  if (name == "circumferential") return Field::Circumferential;
  if (name == "radial") return Field::Radial;
  return std::nullopt;
}

Vec3<double> fibre_field_direction(Material::FibreField field, Vec3<double> axis, Vec3<double> origin,
                                   Vec3<double> c) {
  const Vec3<double> n = (1.0 / norm(axis)) * axis, d = c - origin;
  switch (field) {
    case Field::Circumferential:
      return cross(n, d);
    case Field::Radial:
      return d - dot(d, n) * n;
    default:
      return {0, 0, 0};
  }
}

std::vector<double> resolve_fibre_dirs(const Scene& s, const std::vector<index_t>& elem_material) {
  if (std::all_of(s.materials.begin(), s.materials.end(),
                  [](const Material& m) { return m.fibre_field == Field::Uniform; }))
    return {};
  const index_t ne = static_cast<index_t>(s.tets.size() / 4);
  std::vector<std::vector<int>> row_of(s.materials.size());
  std::vector<index_t> listed(s.materials.size(), 0), count(s.materials.size(), 0);
  for (size_t k = 0; k < s.materials.size(); ++k)
    if (s.materials[k].fibre_field == Field::File) row_of[k] = file_rows(s, s.materials[k], ne);
  const double tol = 1e-9 * mesh_size(s);
  std::vector<double> dirs(3 * size_t(ne));
  for (index_t e = 0; e < ne; ++e) {
    const size_t k = size_t(elem_material[e]);
    const Material& m = s.materials[k];
    ++count[k];
    Vec3<double> a = m.fibre_dir;
    if (m.fibre_field == Field::File) {
      if (const int r = row_of[k][e]; r >= 0) {
        a = m.fibre_rows[r].dir;
        ++listed[k];
      }
    } else if (m.fibre_field != Field::Uniform) {
      const Vec3<double> c = centroid(s, e);
      a = fibre_field_direction(m.fibre_field, m.fibre_axis, m.fibre_origin, c);
      if (!(norm(a) > tol)) {
        const Vec3<double> o = m.fibre_origin, n = m.fibre_axis;
        throw SceneError(fmt::format(
            "{}: material '{}': fibre field {}: element {}'s centroid ({}, {}, {}) m lies on the axis (through ({}, "
            "{}, {}) along ({}, {}, {}); distance {:.3g} m): the {} direction is undefined there; move the axis off "
            "the element or give the element a material without the field",
            location(s, m.fibre_line ? m.fibre_line : m.line), m.name, to_string(m.fibre_field), e, c.x, c.y, c.z,
            o.x, o.y, o.z, n.x, n.y, n.z, norm(a), to_string(m.fibre_field)));
      }
    }
    for (int c = 0; c < 3; ++c) dirs[3 * size_t(e) + c] = a[c];
  }
  for (size_t k = 0; k < s.materials.size(); ++k) {
    const Material& m = s.materials[k];
    if (m.fibre_field == Field::File && count[k] > 0 && listed[k] == 0)
      throw SceneError(fmt::format("{}: material '{}': fibre file '{}' lists none of the material's {} elements "
                                   "(is it the file of another mesh?); its elements would all keep direction=",
                                   location(s, m.fibre_line ? m.fibre_line : m.line), m.name, m.fibre_file,
                                   count[k]));
  }
  return dirs;
}

}  // namespace tissue::scene
