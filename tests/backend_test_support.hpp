// Shared helpers of the backend tests (the contract suite and the cpu
// backend's own tests): box models, displacement fields, field comparisons,
// a serial reference TLED step, and constructions (a top triangle, an
// inverted element).
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <ostream>
#include <string>
#include <vector>

#include "backends/registry.hpp"
#include "core/box_mesh.hpp"
#include "core/model.hpp"
#include "core/tet.hpp"

namespace tissue::test {

constexpr double kL = 0.02;  // box edge (m)

/// One backend and precision of the suites that run over every one (the
/// contract, the materials): cpu and cuda, float and double.
struct BackendKind {
  std::string backend;
  Precision precision;
};

inline void PrintTo(const BackendKind& k, std::ostream* os) { *os << k.backend << " " << to_string(k.precision); }

inline std::vector<BackendKind> all_backend_kinds() {
  return {{"cpu", Precision::Float}, {"cpu", Precision::Double}, {"cuda", Precision::Float}, {"cuda", Precision::Double}};
}

/// Test name suffix: "cpu_float", ...
inline std::string backend_kind_name(const ::testing::TestParamInfo<BackendKind>& info) {
  return info.param.backend + "_" + to_string(info.param.precision);
}

/// Why `backend` cannot run here (not built, no device), or "" when it can.
inline std::string unusable_reason(const std::string& backend) {
  for (const BackendInfo& b : list_backends())
    if (b.name == backend && !b.available) return b.detail;
  return "";
}

/// Skips the calling test when its backend cannot run here, naming why.
#define SKIP_UNLESS_USABLE(backend)                                                          \
  do {                                                                                       \
    if (const std::string why = ::tissue::test::unusable_reason(backend); !why.empty())     \
      GTEST_SKIP() << "backend '" << (backend) << "' is not usable here: " << why;           \
  } while (0)

/// A kL-sized box of n^3 cells, brain-like tissue (E = 3000 Pa, nu = 0.45,
/// rho = 1000 kg/m^3); optionally the bottom face z = 0 fixed.
inline TissueModel<double> box_model(int n, bool fix_bottom = false, bool ianp = true) {
  ModelInput in;
  box_mesh(in, n, n, n, kL, kL, kL);
  const double E = 3000, nu = 0.45;
  in.materials = {{E / (2 * (1 + nu)), E / (3 * (1 - 2 * nu)), 1000}};
  in.ianp = ianp;
  in.source = "box";
  if (fix_bottom) {
    in.fixed.assign(in.nodes.size() / 3, 0);
    for (size_t i = 0; i < in.fixed.size(); ++i) in.fixed[i] = in.nodes[3 * i + 2] == 0.0;
  }
  return build_model(in);
}

/// u = g(X) for every node (3 x n_nodes).
template <class G>
std::vector<double> field(const TissueModel<double>& m, G g) {
  const index_t n = m.n_nodes;
  std::vector<double> u(3 * n);
  for (index_t i = 0; i < n; ++i) {
    const Vec3<double> d = g(Vec3<double>{m.X[i], m.X[n + i], m.X[2 * n + i]});
    for (int c = 0; c < 3; ++c) u[c * n + i] = d[c];
  }
  return u;
}

inline double max_abs(const std::vector<double>& v) {
  double r = 0;
  for (double x : v) r = std::max(r, std::fabs(x));
  return r;
}

inline double max_diff(const std::vector<double>& a, const std::vector<double>& b) {
  double r = 0;
  for (size_t k = 0; k < a.size(); ++k) r = std::max(r, std::fabs(a[k] - b[k]));
  return r;
}

/// The same contact records (Backend::contacts), bit for bit: nodes, tools,
/// kinds and normals; `what` names the comparison in a failure.
inline void expect_same_contacts(const std::vector<ContactNode>& a, const std::vector<ContactNode>& b,
                                 const std::string& what) {
  ASSERT_EQ(a.size(), b.size()) << what;
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].node, b[i].node) << what;
    EXPECT_EQ(a[i].tool, b[i].tool) << what << ", node " << a[i].node;
    EXPECT_EQ(a[i].kind, b[i].kind) << what << ", node " << a[i].node;
    EXPECT_EQ(std::memcmp(&a[i].normal, &b[i].normal, sizeof(Vec3<double>)), 0) << what << ", node " << a[i].node;
  }
}

inline Vec3<double> node_u(const std::vector<double>& u, index_t n, index_t a) {
  return {u[a], u[n + a], u[2 * n + a]};
}

