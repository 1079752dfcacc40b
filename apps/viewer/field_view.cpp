#include "apps/viewer/field_view.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace tissue::viewer {

FieldKind parse_field_kind(const std::string& s) {
  if (s == "none") return FieldKind::None;
  if (s == "displacement") return FieldKind::Displacement;
  if (s == "pressure") return FieldKind::Pressure;
  if (s == "J") return FieldKind::Jacobian;
  throw std::invalid_argument(fmt::format("--field '{}' is none of none, displacement, pressure, J", s));
}

const char* field_name(FieldKind k) {
  switch (k) {
    case FieldKind::Displacement: return "displacement";
    case FieldKind::Pressure: return "pressure";
    case FieldKind::Jacobian: return "J";
    case FieldKind::None: break;
  }
  return "none";
}

NodeField node_field(FieldKind kind, const Fields& f, index_t n_nodes, const std::vector<index_t>& node_elem_start,
                     const std::vector<index_t>& node_elem) {
  NodeField out;
  out.kind = kind;
  const std::size_t n = std::size_t(n_nodes);
  if (kind == FieldKind::None) return out;
  out.value.assign(n, 0.0);
  switch (kind) {
    case FieldKind::Displacement:
      for (std::size_t i = 0; i < n; ++i)  // u is component-major
        out.value[i] = 1e3 * std::hypot(f.u[i], f.u[n + i], f.u[2 * n + i]);
      out.label = "|u| (mm)";
      break;
    case FieldKind::Pressure:
      std::copy_n(f.node_p.begin(), n, out.value.begin());
      out.label = "pressure (Pa)";
      break;
    case FieldKind::Jacobian:
      for (std::size_t i = 0; i < n; ++i) {
        double sum = 0;
        const index_t b = node_elem_start[i], e = node_elem_start[i + 1];
        for (index_t k = b; k < e; ++k) sum += f.elem_J[std::size_t(incident_element(node_elem[k]))];
        out.value[i] = e > b ? sum / (e - b) : 1.0;
      }
      out.label = "J = det F";
      break;
    case FieldKind::None: break;
  }
  double lo = INFINITY, hi = -INFINITY;
  for (double v : out.value)
    if (std::isfinite(v)) lo = std::min(lo, v), hi = std::max(hi, v);
  if (!(lo <= hi)) lo = hi = 0;  // nothing finite
  if (kind == FieldKind::Displacement) {
    out.lo = 0;
    out.hi = std::max(hi, 1e-3);  // at least 1 micrometre
  } else {
    const double centre = kind == FieldKind::Jacobian ? 1.0 : 0.0;
    const double m = std::max({std::fabs(lo - centre), std::fabs(hi - centre), kind == FieldKind::Jacobian ? 1e-4 : 1e-3});
    out.lo = centre - m;
    out.hi = centre + m;
  }
  return out;
}

std::array<std::uint8_t, 3> field_colour(FieldKind kind, double t) {
  if (!std::isfinite(t)) return {255, 0, 255};
  t = std::clamp(t, 0.0, 1.0);
  // piecewise-linear through control colours, evenly spaced in t
  static const double kSequential[5][3] = {
      {0.18, 0.07, 0.35}, {0.15, 0.35, 0.55}, {0.12, 0.60, 0.55}, {0.50, 0.80, 0.30}, {0.99, 0.91, 0.15}};
  static const double kDiverging[5][3] = {
      {0.13, 0.25, 0.65}, {0.45, 0.65, 0.90}, {0.96, 0.96, 0.96}, {0.92, 0.55, 0.40}, {0.70, 0.10, 0.15}};
  const auto& map = kind == FieldKind::Displacement ? kSequential : kDiverging;
  const double x = t * 4;
  const int i = std::min(3, int(x));
  const double s = x - i;
  std::array<std::uint8_t, 3> c;
  for (int k = 0; k < 3; ++k) c[k] = std::uint8_t(std::lround(255 * ((1 - s) * map[i][k] + s * map[i + 1][k])));
  return c;
}

std::vector<std::uint8_t> node_colours(const NodeField& f) {
  std::vector<std::uint8_t> rgb(3 * f.value.size());
  const double span = f.hi - f.lo;
  for (std::size_t i = 0; i < f.value.size(); ++i) {
    const auto c = field_colour(f.kind, span > 0 ? (f.value[i] - f.lo) / span : 0.5);
    std::copy(c.begin(), c.end(), rgb.begin() + long(3 * i));
  }
  return rgb;
}

void ForceHistory::add(double t, const std::vector<double>& forces) {
  if ((!times_.empty() && t < times_.back()) || forces.size() != series_.size()) {
    times_.clear();
    series_.assign(forces.size(), {});
  }
  times_.push_back(t);
  for (std::size_t k = 0; k < forces.size(); ++k) series_[k].push_back(float(forces[k]));
  while (times_.size() > 1 && times_.back() - times_.front() > window_) {
    times_.pop_front();
    for (auto& s : series_) s.pop_front();
  }
}

std::vector<float> ForceHistory::series(int k) const { return {series_.at(k).begin(), series_.at(k).end()}; }

double ForceHistory::latest(int k) const { return series_.at(k).empty() ? 0.0 : series_.at(k).back(); }

double ForceHistory::peak(int k) const {
  const auto& s = series_.at(k);
  return s.empty() ? 0.0 : *std::max_element(s.begin(), s.end());
}

}  // namespace tissue::viewer
