#include "io/mesh_quality.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/tet.hpp"

namespace tissue::io {
namespace {

constexpr double kDegrees = 180.0 / 3.14159265358979323846;

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  const size_t k = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + k, v.end());
  return v[k];
}

}  // namespace

void tet_dihedral_angles(const Vec3<double> X[4], double angles[6]) {
  // Outward normal of the face opposite corner k (any orientation of the tet):
  // the normal of the other three corners, turned away from corner k.
  static constexpr int kOpp[4][3] = {{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}};
  Vec3<double> n[4];
  for (int k = 0; k < 4; ++k) {
    const Vec3<double>& a = X[kOpp[k][0]];
    Vec3<double> c = cross(X[kOpp[k][1]] - a, X[kOpp[k][2]] - a);
    if (dot(c, X[k] - a) > 0) c = -1.0 * c;
    const double l = norm(c);
    n[k] = l > 0 ? (1.0 / l) * c : c;
  }
  // The edge (i, j) is shared by the faces opposite the two other corners.
  static constexpr int kEdge[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};
  for (int e = 0; e < 6; ++e) {
    int f[2], m = 0;
    for (int k = 0; k < 4; ++k)
      if (k != kEdge[e][0] && k != kEdge[e][1]) f[m++] = k;
    angles[e] = std::acos(std::clamp(-dot(n[f[0]], n[f[1]]), -1.0, 1.0));
  }
}

QualityReport mesh_quality(const VolumeMesh& mesh, const std::vector<MaterialParams>& materials,
                           const std::vector<index_t>& tet_material, double tick, double safety, double budget) {
  QualityReport r;
  r.n_tets = mesh.n_tets();
  r.n_nodes = mesh.n_nodes();
  r.budget = budget;
  r.tick = tick;
  r.safety = safety;
  std::vector<double> dt_e(r.n_tets), rho_V(r.n_tets), min_angle(r.n_tets), max_edge(r.n_tets);
  r.min_dihedral = 180;
  r.dt_crit = std::numeric_limits<double>::infinity();
  for (index_t e = 0; e < r.n_tets; ++e) {
    Vec3<double> X[4];
    for (int a = 0; a < 4; ++a) X[a] = mesh.node(mesh.tets[4 * e + a]);
    double dN[12];
    const double V = std::fabs(tet_shape_gradients(X, dN));
    const MaterialParams& p = materials.at(tet_material.empty() ? 0 : size_t(tet_material[e]));
    dt_e[e] = element_time_step(X, V, p);
    rho_V[e] = p.rho * V;
    r.total_mass += rho_V[e];
    double lo = INFINITY, hi = 0;
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b) {
        const double l = norm(X[a] - X[b]);
        lo = std::min(lo, l);
        hi = std::max(hi, l);
      }
    max_edge[e] = hi;
    double ang[6];
    tet_dihedral_angles(X, ang);
    min_angle[e] = kDegrees * *std::min_element(ang, ang + 6);
    r.min_dihedral = std::min(r.min_dihedral, min_angle[e]);
    r.below_10 += min_angle[e] < 10 ? 1 : 0;
    if (dt_e[e] < r.dt_crit) {
      r.dt_crit = dt_e[e];
      r.dt_crit_elem = e;
      r.worst_centroid = 0.25 * (X[0] + X[1] + X[2] + X[3]);
      r.worst_min_edge = lo;
      r.worst_max_edge = hi;
      r.worst_dihedral = min_angle[e];
    }
  }
  r.median_edge = median(max_edge);
  r.median_dihedral = median(min_angle);
  r.dt_median = median(dt_e);
  r.steps_unscaled = int(std::ceil(tick / (safety * r.dt_crit) * (1 - 1e-12)));
  r.mass = choose_mass_scaling(dt_e, rho_V, tick, safety, budget);
  return r;
}

std::string QualityReport::summary() const {
  std::string s = fmt::format(
      "  dihedral angles: min {:.2f} deg, median of the tets' smallest {:.1f} deg; {} tets under 10 deg\n"
      "  dt_crit {:.3g} s (element {}) = {:.3f} x the median element's L/c {:.3g} s\n"
      "  steps per {:.3g} ms tick at dt = {:.2g} dt_crit: {}",
      min_dihedral, median_dihedral, below_10, dt_crit, dt_crit_elem, dt_ratio(), dt_median, 1e3 * tick, safety, steps_unscaled);
  if (mass.scaled_elems > 0)
    s += fmt::format(
        "; mass scaling (budget {:.3g} %) would bring it to {} by adding {:.3g} % mass on {} elements (density up "
        "to x{:.3g})\n",
        100 * budget, mass.steps, 100 * mass.added_mass / total_mass, mass.scaled_elems, mass.max_scale);
  else
    s += "; mass scaling would add nothing\n";
  if (dt_crit_elem >= 0 && dt_ratio() < kDtRatioGoal)
    s += fmt::format(
        "  below the goal of {:.2f}: element {} at ({:.4g}, {:.4g}, {:.4g}) mm sets the step, its edges {:.3g} to "
        "{:.3g} mm against a median element's longest edge of {:.3g} mm, its smallest dihedral {:.1f} deg\n",
        kDtRatioGoal, dt_crit_elem, 1e3 * worst_centroid.x, 1e3 * worst_centroid.y, 1e3 * worst_centroid.z,
        1e3 * worst_min_edge, 1e3 * worst_max_edge, 1e3 * median_edge, worst_dihedral);
  return s;
}

}  // namespace tissue::io
