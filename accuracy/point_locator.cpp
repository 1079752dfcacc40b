#include "accuracy/point_locator.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace tissue::accuracy {

PointLocator::PointLocator(const TissueModel<double>& model) : m_(model) {
  const index_t ne = m_.n_elems;
  Vec3<double> hi = reference_position(m_, 0);
  lo_ = hi;
  for (index_t i = 1; i < m_.n_nodes; ++i) {
    const Vec3<double> x = reference_position(m_, i);
    for (int c = 0; c < 3; ++c) {
      lo_[c] = std::min(lo_[c], x[c]);
      hi[c] = std::max(hi[c], x[c]);
    }
  }
  // about one tet per cell, cubic cells
  double vol = 1;
  for (int c = 0; c < 3; ++c) vol *= std::max(hi[c] - lo_[c], 1e-12);
  const double h = std::cbrt(vol / std::max<index_t>(ne, 1));
  for (int c = 0; c < 3; ++c) {
    n_[c] = std::clamp(static_cast<int>(std::ceil((hi[c] - lo_[c]) / h)), 1, 512);
    size_[c] = std::max(hi[c] - lo_[c], 1e-12) / n_[c];
  }
  const std::size_t cells = std::size_t(n_[0]) * n_[1] * n_[2];
  // two passes: count, then fill (CSR)
  std::vector<std::array<int, 6>> box(ne);
  std::vector<index_t> count(cells + 1, 0);
  for (index_t e = 0; e < ne; ++e) {
    Vec3<double> a = reference_position(m_, m_.elem_nodes[e]), b = a;
    for (int k = 1; k < 4; ++k) {
      const Vec3<double> x = reference_position(m_, m_.elem_nodes[k * ne + e]);
      for (int c = 0; c < 3; ++c) {
        a[c] = std::min(a[c], x[c]);
        b[c] = std::max(b[c], x[c]);
      }
    }
    const auto ca = cell_of(a), cb = cell_of(b);
    box[e] = {ca[0], ca[1], ca[2], cb[0], cb[1], cb[2]};
    for (int k = ca[2]; k <= cb[2]; ++k)
      for (int j = ca[1]; j <= cb[1]; ++j)
        for (int i = ca[0]; i <= cb[0]; ++i) ++count[1 + i + n_[0] * (j + n_[1] * std::size_t(k))];
  }
  start_.assign(cells + 1, 0);
  for (std::size_t c = 0; c < cells; ++c) start_[c + 1] = start_[c] + count[c + 1];
  elems_.resize(start_.back());
  std::vector<index_t> fill(start_.begin(), start_.end() - 1);
  for (index_t e = 0; e < ne; ++e) {
    const auto& bx = box[e];
    for (int k = bx[2]; k <= bx[5]; ++k)
      for (int j = bx[1]; j <= bx[4]; ++j)
        for (int i = bx[0]; i <= bx[3]; ++i) elems_[fill[i + n_[0] * (j + n_[1] * std::size_t(k))]++] = e;
  }
}

std::array<int, 3> PointLocator::cell_of(Vec3<double> p) const {
  std::array<int, 3> c;
  for (int a = 0; a < 3; ++a) c[a] = std::clamp(static_cast<int>(std::floor((p[a] - lo_[a]) / size_[a])), 0, n_[a] - 1);
  return c;
}

double PointLocator::raw_bary(index_t e, Vec3<double> p, std::array<double, 4>& b) const {
  const index_t ne = m_.n_elems;
  const Vec3<double> d = p - reference_position(m_, m_.elem_nodes[e]);
  double lowest = 1e300;
  for (int a = 0; a < 4; ++a) {
    b[a] = (a == 0 ? 1.0 : 0.0) + m_.dndx[(3 * a) * ne + e] * d.x + m_.dndx[(3 * a + 1) * ne + e] * d.y +
           m_.dndx[(3 * a + 2) * ne + e] * d.z;
    lowest = std::min(lowest, b[a]);
  }
  return lowest;
}

Location PointLocator::locate(Vec3<double> p) const {
  Location best;
  double best_low = -1e300;
  std::array<double, 4> b;
  const auto c = cell_of(p);
  auto scan = [&](int i, int j, int k) {
    const std::size_t cell = i + n_[0] * (j + n_[1] * std::size_t(k));
    for (index_t q = start_[cell]; q < start_[cell + 1]; ++q) {
      const index_t e = elems_[q];
      const double low = raw_bary(e, p, b);
      if (low > best_low) {
        best_low = low;
        best.elem = e;
        best.bary = b;
      }
    }
  };
  scan(c[0], c[1], c[2]);
  if (best_low < -1e-12)  // not inside a tet of its own cell: widen to the neighbours
    for (int k = std::max(0, c[2] - 1); k <= std::min(n_[2] - 1, c[2] + 1); ++k)
      for (int j = std::max(0, c[1] - 1); j <= std::min(n_[1] - 1, c[1] + 1); ++j)
        for (int i = std::max(0, c[0] - 1); i <= std::min(n_[0] - 1, c[0] + 1); ++i) scan(i, j, k);
  if (best.elem < 0) return best;
  best.outside = best_low < 0 ? -best_low : 0;
  double sum = 0;
  for (double& x : best.bary) sum += (x = std::max(x, 0.0));
  for (double& x : best.bary) x /= sum;
  return best;
}

std::vector<double> sample_field(const TissueModel<double>& model, std::span<const double> field,
                                 std::span<const double> points) {
  if (field.size() != 3 * std::size_t(model.n_nodes))
    throw std::invalid_argument(
        fmt::format("sample_field: {} field values for {} nodes (need 3 x n_nodes)", field.size(), model.n_nodes));
  const PointLocator loc(model);
  const std::size_t np = points.size() / 3;
  const index_t n = model.n_nodes, ne = model.n_elems;
  std::vector<double> out(3 * np, 0.0);
  for (std::size_t k = 0; k < np; ++k) {
    const Location l = loc.locate({points[3 * k], points[3 * k + 1], points[3 * k + 2]});
    if (l.elem < 0 || l.outside > kMaxOutside)
      throw std::runtime_error(fmt::format("sample_field: point {} ({:.6g}, {:.6g}, {:.6g}) lies outside the mesh{}", k,
                                           points[3 * k], points[3 * k + 1], points[3 * k + 2],
                                           l.elem < 0 ? "" : fmt::format(" (beyond element {})", l.elem)));
    for (int a = 0; a < 4; ++a) {
      const index_t i = model.elem_nodes[a * ne + l.elem];
      for (int c = 0; c < 3; ++c) out[c * np + k] += l.bary[a] * field[c * n + i];
    }
  }
  return out;
}

}  // namespace tissue::accuracy