/// Serial, scatter-based reference of one TLED step over the whole mesh,
/// straight from docs/design.md section 2 and core/tet.hpp (R = 0). Held nodes
/// (held[a]) are set to u_held. Returns the internal forces f (3 x n).
inline std::vector<double> reference_step(const TissueModel<double>& m, std::vector<double>& u, std::vector<double>& u_prev,
                                   const std::vector<std::uint8_t>& held, const std::vector<double>& u_held) {
  const index_t n = m.n_nodes, ne = m.n_elems;
  auto corner_u = [&](index_t e, Vec3<double> ue[4], double dN[12]) {
    for (int a = 0; a < 4; ++a) ue[a] = node_u(u, n, m.elem_nodes[a * ne + e]);
    for (int k = 0; k < 12; ++k) dN[k] = m.dndx[k * ne + e];
  };
  std::vector<double> num(n, 0.0), den(n, 0.0), kv(n, 0.0), f(3 * n, 0.0);
  for (index_t e = 0; e < ne; ++e) {  // pass 1 and the scatter of pass 2
    Vec3<double> ue[4];
    double dN[12];
    corner_u(e, ue, dN);
    const double dv = (det(deformation_gradient(ue, dN)) - 1.0) * m.volume[e];
    for (int a = 0; a < 4; ++a) {
      num[m.elem_nodes[a * ne + e]] += dv;
      den[m.elem_nodes[a * ne + e]] += m.volume[e];
      kv[m.elem_nodes[a * ne + e]] += m.K[e] * m.volume[e];
    }
  }
  for (index_t e = 0; e < ne; ++e) {  // pass 3 and the scatter of pass 4
    Vec3<double> ue[4], fe[4];
    double dN[12];
    corner_u(e, ue, dN);
    double p[4];
    for (int a = 0; a < 4; ++a) {  // p_a = K_a theta_a, K_a the node's volume-weighted bulk modulus
      const index_t i = m.elem_nodes[a * ne + e];
      p[a] = kv[i] / den[i] * (num[i] / den[i]);
    }
    const double pbar = 0.25 * (((p[0] + p[1]) + p[2]) + p[3]);
    if (m.ianp)
      ianp_element_forces(ue, dN, m.volume[e], m.mu[e], m.K[e], pbar, fe);
    else
      plain_element_forces(ue, dN, m.volume[e], m.mu[e], m.K[e], fe);
    for (int a = 0; a < 4; ++a)
      for (int c = 0; c < 3; ++c) f[c * n + m.elem_nodes[a * ne + e]] += fe[a][c];
  }
  std::vector<double> next(3 * n);
  for (index_t a = 0; a < n; ++a)
    for (int c = 0; c < 3; ++c) {
      const size_t k = size_t(c) * n + a;
      next[k] = held[a] ? u_held[k]
                        : central_difference_update(CentralDifference<double>{m.cd_A[a], m.cd_B[a], m.cd_C[a]}, -f[k],
                                                    u[k], u_prev[k]);
    }
  u_prev = u;
  u = next;
  return f;
}

/// The three nodes of a top-face triangle near the middle of a box of n^3 cells.
inline std::vector<index_t> top_triangle(const TissueModel<double>& m) {
  const index_t n = m.n_nodes, nt = m.n_tris;
  index_t best = -1;
  double best_d = 1e300;
  for (index_t t = 0; t < nt; ++t) {
    Vec3<double> c{0, 0, 0};
    bool top = true;
    for (int k = 0; k < 3; ++k) {
      const index_t i = m.tris[k * nt + t];
      top = top && m.X[2 * n + i] == kL;
      c = c + (1.0 / 3) * Vec3<double>{m.X[i], m.X[n + i], m.X[2 * n + i]};
    }
    const double d = std::hypot(c.x - kL / 2, c.y - kL / 2);
    if (top && d < best_d) {
      best = t;
      best_d = d;
    }
  }
  std::vector<index_t> v = {m.tris[best], m.tris[nt + best], m.tris[2 * nt + best]};
  std::sort(v.begin(), v.end());
  return v;
}

/// Moves node `a` of element `e` along -dN_a so that J_e = 1 - amount.
inline std::vector<double> flip(const TissueModel<double>& m, index_t e, int corner, double amount) {
  const index_t n = m.n_nodes, ne = m.n_elems;
  const Vec3<double> g{m.dndx[(3 * corner) * ne + e], m.dndx[(3 * corner + 1) * ne + e],
                       m.dndx[(3 * corner + 2) * ne + e]};
  std::vector<double> u(3 * n, 0.0);
  const index_t a = m.elem_nodes[corner * ne + e];
  for (int c = 0; c < 3; ++c) u[c * n + a] = -amount * g[c] / dot(g, g);  // J = 1 + dN_a . u_a
  return u;
}

/// Lowest element with det F <= 0 under u (core math), and its J.
inline std::pair<index_t, double> lowest_inverted(const TissueModel<double>& m, const std::vector<double>& u) {
  const index_t n = m.n_nodes, ne = m.n_elems;
  for (index_t e = 0; e < ne; ++e) {
    Vec3<double> ue[4];
    double dN[12];
    for (int a = 0; a < 4; ++a) ue[a] = node_u(u, n, m.elem_nodes[a * ne + e]);
    for (int k = 0; k < 12; ++k) dN[k] = m.dndx[k * ne + e];
    const double J = det(deformation_gradient(ue, dN));
    if (J <= 0) return {e, J};
  }
  return {-1, 1};
}


}  // namespace tissue::test
