// The cpu backend (cpu/): the IANP passes against a serial reference built
// from core/tet.hpp, zero force at rest and under rigid motion, determinism
// across thread counts, float against double, the region (only region nodes
// move; halo, frozen, fixed and driven semantics), the inverted-element stop,
// the reductions, and bad input.
#include <fmt/format.h>
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <vector>

#include "core/box_mesh.hpp"
#include "core/device.hpp"
#include "core/scheduler.hpp"
#include "core/tet.hpp"
#include "cpu/cpu_backend.hpp"
#include "cpu/host_backend.hpp"

namespace tissue {
namespace {

constexpr double kL = 0.02;  // box edge (m)

/// A kL-sized box of n^3 cells, brain-like tissue (E = 3000 Pa, nu = 0.45,
/// rho = 1000 kg/m^3); optionally the bottom face z = 0 fixed.
TissueModel<double> box_model(int n, bool fix_bottom = false, bool ianp = true) {
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

double max_abs(const std::vector<double>& v) {
  double r = 0;
  for (double x : v) r = std::max(r, std::fabs(x));
  return r;
}

double max_diff(const std::vector<double>& a, const std::vector<double>& b) {
  double r = 0;
  for (size_t k = 0; k < a.size(); ++k) r = std::max(r, std::fabs(a[k] - b[k]));
  return r;
}

Vec3<double> node_u(const std::vector<double>& u, index_t n, index_t a) {
  return {u[a], u[n + a], u[2 * n + a]};
}

/// Serial, scatter-based reference of one TLED step over the whole mesh,
/// straight from DESIGN.md section 2 and core/tet.hpp (R = 0). Held nodes
/// (held[a]) are set to u_held. Returns the internal forces f (3 x n).
std::vector<double> reference_step(const TissueModel<double>& m, std::vector<double>& u, std::vector<double>& u_prev,
                                   const std::vector<std::uint8_t>& held, const std::vector<double>& u_held) {
  const index_t n = m.n_nodes, ne = m.n_elems;
  auto corner_u = [&](index_t e, Vec3<double> ue[4], double dN[12]) {
    for (int a = 0; a < 4; ++a) ue[a] = node_u(u, n, m.elem_nodes[a * ne + e]);
    for (int k = 0; k < 12; ++k) dN[k] = m.dndx[k * ne + e];
  };
  std::vector<double> num(n, 0.0), den(n, 0.0), f(3 * n, 0.0);
  for (index_t e = 0; e < ne; ++e) {  // pass 1 and the scatter of pass 2
    Vec3<double> ue[4];
    double dN[12];
    corner_u(e, ue, dN);
    const double pv = volumetric_pressure(det(deformation_gradient(ue, dN)), m.K[e]) * m.volume[e];
    for (int a = 0; a < 4; ++a) {
      num[m.elem_nodes[a * ne + e]] += pv;
      den[m.elem_nodes[a * ne + e]] += m.volume[e];
    }
  }
  for (index_t e = 0; e < ne; ++e) {  // pass 3 and the scatter of pass 4
    Vec3<double> ue[4], fe[4];
    double dN[12];
    corner_u(e, ue, dN);
    double p[4];
    for (int a = 0; a < 4; ++a) p[a] = num[m.elem_nodes[a * ne + e]] / den[m.elem_nodes[a * ne + e]];
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

class CpuBackendTest : public ::testing::TestWithParam<Precision> {
 protected:
  bool is_float() const { return GetParam() == Precision::Float; }
  std::unique_ptr<Backend> make(const TissueModel<double>& m) {
    auto b = make_cpu_backend(GetParam());
    b->upload(m);
    return b;
  }
};

INSTANTIATE_TEST_SUITE_P(Precisions, CpuBackendTest, ::testing::Values(Precision::Float, Precision::Double),
                         [](const auto& info) { return std::string(to_string(info.param)); });

TEST_P(CpuBackendTest, IdentifiesItself) {
  auto b = make_cpu_backend(GetParam());
  EXPECT_EQ(b->name(), "cpu");
  EXPECT_EQ(b->precision(), GetParam());
  EXPECT_NE(b->device_name().find("TBB threads"), std::string::npos) << b->device_name();
  EXPECT_EQ(b->device_name(), cpu_device_name());
}

TEST_P(CpuBackendTest, ZeroForceAtRest) {
  const auto m = box_model(3, true);
  auto b = make(m);
  b->advance(3);
  const Fields f = b->download();
  EXPECT_EQ(max_abs(f.u), 0.0);
  EXPECT_EQ(max_abs(f.f), 0.0);
  EXPECT_EQ(max_abs(f.node_p), 0.0);
  for (double J : f.elem_J) EXPECT_EQ(J, 1.0);
  const Reductions r = b->reduce();
  EXPECT_EQ(r.free_force2 + r.held_force2 + r.kinetic + r.max_disp, 0.0);
  EXPECT_EQ(r.bad_elem, -1);
  EXPECT_TRUE(r.finite);
}

/// Max |f| after one step from a 5% uniaxial stretch: the force scale the
/// rigid-motion tolerances are relative to.
double stretch_force(Backend& b, const TissueModel<double>& m) {
  b.set_displacements(field(m, [](Vec3<double> X) { return Vec3<double>{0.05 * X.x, 0, 0}; }));
  b.advance(1);
  return max_abs(b.download().f);
}

TEST_P(CpuBackendTest, RigidTranslationGivesNoInternalForce) {
  const auto m = box_model(4);
  auto b = make(m);
  const double scale = stretch_force(*b, m);
  ASSERT_GT(scale, 1e-6);
  const auto u = field(m, [](Vec3<double>) { return Vec3<double>{0.003, -0.002, 0.001}; });
  b->set_displacements(u);
  b->advance(1);
  const Fields f = b->download();
  // tolerance: rounding of F = I + sum u_a dN_a^T, relative to the stretch case
  EXPECT_LT(max_abs(f.f), (is_float() ? 1e-4 : 1e-11) * scale);
  EXPECT_LT(max_diff(f.u, u), is_float() ? 1e-9 : 1e-17);  // and nothing moved
}

TEST_P(CpuBackendTest, RigidRotationGivesNoInternalForce) {
  const auto m = box_model(4);
  auto b = make(m);
  const double scale = stretch_force(*b, m);
  // 30 degrees about the axis (1, 2, 3) / |.| through the box centre (Rodrigues)
  const Vec3<double> k = (1.0 / std::sqrt(14.0)) * Vec3<double>{1, 2, 3}, c{kL / 2, kL / 2, kL / 2};
  const double th = M_PI / 6;
  const auto u = field(m, [&](Vec3<double> X) {
    const Vec3<double> r = X - c;
    const Vec3<double> Rr = std::cos(th) * r + std::sin(th) * cross(k, r) + ((1 - std::cos(th)) * dot(k, r)) * k;
    return Rr - r;
  });
  b->set_displacements(u);
  b->advance(1);
  EXPECT_LT(max_abs(b->download().f), (is_float() ? 1e-4 : 1e-11) * scale);
}

TEST_P(CpuBackendTest, PassesMatchASerialReference) {
  for (bool ianp : {true, false}) {
    const auto m = box_model(3, true, ianp);
    auto b = make(m);
    std::vector<double> u = field(m, [](Vec3<double> X) {
      return Vec3<double>{0.04 * X.x * X.z / kL, -0.03 * X.y, 0.02 * X.x - 0.05 * X.z * X.z / kL};
    });
    for (index_t a = 0; a < m.n_nodes; ++a)
      if (m.node_flags[a] & kFixed)
        for (int c = 0; c < 3; ++c) u[c * m.n_nodes + a] = 0;
    b->set_displacements(u);
    std::vector<double> u_prev = u, u_held(u.size(), 0.0), f;
    std::vector<std::uint8_t> held(m.n_nodes);
    for (index_t a = 0; a < m.n_nodes; ++a) held[a] = (m.node_flags[a] & kFixed) ? 1 : 0;
    for (int s = 0; s < 5; ++s) f = reference_step(m, u, u_prev, held, u_held);
    b->advance(5);
    const Fields got = b->download();
    const double f_tol = (is_float() ? 1e-4 : 1e-12) * max_abs(f);  // measured: 2e-6 float, 0 double
    const double u_tol = (is_float() ? 1e-5 : 1e-14) * max_abs(u);  // measured: 2e-6 float, 0 double
    EXPECT_LT(max_diff(got.f, f), f_tol) << "ianp " << ianp;
    EXPECT_LT(max_diff(got.u, u), u_tol) << "ianp " << ianp;
  }
}

/// A scripted run: stretch, drive two nodes, step, release, step. Returns the
/// fields and the reductions bit-for-bit.
struct RunResult {
  Fields fields;
  std::vector<Reductions> red;
};

RunResult scripted_run(Precision p, const TissueModel<double>& m) {
  auto b = make_cpu_backend(p);
  b->upload(m);
  RunResult out;
  b->set_displacements(field(m, [](Vec3<double> X) { return Vec3<double>{0.03 * X.x, 0.01 * X.z, -0.02 * X.z}; }));
  const index_t nodes[] = {box_node(12, 12, 6, 6, 12), box_node(12, 12, 7, 6, 12)};
  const double target[] = {0, 0, -0.001, 0, 0, -0.0012};
  b->set_driven(nodes, target);
  for (int s = 0; s < 4; ++s) {
    b->advance(10);
    out.red.push_back(b->reduce());
  }
  b->clear_driven();
  b->advance(10);
  out.red.push_back(b->reduce());
  out.fields = b->download();
  return out;
}

bool same_bits(const std::vector<double>& a, const std::vector<double>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0;
}

TEST_P(CpuBackendTest, RunsAreBitIdenticalAcrossThreadCounts) {
  const auto m = box_model(12, true);  // 10368 tets, about the kidney's size
  const RunResult a = scripted_run(GetParam(), m);
  RunResult b;
  tbb::task_arena one_thread(1);
  one_thread.execute([&] { b = scripted_run(GetParam(), m); });
  const RunResult c = scripted_run(GetParam(), m);
  for (const RunResult* r : {static_cast<const RunResult*>(&b), &c}) {
    EXPECT_TRUE(same_bits(a.fields.u, r->fields.u));
    EXPECT_TRUE(same_bits(a.fields.f, r->fields.f));
    EXPECT_TRUE(same_bits(a.fields.node_p, r->fields.node_p));
    EXPECT_TRUE(same_bits(a.fields.elem_J, r->fields.elem_J));
    ASSERT_EQ(a.red.size(), r->red.size());
    for (size_t k = 0; k < a.red.size(); ++k)
      EXPECT_EQ(std::memcmp(&a.red[k], &r->red[k], offsetof(Reductions, bad_elem)), 0) << "reduction " << k;
  }
  EXPECT_GT(max_abs(a.fields.f), 0.0);
}

TEST(CpuBackendPrecision, FloatAgreesWithDouble) {
  const auto m = box_model(12, true);
  const RunResult f = scripted_run(Precision::Float, m);
  const RunResult d = scripted_run(Precision::Double, m);
  // Tolerance, relative to the largest value of each field: 2e-4 for
  // displacements and 1e-4 for forces and reductions. The cancellation in
  // F - I and in the Neo-Hookean stress at 5% strain costs float about
  // 1e-6 per step, and 50 explicit steps accumulate it (measured here:
  // u 4.7e-5, f 2.4e-5, reaction 2.2e-5, max |u| 3.2e-5).
  EXPECT_LT(max_diff(f.fields.u, d.fields.u), 2e-4 * max_abs(d.fields.u));
  EXPECT_LT(max_diff(f.fields.f, d.fields.f), 1e-4 * max_abs(d.fields.f));
  for (size_t k = 0; k < d.red.size(); ++k) {
    EXPECT_NEAR(f.red[k].reaction.z, d.red[k].reaction.z, 1e-4 * std::fabs(d.red[k].reaction.z)) << k;
    EXPECT_NEAR(f.red[k].max_disp, d.red[k].max_disp, 1e-4 * d.red[k].max_disp) << k;
  }
  // the driven nodes were pushed down: their internal force f = dW/du points down too
  EXPECT_LT(d.red[3].reaction.z, 0.0);
}

/// The three nodes of a top-face triangle near the middle of a box of n^3 cells.
std::vector<index_t> top_triangle(const TissueModel<double>& m) {
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

TEST_P(CpuBackendTest, RegionRunMovesOnlyRegionNodes) {
  const auto m = box_model(6, true);
  auto b = make(m);
  const auto seeds = top_triangle(m);
  const RegionSizes sz = b->build_region(seeds, 1);
  const Region want = flood_fill(m, std::span<const index_t>(seeds), 1);
  EXPECT_EQ(sz.n_inner, want.n_inner);
  EXPECT_EQ(sz.n_halo, want.n_halo);
  EXPECT_EQ(sz.n_elems, index_t(want.elems.size()));
  const Region got = b->region();
  EXPECT_EQ(got.nodes, want.nodes);
  EXPECT_EQ(got.elems, want.elems);
  EXPECT_EQ(got.role, want.role);
  ASSERT_LT(got.nodes.size(), size_t(m.n_nodes) / 2);

  const double push[] = {0, 0, -0.001, 0, 0, -0.001, 0, 0, -0.001};
  b->set_driven(seeds, push);
  b->advance(30);
  const Fields f = b->download();
  const index_t n = m.n_nodes;
  int moved = 0;
  for (index_t a = 0; a < n; ++a) {
    const Vec3<double> u = node_u(f.u, n, a);
    const bool seed = std::count(seeds.begin(), seeds.end(), a) > 0;
    if (seed) {
      EXPECT_NEAR(u.z, -0.001, is_float() ? 1e-10 : 1e-15) << "driven node " << a;  // float(-0.001)
    } else if (want.role[a] == kInner) {
      moved += norm(u) > 1e-6;
    } else {  // outside and halo nodes stay exactly where they were (at 0)
      EXPECT_EQ(norm(u), 0.0) << "node " << a << " role " << int(want.role[a]);
    }
  }
  EXPECT_GT(moved, 0);
  // the force on the driven nodes pushes back up; it matches the downloaded f
  const Reductions r = b->reduce();
  double fz = 0;
  for (index_t a : seeds) fz += f.f[2 * n + a];
  EXPECT_LT(r.reaction.z, 0);
  EXPECT_NEAR(r.reaction.z, fz, 1e-12 * std::fabs(fz));
}

/// build_region on a moving mesh, with a driven node that becomes halo (body
/// of BuildRegionHaloSemantics, per scalar type).
template <class T>
void check_halo_semantics() {
  const auto m = box_model(6, true);
  cpu::CpuBackend<T> b;
  b.upload(m);
  const T target_z = T(0.0007);
  const index_t n = m.n_nodes;
  // whole mesh in motion: released from a stretch, 20 steps
  b.set_displacements(field(m, [](Vec3<double> X) { return Vec3<double>{0.0, 0.0, 0.05 * X.z}; }));
  b.advance(20);
  const auto seeds = top_triangle(m);
  // a driven node that will end up in the halo of the depth-1 region
  const Region deep = flood_fill(m, std::span<const index_t>(seeds), 2);
  const Region shallow = flood_fill(m, std::span<const index_t>(seeds), 1);
  index_t h = -1;
  for (index_t a = 0; a < n && h < 0; ++a)
    if (shallow.role[a] == kHalo && !(m.node_flags[a] & kFixed)) h = a;
  ASSERT_GE(h, 0);
  ASSERT_EQ(deep.role[h], kInner);
  const double target[] = {0.0, 0.0, 0.0007};
  b.set_driven(std::span<const index_t>(&h, 1), target);

  const std::vector<double> u0(b.state().u.begin(), b.state().u.end());
  ASSERT_GT(max_diff(u0, std::vector<double>(b.state().u_prev.begin(), b.state().u_prev.end())), 0.0);  // moving

  b.build_region(seeds, 1);
  // pass 1 was recomputed over every element, from the current u
  for (index_t e = 0; e < m.n_elems; ++e) {
    Vec3<double> ue[4];
    double dN[12];
    for (int a = 0; a < 4; ++a) ue[a] = node_u(u0, n, m.elem_nodes[a * m.n_elems + e]);
    for (int k = 0; k < 12; ++k) dN[k] = m.dndx[k * m.n_elems + e];
    const double tol = std::is_same_v<T, float> ? 1e-6 : 1e-15;
    ASSERT_NEAR(b.state().elem_J[e], det(deformation_gradient(ue, dN)), tol) << "element " << e;
  }
  b.advance(15);
  const Fields f = b.download();
  int inner_moved = 0;
  for (index_t a = 0; a < n; ++a) {
    const Vec3<double> u = node_u(f.u, n, a), was = node_u(u0, n, a);
    if (m.node_flags[a] & kFixed) {
      EXPECT_EQ(norm(u), 0.0) << "fixed node " << a;
    } else if (a == h) {
      EXPECT_EQ(u.z, double(target_z)) << "driven halo node keeps its target";
    } else if (shallow.role[a] == kInner) {
      inner_moved += norm(u - was) > 0;
    } else {  // halo held at, and outside frozen at, the displacement they had
      EXPECT_EQ(norm(u - was), 0.0) << "node " << a << " role " << int(shallow.role[a]);
      if (shallow.role[a] == kOutside) {
        EXPECT_EQ(norm(node_u(f.f, n, a)), 0.0);
      }
    }
  }
  EXPECT_GT(inner_moved, 0);

  // released, the halo node stays held where it is; a released inner node moves
  b.clear_driven();
  const index_t s0 = seeds[0];
  const double down[] = {0.0, 0.0, -0.0005};
  b.set_driven(std::span<const index_t>(&s0, 1), down);
  b.advance(5);
  b.clear_driven();
  const T s0_z = b.state().u[2 * n + s0];
  b.advance(5);
  EXPECT_EQ(b.state().u[2 * n + h], target_z);
  EXPECT_NE(b.state().u[2 * n + s0], s0_z);
  EXPECT_FALSE(b.state().held[s0]);
  EXPECT_TRUE(b.state().held[h]);
}

TEST_P(CpuBackendTest, BuildRegionHaloSemantics) {
  if (is_float())
    check_halo_semantics<float>();
  else
    check_halo_semantics<double>();
}

/// Moves node `a` of element `e` along -dN_a so that J_e = 1 - amount.
std::vector<double> flip(const TissueModel<double>& m, index_t e, int corner, double amount) {
  const index_t n = m.n_nodes, ne = m.n_elems;
  const Vec3<double> g{m.dndx[(3 * corner) * ne + e], m.dndx[(3 * corner + 1) * ne + e],
                       m.dndx[(3 * corner + 2) * ne + e]};
  std::vector<double> u(3 * n, 0.0);
  const index_t a = m.elem_nodes[corner * ne + e];
  for (int c = 0; c < 3; ++c) u[c * n + a] = -amount * g[c] / dot(g, g);  // J = 1 + dN_a . u_a
  return u;
}

/// Lowest element with det F <= 0 under u (core math), and its J.
std::pair<index_t, double> lowest_inverted(const TissueModel<double>& m, const std::vector<double>& u) {
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

TEST_P(CpuBackendTest, InvertedElementIsReportedOnceThenCleared) {
  for (bool ianp : {true, false}) {
    const auto m = box_model(2, false, ianp);
    auto b = make(m);
    const auto u = flip(m, 29, 3, 1.3);
    const auto [e, J] = lowest_inverted(m, u);
    ASSERT_GE(e, 0);
    b->set_displacements(u);
    b->advance(1);
    const Reductions r = b->reduce();
    EXPECT_EQ(r.bad_elem, e) << "ianp " << ianp;
    EXPECT_NEAR(r.bad_J, J, 1e-6 * std::fabs(J) + 1e-6);  // recorded as float
    EXPECT_EQ(b->reduce().bad_elem, -1);                  // reduce() cleared the flag
  }
}

TEST_P(CpuBackendTest, InvertedElementStopsTheScheduler) {
  const auto m = box_model(2);
  auto b = make(m);
  const auto u = flip(m, 29, 3, 1.3);
  const auto [e, J] = lowest_inverted(m, u);
  ASSERT_GE(e, 0);
  b->set_displacements(u);
  SchedulerSettings settings;
  settings.depth = kDepthAll;
  Scheduler sched(*b, m, settings);
  ScriptedDevice far(std::vector<Waypoint>{{0.0, {1.0, 1.0, 1.0}}});  // never touches the box
  try {
    sched.tick(far);
    FAIL() << "an inverted element did not stop the run";
  } catch (const SimulationError& err) {
    EXPECT_NE(std::string(err.what()).find(fmt::format("element {} ", e)), std::string::npos) << err.what();
  }
}

TEST_P(CpuBackendTest, ReductionsMatchTheirDefinitions) {
  const auto m = box_model(4, true);
  cpu::CpuBackend<double> b;
  b.upload(m);
  const index_t n = m.n_nodes;
  const auto seeds = top_triangle(m);
  b.build_region(seeds, 2);
  const double push[] = {0.0002, 0, -0.001, 0, 0, -0.001, 0, 0.0001, -0.001};
  b.set_driven(seeds, push);
  b.advance(7);
  const Reductions r = b.reduce();
  const auto& s = b.state();
  Vec3<double> reaction{0, 0, 0}, internal{0, 0, 0};
  double free2 = 0, held2 = 0, kinetic = 0, max_disp = 0;
  for (index_t a : s.region.nodes) {
    const Vec3<double> f{s.f[a], s.f[n + a], s.f[2 * n + a]};
    const Vec3<double> v = (1.0 / m.dt) * (Vec3<double>{s.u[a], s.u[n + a], s.u[2 * n + a]} -
                                           Vec3<double>{s.u_prev[a], s.u_prev[n + a], s.u_prev[2 * n + a]});
    kinetic += 0.5 * m.mass[a] * dot(v, v);
    max_disp = std::max(max_disp, norm(Vec3<double>{s.u[a], s.u[n + a], s.u[2 * n + a]}));
    if (s.driven[a]) reaction = reaction + f;
    if (s.region.role[a] != kInner) continue;
    internal = internal + f;
    (s.held[a] ? held2 : free2) += dot(f, f);
  }
  const double tol = 1e-12;
  EXPECT_NEAR(r.reaction.z, reaction.z, tol * std::fabs(reaction.z));
  EXPECT_NEAR(r.reaction.x, reaction.x, tol * norm(reaction));
  EXPECT_NEAR(r.internal.z, internal.z, tol * norm(reaction));
  EXPECT_NEAR(r.free_force2, free2, tol * free2);
  EXPECT_NEAR(r.held_force2, held2, tol * held2);
  EXPECT_NEAR(r.kinetic, kinetic, tol * kinetic);
  EXPECT_EQ(r.max_disp, max_disp);
  EXPECT_GT(free2, 0);
  EXPECT_GT(kinetic, 0);
  EXPECT_TRUE(r.finite);
  EXPECT_EQ(r.bad_elem, -1);
}

TEST_P(CpuBackendTest, WritePositionsGivesDeformedXyzTriples) {
  const auto m = box_model(2);
  auto b = make(m);
  const auto u = field(m, [](Vec3<double> X) { return Vec3<double>{0.01 * X.y, 0.002, -0.03 * X.x}; });
  b->set_displacements(u);
  const index_t n = m.n_nodes;
  std::vector<float> pos(3 * n);
  b->write_positions(pos.data());
  for (index_t i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(pos[3 * i + c], m.X[c * n + i] + u[c * n + i], 1e-8) << i;
}

TEST_P(CpuBackendTest, BadInputIsRejectedWithItsRule) {
  auto fresh = make_cpu_backend(GetParam());
  EXPECT_THROW(fresh->advance(1), std::logic_error);
  EXPECT_THROW(fresh->reduce(), std::logic_error);
  EXPECT_THROW(fresh->collide({0, 0, 0}, {1, 1, 1}), std::logic_error);

  const auto m = box_model(2);
  auto b = make(m);
  const index_t n = m.n_nodes;
  auto message = [](auto&& f) {
    try {
      f();
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("<no exception>");
  };
  std::vector<double> u(3 * n - 1, 0.0);
  EXPECT_NE(message([&] { b->set_displacements(u); }).find(fmt::format("need 3 x n_nodes = {}", 3 * n)),
            std::string::npos);
  u.assign(3 * n, 0.0);
  u[n + 5] = std::nan("");
  EXPECT_NE(message([&] { b->set_displacements(u); }).find("node 5: displacement y"), std::string::npos);
  const index_t nodes[] = {3, n};
  const double t6[6] = {};
  EXPECT_NE(message([&] { b->set_driven(nodes, std::span<const double>(t6, 5)); }).find("5 displacement values"),
            std::string::npos);
  EXPECT_NE(message([&] { b->set_driven(nodes, t6); }).find(fmt::format("node {} out of range", n)), std::string::npos);
  const index_t far[] = {0};
  const index_t seed[] = {n - 1};
  b->build_region(seed, 0);
  EXPECT_NE(message([&] { b->set_driven(far, std::span<const double>(t6, 3)); }).find("node 0 is outside"),
            std::string::npos);
  EXPECT_THROW(b->build_region(seed, -3), std::invalid_argument);
}

}  // namespace
}  // namespace tissue
