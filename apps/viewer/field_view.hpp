// What the viewer colours the surface by (docs/viewer.md "Fields"): the
// displacement magnitude, the IANP nodal pressure, or J = det F averaged
// from the elements to the nodes, mapped through a colour map to one colour
// per node, with the range the legend shows; and each tool's force over the
// last seconds for the overlay's plot. GL-free: the renderer takes the
// colours, the overlay the range and the history.
#pragma once

#include <array>
#include <cstdint>
#include <deque>
#include <string>
#include <vector>

#include "core/backend.hpp"
#include "core/model.hpp"

namespace tissue::viewer {

enum class FieldKind { None, Displacement, Pressure, Jacobian };

/// "none" | "displacement" | "pressure" | "J"; std::invalid_argument naming the text otherwise.
FieldKind parse_field_kind(const std::string& s);
const char* field_name(FieldKind k);  ///< the word parse_field_kind takes

/// One value per node and the range the colours span.
struct NodeField {
  FieldKind kind = FieldKind::None;
  std::vector<double> value;  ///< per node, in `unit`
  double lo = 0, hi = 0;      ///< the colour map's ends
  std::string label;          ///< for the legend: "|u| (mm)", "pressure (Pa)", "J"
};

/// The field's nodal values from a download: |u| in mm; pressure in Pa;
/// J as the mean of the incident elements' J. The range: [0, max |u|];
/// pressure and J symmetric about 0 and 1 (tension and compression read
/// apart), at least a small span so a field at rest shows one colour.
/// `node_elem_start` / `node_elem` are the model's CSR (element * 4 + corner).
NodeField node_field(FieldKind kind, const Fields& f, index_t n_nodes, const std::vector<index_t>& node_elem_start,
                     const std::vector<index_t>& node_elem);

/// The colour of t in [0, 1] (clamped; NaN is magenta): a sequential map
/// (dark blue -> teal -> yellow) for |u|, a diverging one (blue -> white ->
/// red) for pressure and J.
std::array<std::uint8_t, 3> field_colour(FieldKind kind, double t);

/// RGB bytes per node (3 x n) of the field over its range.
std::vector<std::uint8_t> node_colours(const NodeField& f);

/// Each tool's force magnitude over the last `window` seconds of simulated
/// time (the overlay's plot).
class ForceHistory {
 public:
  explicit ForceHistory(double window = 5.0) : window_(window) {}
  /// A sample at simulated time t (s): |force| per tool (N). A time before
  /// the last sample (the tissue was rebuilt) starts over.
  void add(double t, const std::vector<double>& forces);
  int n_tools() const { return int(series_.size()); }
  /// Tool k's magnitudes, oldest first.
  std::vector<float> series(int k) const;
  double latest(int k) const;
  double peak(int k) const;
  std::size_t size() const { return times_.size(); }
  double span() const { return times_.empty() ? 0 : times_.back() - times_.front(); }

 private:
  double window_;
  std::deque<double> times_;
  std::vector<std::deque<float>> series_;
};

}  // namespace tissue::viewer
