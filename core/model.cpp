#include "core/model.hpp"

#include <algorithm>
#include <cmath>
#include <fmt/format.h>
#include <limits>
#include <array>

#include "core/tet.hpp"

namespace tissue {
namespace {

Vec3<double> node_pos(const std::vector<double>& xyz, index_t i) {
  return {xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]};
}

/// The optional terms of material k (core/material.hpp): docs/materials.md's rules.
void check_law_terms(const ModelInput& in, size_t k, const MaterialParams& m) {
  const auto fail = [&](const std::string& why) {
    throw ModelError(fmt::format("{}: material {}: {}", in.source, k, why));
  };
  if (!(m.fibre_eta >= 0) || !std::isfinite(m.fibre_eta))
    fail(fmt::format("fibre stiffness eta = {} Pa must be finite and >= 0", m.fibre_eta));
  const Vec3<double> a = m.fibre_dir;
  if (m.fibre_eta > 0 && !(norm(a) > 0 && std::isfinite(norm(a))))
    fail(fmt::format("fibre direction ({}, {}, {}) must be finite and non-zero", a.x, a.y, a.z));
  if (m.prony_terms < 0 || m.prony_terms > kMaxProny)
    fail(fmt::format("{} Prony terms given; 0..{} are allowed", m.prony_terms, kMaxProny));
  double sum = 0;
  for (int i = 0; i < m.prony_terms; ++i) {
    if (!(m.prony_g[i] > 0) || !std::isfinite(m.prony_g[i]))
      fail(fmt::format("Prony term {}: g = {} must be > 0", i + 1, m.prony_g[i]));
    if (!(m.prony_tau[i] > 0) || !std::isfinite(m.prony_tau[i]))
      fail(fmt::format("Prony term {}: tau = {} s must be > 0", i + 1, m.prony_tau[i]));
    sum += m.prony_g[i];
  }
  if (!(sum < 1))
    fail(fmt::format("the Prony moduli sum to {} (must be < 1: the relaxed shear modulus mu (1 - sum g) must "
                     "stay > 0)",
                     sum));
}

void check_materials(const ModelInput& in) {
  if (in.materials.empty()) throw ModelError(in.source + ": no material given");
  for (size_t k = 0; k < in.materials.size(); ++k) {
    const auto& m = in.materials[k];
    if (!(m.mu > 0) || !std::isfinite(m.mu))
      throw ModelError(fmt::format("{}: material {}: shear modulus mu = {} must be > 0", in.source, k, m.mu));
    if (!(m.K > 0) || !std::isfinite(m.K))
      throw ModelError(fmt::format("{}: material {}: bulk modulus K = {} must be > 0", in.source, k, m.K));
    if (!(m.rho > 0) || !std::isfinite(m.rho))
      throw ModelError(fmt::format("{}: material {}: density rho = {} must be > 0", in.source, k, m.rho));
    check_law_terms(in, k, m);
  }
}

/// Why a tet with corners X and signed volume V cannot be used, or "" when
/// it can. The test is relative to the tet's own size, |V| <= 1e-12 x (its
/// longest edge)^3 (a flat tet: four corners within 1e-12 of an edge of one
/// plane), so that it means the same at any scale; coordinates so large or
/// so large or so small that the volume or the squared face areas (edge^4,
/// used for the altitudes) leave the range of a double are named as such
/// rather than as a flat tet.
std::string degenerate_tet(const Vec3<double> X[4], double V) {
  double edge = 0;
  for (int a = 0; a < 4; ++a)
    for (int b = a + 1; b < 4; ++b) edge = std::max(edge, norm(X[b] - X[a]));
  const double scale = edge * edge * edge, scale4 = scale * edge;  // squared face areas go as edge^4
  if (!std::isfinite(V) || !std::isfinite(scale4))
    return fmt::format("its volume overflows a double (longest edge {:.3g} m); coordinates are read in metres: "
                       "rescale the mesh",
                       edge);
  if (edge == 0) return "all four corners are at the same point (zero volume); tets must have V > 0";
  if (scale4 < 1e-290)
    return fmt::format("its volume underflows a double (longest edge {:.3g} m); coordinates are read in metres: "
                       "rescale the mesh",
                       edge);
  if (std::fabs(V) <= 1e-12 * scale)
    return fmt::format("zero volume: V = {:.3g} m^3 is {:.2g} x its longest edge ({:.3g} m) cubed, a flat tet; tets "
                       "must have V > 0",
                       V, std::fabs(V) / scale, edge);
  return "";
}

/// Throws naming both elements when two tets have the same four nodes (in
/// any order): a duplicated tet doubles the mass and stiffness there.
void check_duplicates(const ModelInput& in, index_t ne) {
  std::vector<std::pair<std::array<index_t, 4>, index_t>> keys(ne);
  for (index_t e = 0; e < ne; ++e) {
    std::array<index_t, 4> k;
    for (int a = 0; a < 4; ++a) k[a] = in.tets[4 * size_t(e) + a];
    std::sort(k.begin(), k.end());
    keys[e] = {k, e};
  }
  std::sort(keys.begin(), keys.end());
  for (size_t i = 1; i < keys.size(); ++i)
    if (keys[i].first == keys[i - 1].first) {
      const auto& k = keys[i].first;
      throw ModelError(fmt::format("{}: elements {} and {} have the same four nodes ({} {} {} {}); a duplicated "
                                   "tetrahedron doubles the mass and stiffness there: remove one",
                                   in.source, keys[i - 1].second, keys[i].second, k[0], k[1], k[2], k[3]));
    }
}

/// Name of material k for messages: "material 'brain'" or "material 2".
std::string material_name(const ModelInput& in, size_t k) {
  return k < in.material_names.size() ? fmt::format("material '{}'", in.material_names[k])
                                      : fmt::format("material {}", k);
}

/// The moduli element e's stable step is computed from: its material's, with
/// IANP's bulk modulus of its stiffest corner where materials of different K
/// meet (interface_steps).
MaterialParams step_params(const ModelInput& in, const TissueModel<double>& m, index_t e) {
  MaterialParams p = in.materials[in.elem_material.empty() ? 0 : size_t(in.elem_material[e])];
  if (m.ianp && in.materials.size() > 1) {
    const std::vector<double> node_K = node_bulk_moduli(m);
    for (int a = 0; a < 4; ++a) p.K = std::max(p.K, node_K[m.elem_nodes[size_t(a) * m.n_elems + e]]);
  }
  return p;
}

/// Refuses a model whose stable step would need more than kMaxStepsPerTick
/// steps per haptic tick, naming the element, its material's values and the
/// wave speed that set it (the cause is a modulus or density far outside
/// tissue's range, or a unit mistake, not a step the user chose).
void check_step_count(const ModelInput& in, const TissueModel<double>& m, double safety) {
  if (!(in.tick > 0)) return;
  const double steps = in.tick / (safety * m.dt_crit);
  if (!(steps > kMaxStepsPerTick)) return;
  if (!(in.tick / m.dt_crit > kMaxStepsPerTick))  // the material is fine: the safety factor asks for it
    throw ModelError(fmt::format("{}: dt safety factor {:.3g} makes dt = {:.3g} x dt_crit ({:.4g} s) = {:.3g} s: one "
                                 "{:.4g} s haptic tick would need {:.3g} TLED steps (the most is {:.0e}); use a "
                                 "safety factor of about 0.9",
                                 in.source, safety, safety, m.dt_crit, safety * m.dt_crit, in.tick, steps,
                                 kMaxStepsPerTick));
  const index_t e = m.dt_crit_elem;
  const size_t k = in.elem_material.empty() ? 0 : size_t(in.elem_material[e]);
  const MaterialParams p = step_params(in, m, e);  // the moduli the step was computed from
  const double c = wave_speed(p);
  const bool fibre_sets_it = fibre_wave_modulus(p.fibre_eta) > p.K + 4 * p.mu / 3;
  // a tissue-like material with a tiny element: the mesh's size (its unit), not the material
  const double E = youngs_modulus(p);
  if (!fibre_sets_it && E >= 1e2 && E <= 1e7 && p.rho >= 100 && p.rho <= 1e4)
    throw ModelError(fmt::format(
        "{}: element {} is {:.4g} m small (its smallest altitude) in a body {:.4g} m across, so its stable step "
        "is dt_crit = L / c = {:.4g} s at the wave speed {:.4g} m/s of its material ('{}', E = {:.4g} Pa, rho = "
        "{:.4g} kg/m^3, soft tissue's): one {:.4g} s haptic tick would need {:.3g} TLED steps (the most is "
        "{:.0e}). The mesh is far too small for an organ (5e-3..1 m across); check its unit: node coordinates "
        "are metres",
        in.source, e, m.dt_crit * c, largest_extent(m), m.dt_crit, c, material_name(in, k), E, p.rho, in.tick,
        steps, kMaxStepsPerTick));
  throw ModelError(fmt::format(
      "{}: element {} ({}: mu = {:.4g} Pa, K = {:.4g} Pa{}{}, rho = {:.4g} kg/m^3) has a wave speed {}, so its "
      "stable step is dt_crit = L / c = {:.4g} s (L = {:.4g} m, its smallest altitude{}): one {:.4g} s haptic tick "
      "would need {:.3g} TLED steps (the most is {:.0e}). The {} is far too high or the density far too low for "
      "tissue (soft tissue: E ~ 1e3..1e6 Pa, rho ~ 1000 kg/m^3); check the units (Pa, kg/m^3)",
      in.source, e, material_name(in, k), p.mu, p.K, p.K > in.materials[k].K ? " (its stiffest corner's, IANP)" : "",
      p.fibre_eta > 0 ? fmt::format(", fibre stiffness eta = {:.4g} Pa", p.fibre_eta) : std::string(), p.rho,
      wave_speed_text(p), m.dt_crit, m.dt_crit * c, in.ianp ? "" : " x 0.85 for a plain tet", in.tick, steps,
      kMaxStepsPerTick, fibre_sets_it ? "fibre stiffness" : "modulus"));
}

/// Boundary faces (faces owned by one tet), oriented outward. Sorts all
/// 4 n_elems faces by their sorted corner ids; a face seen once is boundary.
void extract_surface(TissueModel<double>& m) {
  // Face opposite corner k, ordered so that its normal points away from corner k
  // for a positively oriented tet.
  static constexpr int kFace[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};
  struct Face {
    std::array<index_t, 3> key;  // sorted corner ids
    index_t elem;
    int corner;
  };
  const index_t ne = m.n_elems;
  std::vector<Face> faces;
  faces.reserve(4 * size_t(ne));
  for (index_t e = 0; e < ne; ++e)
    for (int k = 0; k < 4; ++k) {
      std::array<index_t, 3> f{m.elem_nodes[kFace[k][0] * ne + e], m.elem_nodes[kFace[k][1] * ne + e],
                               m.elem_nodes[kFace[k][2] * ne + e]};
      std::sort(f.begin(), f.end());
      faces.push_back({f, e, k});
    }
  std::sort(faces.begin(), faces.end(), [](const Face& a, const Face& b) {
    return a.key != b.key ? a.key < b.key : a.elem < b.elem;
  });
  std::vector<index_t> tri;  // (n_tris x 3) while collecting
  for (size_t i = 0; i < faces.size();) {
    size_t j = i + 1;
    while (j < faces.size() && faces[j].key == faces[i].key) ++j;
    if (j - i == 1) {
      const Face& f = faces[i];
      for (int v = 0; v < 3; ++v) tri.push_back(m.elem_nodes[kFace[f.corner][v] * ne + f.elem]);
      m.tri_elem.push_back(f.elem);
    }
    i = j;
  }
  m.n_tris = static_cast<index_t>(m.tri_elem.size());
  m.tris.resize(tri.size());  // component-major (3 x n_tris)
  for (index_t t = 0; t < m.n_tris; ++t)
    for (int v = 0; v < 3; ++v) m.tris[v * m.n_tris + t] = tri[3 * t + v];
  for (index_t t = 0; t < 3 * m.n_tris; ++t) m.node_flags[m.tris[t]] |= kSurface;
  // surface nodes and, per surface node, its (triangle, corner) slots in ascending order
  std::vector<index_t> surf_of(m.n_nodes, -1);
  for (index_t a = 0; a < m.n_nodes; ++a)
    if (m.node_flags[a] & kSurface) {
      surf_of[a] = static_cast<index_t>(m.surf_nodes.size());
      m.surf_nodes.push_back(a);
    }
  m.n_surf = static_cast<index_t>(m.surf_nodes.size());
  m.surf_slot_start.assign(m.n_surf + 1, 0);
  for (index_t t = 0; t < m.n_tris; ++t)
    for (int k = 0; k < 3; ++k) ++m.surf_slot_start[surf_of[tri[3 * t + k]] + 1];
  for (index_t i = 0; i < m.n_surf; ++i) m.surf_slot_start[i + 1] += m.surf_slot_start[i];
  m.surf_slot.assign(3 * size_t(m.n_tris), 0);
  std::vector<index_t> fill(m.surf_slot_start.begin(), m.surf_slot_start.end() - 1);
  for (index_t t = 0; t < m.n_tris; ++t)
    for (int k = 0; k < 3; ++k) m.surf_slot[fill[surf_of[tri[3 * t + k]]]++] = 3 * t + k;
}

/// Density factor that lifts an element's step dt_e to `need` (1 if it has it).
double density_scale(double dt_e, double need) { return dt_e < need ? (need / dt_e) * (need / dt_e) : 1.0; }

/// Mass that scaling adds to lift every dt_e to `need` (kg), with the count
/// of scaled elements and the largest factor.
MassScaling mass_needed(const std::vector<double>& dt_e, const std::vector<double>& rho_V, double need) {
  MassScaling r;
  r.need = need;
  for (size_t e = 0; e < dt_e.size(); ++e)
    if (const double s = density_scale(dt_e[e], need); s > 1) {
      r.added_mass += (s - 1) * rho_V[e];
      ++r.scaled_elems;
      r.max_scale = std::max(r.max_scale, s);
    }
  return r;
}

/// The optional terms' per-element data (core/material.hpp), allocated only
/// when a set uses them. The Prony constants follow in set_time_step.
void fill_law_terms(const ModelInput& in, TissueModel<double>& m) {
  const index_t ne = m.n_elems;
  const auto material = [&](index_t e) -> const MaterialParams& {
    return in.materials[in.elem_material.empty() ? 0 : in.elem_material[e]];
  };
  bool fibre = false, visco = false;
  for (const MaterialParams& p : in.materials) {
    fibre = fibre || p.fibre_eta > 0;
    visco = visco || p.prony_terms > 0;
  }
  if (fibre) {
    m.fibre.assign(4 * size_t(ne), 0.0);
    for (index_t e = 0; e < ne; ++e) {
      const MaterialParams& p = material(e);
      if (!(p.fibre_eta > 0)) continue;
      Vec3<double> a = p.fibre_dir;
      if (!in.fibre_dirs.empty()) {  // the element's own direction (a fibre field or file)
        a = node_pos(in.fibre_dirs, e);
        const double len = norm(a);
        if (!(len > 0) || !std::isfinite(len) || !std::isfinite(a.x) || !std::isfinite(a.y) || !std::isfinite(a.z)) {
          const size_t k = in.elem_material.empty() ? 0 : size_t(in.elem_material[e]);
          throw ModelError(fmt::format("{}: element {} ({}, fibre stiffness {} Pa): fibre direction ({}, {}, {}) "
                                       "must be finite and non-zero (fibre_dirs gives every fibre element a "
                                       "direction)",
                                       in.source, e, material_name(in, k), p.fibre_eta, a.x, a.y, a.z));
        }
      }
      a = (1.0 / norm(a)) * a;
      for (int c = 0; c < 3; ++c) m.fibre[c * ne + e] = a[c];
      m.fibre[3 * ne + e] = p.fibre_eta;
    }
  }
  if (!visco) return;
  m.visco_slot.assign(ne, -1);
  for (index_t e = 0; e < ne; ++e)
    if (material(e).prony_terms > 0) {
      m.visco_slot[e] = m.n_visco++;
      m.n_prony = std::max(m.n_prony, material(e).prony_terms);
    }
  m.prony_g.assign(m.n_prony * size_t(m.n_visco), 0.0);
  m.prony_tau.assign(m.n_prony * size_t(m.n_visco), 1.0);
  for (index_t e = 0; e < ne; ++e) {
    const index_t v = m.visco_slot[e];
    if (v < 0) continue;
    const MaterialParams& p = material(e);
    for (int i = 0; i < p.prony_terms; ++i) {
      m.prony_g[i * size_t(m.n_visco) + v] = p.prony_g[i];
      m.prony_tau[i * size_t(m.n_visco) + v] = p.prony_tau[i];
    }
  }
}

}  // namespace

double wave_speed(const MaterialParams& p) {
  const double lambda = p.K - 2.0 * p.mu / 3.0;
  return std::sqrt((lambda + 2 * p.mu + fibre_wave_modulus(p.fibre_eta)) / p.rho);
}

std::string wave_speed_text(const MaterialParams& p) {
  const bool fibre = p.fibre_eta > 0;
  return fmt::format("c = sqrt((K + 4 mu / 3{}) / rho) = sqrt(({:.4g} Pa + 4 x {:.4g} Pa / 3{}) / {:.4g} kg/m^3) = "
                     "{:.4g} m/s",
                     fibre ? " + 4 eta" : "", p.K, p.mu,
                     fibre ? fmt::format(" + 4 x {:.4g} Pa", p.fibre_eta) : std::string(), p.rho, wave_speed(p));
}

double element_time_step(const Vec3<double> X[4], double volume, const MaterialParams& p, bool ianp) {
  // Plain tets are stiffer than IANP ones: their measured stability limit
  // (2 / omega_max of the lumped linearised system) is 0.89..0.94 of
  // L / c for nu in 0.3..0.499, so their L_e carries a 0.85 factor.
  return (ianp ? 1.0 : 0.85) * tet_min_altitude(X, volume) / wave_speed(p);
}

void align_time_step(TissueModel<double>& m, double tick) {
  if (!(tick > 0)) throw ModelError(fmt::format("haptic tick {} s must be > 0", tick));
  const double steps = std::ceil(tick / m.dt * (1 - 1e-12));
  if (steps > kMaxStepsPerTick)
    throw ModelError(fmt::format("time step dt = {:.4g} s would need {:.3g} steps per {:.4g} s haptic tick (the most "
                                 "is {:.0e})",
                                 m.dt, steps, tick, kMaxStepsPerTick));
  set_time_step(m, tick / steps, m.damping);
}

MassScaling choose_mass_scaling(const std::vector<double>& dt_e, const std::vector<double>& rho_V, double tick,
                                double safety, double budget) {
  double total = 0, dt_min = std::numeric_limits<double>::infinity();
  for (size_t e = 0; e < dt_e.size(); ++e) {
    total += rho_V[e];
    dt_min = std::min(dt_min, dt_e[e]);
  }
  // n steps without scaling suffice; the added mass falls as n grows (each
  // element's need dt / safety does), so bisect for the fewest within budget
  const long unscaled = std::max(1L, long(std::min(1e9, std::ceil(tick / (safety * dt_min) * (1 - 1e-12)))));
  long lo = 1, hi = unscaled;
  while (lo < hi) {
    const long mid = lo + (hi - lo) / 2;
    if (mass_needed(dt_e, rho_V, tick / double(mid) / safety).added_mass <= budget * total)
      hi = mid;
    else
      lo = mid + 1;
  }
  MassScaling r = lo < unscaled ? mass_needed(dt_e, rho_V, tick / double(lo) / safety) : MassScaling{};
  r.steps = int(lo);
  r.dt = tick / double(lo);
  r.need = r.dt / safety;
  return r;
}

double largest_extent(const TissueModel<double>& m) {
  double L = 0;
  for (int c = 0; c < 3; ++c) {
    const auto axis = m.X.begin() + std::ptrdiff_t(c) * m.n_nodes;
    const auto [lo, hi] = std::minmax_element(axis, axis + m.n_nodes);
    L = std::max(L, *hi - *lo);
  }
  return L;
}

double lowest_mode_estimate(const TissueModel<double>& m) {
  const double L = largest_extent(m);
  double vol = 0, mu_v = 0;
  for (index_t e = 0; e < m.n_elems; ++e) {
    vol += m.volume[e];
    mu_v += m.mu[e] * m.volume[e];
  }
  const double rho = m.total_mass / vol;
  return 0.5 * M_PI * std::sqrt(mu_v / vol / rho) / L;
}

void set_time_step(TissueModel<double>& m, double dt, double damping) {
  if (!(dt > 0) || !std::isfinite(dt)) throw ModelError(fmt::format("time step dt = {} s must be > 0", dt));
  if (dt > m.dt_crit)
    throw ModelError(fmt::format(
        "time step dt = {:.6g} s is above the stable limit dt_crit = {:.6g} s set by element {} "
        "(min_e L_e / c_e); use dt <= {:.6g} s or a safety factor < 1",
        dt, m.dt_crit, m.dt_crit_elem, m.dt_crit));
  if (!(damping >= 0) || !std::isfinite(damping))
    throw ModelError(fmt::format("damping alpha = {} 1/s must be >= 0", damping));
  m.dt = dt;
  m.damping = damping;
  m.cd_A.resize(m.n_nodes);
  m.cd_B.resize(m.n_nodes);
  m.cd_C.resize(m.n_nodes);
  for (index_t i = 0; i < m.n_nodes; ++i) {
    const auto k = central_difference_constants(m.mass[i], dt, damping);
    m.cd_A[i] = k.A;
    m.cd_B[i] = k.B;
    m.cd_C[i] = k.C;
  }
  m.prony_decay.resize(m.prony_g.size());
  m.prony_gain.resize(m.prony_g.size());
  for (size_t k = 0; k < m.prony_g.size(); ++k) {
    if (m.prony_g[k] > 0)
      prony_constants(m.prony_g[k], m.prony_tau[k], dt, &m.prony_decay[k], &m.prony_gain[k]);
    else
      m.prony_decay[k] = m.prony_gain[k] = 0;  // an unused term: q stays 0
  }
}

namespace {

/// build_model's first step: the input's sizes, finiteness and masks.
void check_input(const ModelInput& in) {
  if (in.nodes.size() % 3 != 0) throw ModelError(in.source + ": node coordinate count is not a multiple of 3");
  if (in.tets.size() % 4 != 0) throw ModelError(in.source + ": element corner count is not a multiple of 4");
  const size_t n = in.nodes.size() / 3, ne = in.tets.size() / 4;
  if (n < 4 || ne < 1) throw ModelError(in.source + ": the mesh needs at least one tetrahedron");
  check_materials(in);
  for (size_t k = 0; k < in.nodes.size(); ++k)
    if (!std::isfinite(in.nodes[k]))
      throw ModelError(fmt::format("{}: node {}: coordinate {} is not finite", in.source, k / 3, "xyz"[k % 3]));
  if (!in.elem_material.empty() && in.elem_material.size() != ne)
    throw ModelError(fmt::format("{}: {} element material ids for {} elements", in.source, in.elem_material.size(), ne));
  if (!in.fixed.empty() && in.fixed.size() != n)
    throw ModelError(fmt::format("{}: {} fixed flags for {} nodes", in.source, in.fixed.size(), n));
  if (!in.fibre_dirs.empty() && in.fibre_dirs.size() != 3 * ne)
    throw ModelError(fmt::format("{}: {} fibre direction components for {} elements; fibre_dirs holds x y z per "
                                 "element ({} numbers) or is empty",
                                 in.source, in.fibre_dirs.size(), ne, 3 * ne));
  if (!in.fixed_axes.empty() && in.fixed_axes.size() != n)
    throw ModelError(fmt::format("{}: {} fixed-axis masks for {} nodes", in.source, in.fixed_axes.size(), n));
  for (size_t i = 0; i < in.fixed_axes.size(); ++i)
    if (in.fixed_axes[i] > kAllAxes)
      throw ModelError(fmt::format("{}: node {}: fixed-axis mask {} has bits beyond x, y, z (must be 0..7)", in.source,
                                   i, int(in.fixed_axes[i])));
  if (in.dt < 0 || std::isnan(in.dt))
    throw ModelError(fmt::format("{}: time step dt = {} s must be > 0 (or 0 for the default)", in.source, in.dt));
  if (in.damping && !(*in.damping >= 0 && std::isfinite(*in.damping)))
    throw ModelError(fmt::format("{}: damping alpha = {} 1/s must be finite and >= 0 (or unset for the default)",
                                 in.source, *in.damping));
  if (!(in.dt_safety > 0 && in.dt_safety < 1) && (in.dt == 0 || in.mass_scaling > 0))
    throw ModelError(fmt::format("{}: dt safety factor {} must be in (0, 1)", in.source, in.dt_safety));
  if (!(in.mass_scaling >= 0 && in.mass_scaling < 1))
    throw ModelError(fmt::format("{}: mass scaling budget {} must be in [0, 1) (a fraction of the total mass)",
                                 in.source, in.mass_scaling));
}

/// Each element's stable step and mass, for mass scaling (build_model's geometry step fills them).
struct ElementSteps {
  std::vector<double> dt;     ///< L_e / c_e (s)
  std::vector<double> rho_V;  ///< rho_e V_e (kg)
};

/// build_model's geometry step: corners, volumes (inverted tets reoriented), shape gradients, materials,
/// lumped masses, each element's stable step and dt_crit; `uses` counts each node's elements.
ElementSteps element_geometry(const ModelInput& in, TissueModel<double>& m, std::vector<index_t>& uses) {
  const index_t n = m.n_nodes, ne = m.n_elems;
  m.X.resize(3 * n);
  for (index_t i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) m.X[c * n + i] = in.nodes[3 * i + c];
  m.elem_nodes.resize(4 * ne);
  m.dndx.resize(12 * ne);
  m.volume.resize(ne);
  m.mu.resize(ne);
  m.K.resize(ne);
  m.mass.assign(n, 0.0);
  m.dt_crit = std::numeric_limits<double>::infinity();
  uses.assign(n, 0);
  ElementSteps steps{std::vector<double>(ne), std::vector<double>(ne)};
  for (index_t e = 0; e < ne; ++e) {
    index_t c[4];
    for (int a = 0; a < 4; ++a) {
      c[a] = in.tets[4 * e + a];
      if (c[a] < 0 || c[a] >= n)
        throw ModelError(fmt::format("{}: element {}: corner {} refers to node {}, but there are {} nodes", in.source,
                                     e, a, c[a], n));
      for (int b = 0; b < a; ++b)
        if (c[b] == c[a])
          throw ModelError(fmt::format("{}: element {}: node {} appears twice (zero-volume tet)", in.source, e, c[a]));
    }
    Vec3<double> X[4];
    for (int a = 0; a < 4; ++a) X[a] = node_pos(in.nodes, c[a]);
    double dN[12] = {};
    double V = tet_shape_gradients(X, dN);
    if (const std::string why = degenerate_tet(X, V); !why.empty())
      throw ModelError(
          fmt::format("{}: element {} (nodes {} {} {} {}): {}", in.source, e, c[0], c[1], c[2], c[3], why));
    if (V < 0) {  // inverted input: swap corners 1 and 2
      std::swap(c[1], c[2]);
      std::swap(X[1], X[2]);
      V = tet_shape_gradients(X, dN);
      ++m.reoriented;
    }
    const index_t mat = in.elem_material.empty() ? 0 : in.elem_material[e];
    if (mat < 0 || size_t(mat) >= in.materials.size())
      throw ModelError(fmt::format("{}: element {}: material index {} out of range (0..{})", in.source, e, mat,
                                   in.materials.size() - 1));
    const MaterialParams& p = in.materials[mat];
    for (int a = 0; a < 4; ++a) {
      m.elem_nodes[a * ne + e] = c[a];
      m.mass[c[a]] += p.rho * V / 4;
      ++uses[c[a]];
    }
    for (int k = 0; k < 12; ++k) m.dndx[k * ne + e] = dN[k];
    m.volume[e] = V;
    m.mu[e] = p.mu;
    m.K[e] = p.K;
    m.total_mass += p.rho * V;
    steps.dt[e] = element_time_step(X, V, p, in.ianp);
    steps.rho_V[e] = p.rho * V;
    if (steps.dt[e] < m.dt_crit) {
      m.dt_crit = steps.dt[e];
      m.dt_crit_elem = e;
    }
  }
  return steps;
}

/// build_model's adjacency step: every node used (its flags from the fixed masks), the node -> (element,
/// corner) lists sorted by element for a deterministic gather, and each corner's slot in them.
void node_adjacency(const ModelInput& in, TissueModel<double>& m, const std::vector<index_t>& uses) {
  const index_t n = m.n_nodes, ne = m.n_elems;
  m.node_flags.assign(n, 0);
  for (index_t i = 0; i < n; ++i)
    if (uses[i] == 0)
      throw ModelError(fmt::format("{}: node {} belongs to no element (every node needs mass)", in.source, i));
    else if (!in.fixed.empty() && in.fixed[i])
      m.node_flags[i] |= kFixed;
    else if (!in.fixed_axes.empty())
      m.node_flags[i] |= std::uint8_t(in.fixed_axes[i] << 2);
  m.node_elem_start.assign(n + 1, 0);
  for (index_t i = 0; i < n; ++i) m.node_elem_start[i + 1] = m.node_elem_start[i] + uses[i];
  m.node_elem.resize(4 * ne);
  std::vector<index_t> fill(m.node_elem_start.begin(), m.node_elem_start.end() - 1);
  for (index_t e = 0; e < ne; ++e)
    for (int a = 0; a < 4; ++a) m.node_elem[fill[m.elem_nodes[a * ne + e]]++] = incident_entry(e, a);
  m.elem_slot.resize(4 * size_t(ne));
  for (size_t k = 0; k < m.node_elem.size(); ++k)
    m.elem_slot[size_t(incident_corner(m.node_elem[k])) * ne + incident_element(m.node_elem[k])] = static_cast<index_t>(k);
}

/// IANP where materials of different K meet: an element's pressure comes from its corners' K_a
/// (node_bulk_moduli), so its stable step is that of the stiffest corner's K.
void interface_steps(const ModelInput& in, TissueModel<double>& m, ElementSteps& steps) {
  if (!m.ianp || in.materials.size() <= 1) return;
  const index_t ne = m.n_elems;
  const std::vector<double> node_K = node_bulk_moduli(m);
  for (index_t e = 0; e < ne; ++e) {
    double K = m.K[e];
    for (int a = 0; a < 4; ++a) K = std::max(K, node_K[m.elem_nodes[a * ne + e]]);
    if (!(K > m.K[e])) continue;
    Vec3<double> X[4];
    for (int a = 0; a < 4; ++a) X[a] = node_pos(in.nodes, m.elem_nodes[a * ne + e]);
    const index_t mat = in.elem_material.empty() ? 0 : in.elem_material[e];
    MaterialParams p = in.materials[mat];  // the fibre's share of the step too
    p.K = K;
    steps.dt[e] = element_time_step(X, m.volume[e], p, true);
    if (steps.dt[e] < m.dt_crit) {
      m.dt_crit = steps.dt[e];
      m.dt_crit_elem = e;
    }
  }
}

/// The assembled mesh's stable step where mass scaling raised elements: 2 / omega_max of the lumped,
/// linearised system at rest, estimated by power iteration over the scaled elements and the ring of
/// elements around them (their nodes move; every element touching one of those nodes adds its
/// stiffness; the nodes beyond are held). Each element's stiffness is plain linear elasticity with its
/// step's moduli (the stiffest corner's K at an IANP interface, and the fibre's wave modulus as an
/// isotropic factor), stiffer than IANP's averaged pressure. Each element's own L_e / c_e holds the
/// step of a mesh of well-shaped elements (the default kidney: dt 0.81 of this limit), but not of the
/// pieces a cut leaves: on the kidney cut across three times it was 1.14 of it, and the whole mesh
/// stepped at it inverted an element in the cut within 20 ticks. Where dt exceeds kAssembledShare of
/// the limit, the nodes that carry at least kAssembledKinetic of the mode's largest nodal kinetic
/// energy get mass, 1.05 (dt / (kAssembledShare limit))^2 times theirs, round after round (each from the
/// fixed start again, so that the next mode is found), within the mass scaling budget. Where the
/// rounds or the budget do not bring it down, the mass they gave is taken back and dt falls to that
/// share (to a whole number of steps per tick); a dt the input asks for is refused instead.
constexpr double kAssembledShare = 0.95;
constexpr double kAssembledKinetic = 0.05;
constexpr int kAssembledRounds = 12;

struct AssembledStep {
  double limit = 0;       ///< 2 / omega_max (s); 0 when nothing was iterated
  double added_mass = 0;  ///< kg given to nodes
  index_t nodes = 0;      ///< nodes given mass
};

AssembledStep hold_assembled_step(const ModelInput& in, TissueModel<double>& m, const std::vector<double>& scale,
                                  double& dt, double budget_left) {
  AssembledStep out;
  const index_t n = m.n_nodes, ne = m.n_elems;
  // the nodes that move: those of the scaled elements and of the elements that share one of them
  std::vector<std::uint8_t> movable(n, 0), touched(n, 0);
  for (index_t e = 0; e < ne; ++e)
    if (scale[e] > 1)
      for (int a = 0; a < 4; ++a) movable[m.elem_nodes[a * ne + e]] = 1;
  std::vector<std::uint8_t> ring(ne, 0);
  for (index_t e = 0; e < ne; ++e)
    for (int a = 0; a < 4; ++a) ring[e] |= movable[m.elem_nodes[a * ne + e]];
  for (index_t e = 0; e < ne; ++e)
    if (ring[e])
      for (int a = 0; a < 4; ++a) movable[m.elem_nodes[a * ne + e]] = 1;
  for (index_t a = 0; a < n; ++a)
    if (m.node_flags[a] & kFixed) movable[a] = 0;
  // every element with a moving node adds its stiffness (the nodes beyond them are held)
  std::vector<index_t> patch, nodes;
  for (index_t e = 0; e < ne; ++e) {
    bool moves = false;
    for (int a = 0; a < 4; ++a) moves = moves || movable[m.elem_nodes[a * ne + e]];
    if (!moves) continue;
    patch.push_back(e);
    for (int a = 0; a < 4; ++a) touched[m.elem_nodes[a * ne + e]] = 1;
  }
  for (index_t a = 0; a < n; ++a)
    if (touched[a]) nodes.push_back(a);
  if (patch.empty()) return out;
  // each patch element's moduli: mu, lambda from its step's K, and the fibre as a factor on the stress
  const std::vector<double> node_K = m.ianp && in.materials.size() > 1 ? node_bulk_moduli(m) : std::vector<double>{};
  std::vector<double> mu_e(patch.size()), lambda_e(patch.size()), factor_e(patch.size(), 1.0);
  for (std::size_t k = 0; k < patch.size(); ++k) {
    const index_t e = patch[k];
    double K = m.K[e];
    if (!node_K.empty())
      for (int a = 0; a < 4; ++a) K = std::max(K, node_K[m.elem_nodes[a * ne + e]]);
    mu_e[k] = m.mu[e];
    lambda_e[k] = K - 2 * m.mu[e] / 3;
    if (m.has_fibre()) factor_e[k] += fibre_wave_modulus(m.fibre[3 * size_t(ne) + e]) / (K + 4 * m.mu[e] / 3);
  }
  // y = K x over the patch (x is zero at held nodes)
  const auto stiffness = [&](const std::vector<double>& x, std::vector<double>& y) {
    for (const index_t a : nodes)
      for (int i = 0; i < 3; ++i) y[3 * size_t(a) + i] = 0;
    for (std::size_t k = 0; k < patch.size(); ++k) {
      const index_t e = patch[k];
      double H[3][3] = {};
      for (int a = 0; a < 4; ++a) {
        const index_t node = m.elem_nodes[a * ne + e];
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) H[i][j] += x[3 * size_t(node) + i] * m.dndx[(3 * a + j) * size_t(ne) + e];
      }
      const double mu = mu_e[k], tr = H[0][0] + H[1][1] + H[2][2], f = factor_e[k] * m.volume[e];
      double S[3][3];
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) S[i][j] = mu * (H[i][j] + H[j][i]) + (i == j ? lambda_e[k] * tr : 0.0);
      for (int a = 0; a < 4; ++a) {
        const index_t node = m.elem_nodes[a * ne + e];
        for (int i = 0; i < 3; ++i) {
          double sum = 0;
          for (int j = 0; j < 3; ++j) sum += S[i][j] * m.dndx[(3 * a + j) * size_t(ne) + e];
          y[3 * size_t(node) + i] += f * sum;
        }
      }
    }
  };
  std::vector<double> x(3 * size_t(n), 0.0), y(3 * size_t(n), 0.0);
  // power iteration on M^-1 K from a fixed pseudo-random start (every mode has a share), until the
  // residual |K x - w2 M x| (in M^-1) is within 1e-3 w2 |x| (in M), at most 2,000 iterations
  const auto omega2 = [&]() {
    for (const index_t a : nodes)
      for (int i = 0; i < 3; ++i) {
        std::uint64_t h = (std::uint64_t(a) * 3 + std::uint64_t(i) + 1) * 0x9E3779B97F4A7C15ull;
        h ^= h >> 29;
        h *= 0xBF58476D1CE4E5B9ull;
        h ^= h >> 32;
        x[3 * size_t(a) + i] = movable[a] ? double(h % 2001) / 1000.0 - 1.0 : 0.0;
      }
    double w2 = 0;
    for (int it = 0; it < 2000; ++it) {
      stiffness(x, y);
      double xKx = 0, xMx = 0;
      for (const index_t a : nodes)
        for (int i = 0; i < 3; ++i) {
          const size_t k = 3 * size_t(a) + i;
          xKx += x[k] * y[k];
          xMx += m.mass[a] * x[k] * x[k];
        }
      if (!(xMx > 0)) return 0.0;
      w2 = xKx / xMx;
      double r2 = 0, big = 0;
      for (const index_t a : nodes) {
        if (!movable[a]) continue;
        for (int i = 0; i < 3; ++i) {
          const size_t k = 3 * size_t(a) + i;
          const double r = y[k] - w2 * m.mass[a] * x[k];
          r2 += r * r / m.mass[a];
          x[k] = y[k] / m.mass[a];
          big = std::max(big, std::fabs(x[k]));
        }
      }
      if (r2 <= 1e-6 * w2 * w2 * xMx || !(big > 0)) break;
      for (const index_t a : nodes)
        for (int i = 0; i < 3; ++i) x[3 * size_t(a) + i] /= big;
    }
    return w2;
  };
  const std::vector<double> mass_before = m.mass;
  std::vector<std::uint8_t> given(n, 0);
  for (int round = 0;; ++round) {
    const double w2 = omega2();
    if (!(w2 > 0)) return out;
    const double limit = 2 / std::sqrt(w2);
    if (round == 0) out.limit = limit;
    const double over = dt / (kAssembledShare * limit);
    if (over <= 1) {
      out.limit = limit;
      return out;
    }
    // the mode's nodes, by their kinetic energy in it (x is the last iterate)
    const auto kinetic = [&](index_t a) {
      const double* v = &x[3 * size_t(a)];
      return m.mass[a] * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    };
    double most = 0, more = 0;
    for (const index_t a : nodes) most = std::max(most, kinetic(a));
    for (const index_t a : nodes)
      if (movable[a] && kinetic(a) >= kAssembledKinetic * most) more += m.mass[a] * (1.05 * over * over - 1);
    if (round == kAssembledRounds || out.added_mass + more > budget_left) {
      // the mass does not bring it down within the rounds and the budget: a smaller step instead
      m.mass = mass_before;
      out = {limit, 0, 0};
      if (in.dt > 0)
        throw ModelError(fmt::format(
            "{}: time step dt = {:.6g} s is above {} of the assembled mesh's stable limit {:.6g} s (2 / omega_max "
            "of the lumped system over the mass-scaled elements), and mass scaling's budget ({:.3g} %) cannot "
            "bring it down; use a smaller dt or a larger mass-scaling budget",
            in.source, in.dt, kAssembledShare, limit, 100 * in.mass_scaling));
      dt = kAssembledShare * limit;
      if (in.tick > 0) {
        const double steps = std::ceil(in.tick / dt * (1 - 1e-12));
        if (steps > kMaxStepsPerTick)
          throw ModelError(fmt::format("{}: the assembled mesh's stable limit {:.6g} s would need {:.3g} steps per "
                                       "{:.4g} s haptic tick (the most is {:.0e})",
                                       in.source, limit, steps, in.tick, kMaxStepsPerTick));
        dt = in.tick / steps;
      }
      return out;
    }
    for (const index_t a : nodes) {
      if (!movable[a] || !(kinetic(a) >= kAssembledKinetic * most)) continue;
      const double extra = m.mass[a] * (1.05 * over * over - 1);
      m.mass[a] += extra;
      out.added_mass += extra;
      out.nodes += !given[a];
      given[a] = 1;
    }
  }
}

/// build_model's time step: the requested or safe dt, selective mass scaling within its budget, the
/// damping, and the central difference's constants.
void choose_time_step(const ModelInput& in, TissueModel<double>& m, const ElementSteps& steps) {
  m.dt_crit_physical = m.dt_crit;
  if (in.dt == 0) check_step_count(in, m, in.dt_safety);
  double dt = in.dt > 0 ? in.dt : in.dt_safety * m.dt_crit;
  m.elem_step = steps.dt;  // mass scaling below raises the scaled elements'
  m.elem_mass = steps.rho_V;
  if (in.mass_scaling > 0) {
    MassScaling ms;
    if (in.dt > 0) {  // lift every element to the requested step
      ms = mass_needed(steps.dt, steps.rho_V, in.dt / in.dt_safety);
      if (ms.added_mass > in.mass_scaling * m.total_mass)
        throw ModelError(fmt::format(
            "{}: time step dt = {:.6g} s is above the stable limit dt_crit = {:.6g} s set by element {} "
            "(min_e L_e / c_e), and lifting every element to dt / safety = {:.6g} s by mass scaling needs "
            "{:.3g} % added mass on {} elements (budget {:.3g} %); use a smaller dt or a larger mass-scaling budget",
            in.source, in.dt, m.dt_crit, m.dt_crit_elem, ms.need, 100 * ms.added_mass / m.total_mass,
            ms.scaled_elems, 100 * in.mass_scaling));
    } else if (in.tick > 0) {
      ms = choose_mass_scaling(steps.dt, steps.rho_V, in.tick, in.dt_safety, in.mass_scaling);
      dt = ms.dt;
    } else {
      throw ModelError(fmt::format("{}: mass scaling needs a haptic tick or an explicit dt to aim at", in.source));
    }
    if (ms.scaled_elems > 0) {
      const index_t ne = m.n_elems;
      std::vector<double> scale(ne, 1.0);
      for (index_t e = 0; e < ne; ++e)
        if (const double s_e = density_scale(steps.dt[e], ms.need); s_e > 1) {
          scale[e] = s_e;
          for (int a = 0; a < 4; ++a) m.mass[m.elem_nodes[a * ne + e]] += (s_e - 1) * steps.rho_V[e] / 4;
          m.elem_step[e] *= std::sqrt(s_e);
          m.elem_mass[e] *= s_e;
        }
      m.dt_crit = ms.need;  // every scaled element now has dt_e = need; the others had more
      m.added_mass = ms.added_mass;
      m.scaled_elems = ms.scaled_elems;
      m.max_density_scale = ms.max_scale;
      const AssembledStep held =
          hold_assembled_step(in, m, scale, dt, std::max(0.0, in.mass_scaling * m.total_mass - m.added_mass));
      m.added_mass += held.added_mass;
      m.assembled_step = held.limit;
      m.assembled_nodes = held.nodes;
      m.assembled_mass = held.added_mass;
    }
  }
  const double damping = in.damping ? *in.damping : 2.0 * lowest_mode_estimate(m);
  try {
    set_time_step(m, dt, damping);
  } catch (const ModelError& err) {
    throw ModelError(in.source + ": " + err.what());
  }
}

}  // namespace

TissueModel<double> build_model(const ModelInput& in) {
  check_input(in);
  TissueModel<double> m;
  m.n_nodes = static_cast<index_t>(in.nodes.size() / 3);
  m.n_elems = static_cast<index_t>(in.tets.size() / 4);
  m.ianp = in.ianp;
  std::vector<index_t> uses;
  ElementSteps steps = element_geometry(in, m, uses);
  check_duplicates(in, m.n_elems);
  fill_law_terms(in, m);
  node_adjacency(in, m, uses);
  interface_steps(in, m, steps);
  extract_surface(m);
  choose_time_step(in, m, steps);
  return m;
}

ReferenceGrid reference_grid(const TissueModel<double>& m) {
  ReferenceGrid g;
  if (m.n_nodes == 0) return g;
  Vec3<double> hi = reference_position(m, 0);
  g.origin = hi;
  for (index_t a = 1; a < m.n_nodes; ++a) {
    const Vec3<double> x = reference_position(m, a);
    g.origin = {std::fmin(g.origin.x, x.x), std::fmin(g.origin.y, x.y), std::fmin(g.origin.z, x.z)};
    hi = {std::fmax(hi.x, x.x), std::fmax(hi.y, x.y), std::fmax(hi.z, x.z)};
  }
  const double extent = std::fmax(hi.x - g.origin.x, std::fmax(hi.y - g.origin.y, hi.z - g.origin.z));
  if (!(extent > 0) || !std::isfinite(extent)) return g;
  g.step = std::ldexp(1.0, std::ilogb(extent) - 30);  // extent / step in [2^30, 2^31)
  if (!(g.step > 0)) {  // an extent below 2^-1044 m (no model build_model accepts): one point
    g.step = 1;
    return g;
  }
  if (extent / g.step > kMaxGridSteps) g.step *= 2;
  return g;
}

GridPoint grid_point(const ReferenceGrid& g, const TissueModel<double>& m, index_t a) {
  const Vec3<double> x = reference_position(m, a);
  auto steps = [&](double v, double o) { return static_cast<std::int32_t>(std::llround((v - o) / g.step)); };
  return {steps(x.x, g.origin.x), steps(x.y, g.origin.y), steps(x.z, g.origin.z), 0};
}

GradientDeviation worst_gradient_deviation(const TissueModel<double>& m, Precision p, double stop_above) {
  const index_t ne = m.n_elems;
  const ReferenceGrid grid = reference_grid(m);
  GradientDeviation worst;
  for (index_t e = 0; e < ne; ++e) {
    double dN[12];
    for (int k = 0; k < 12; ++k) dN[k] = m.dndx[k * size_t(ne) + e];
    double d;
    if (p == Precision::Float) {
      GridPoint q[4];
      for (int a = 0; a < 4; ++a) q[a] = grid_point(grid, m, m.elem_nodes[a * ne + e]);
      float dN_f[12];
      const float V = tet_shape_gradients_on_grid<float>(q, static_cast<float>(grid.step), dN_f);
      d = gradient_deviation(dN_f, V, dN, m.volume[e]);
    } else {
      Vec3<double> X[4];
      for (int a = 0; a < 4; ++a) X[a] = reference_position(m, m.elem_nodes[a * ne + e]);
      d = shape_gradient_deviation<double>(X, dN, m.volume[e]);
    }
    if (!(d <= worst.deviation)) worst = {d, e};
    if (!(worst.deviation <= stop_above)) break;
  }
  return worst;
}

template <class T>
TissueModel<T> convert(const TissueModel<double>& m) {
  TissueModel<T> r;
  r.n_nodes = m.n_nodes;
  r.n_elems = m.n_elems;
  r.n_tris = m.n_tris;
  r.n_surf = m.n_surf;
  r.n_visco = m.n_visco;
  r.n_prony = m.n_prony;
  // every array of core/store.hpp's lists and the law terms', element-wise to its type at T
#define TISSUE_STORE_CONVERT(name, ...) r.name.assign(m.name.begin(), m.name.end());
#define TISSUE_LAW_CONVERT(kind, name, len) TISSUE_STORE_CONVERT(name)
  TISSUE_MODEL_ARRAYS(TISSUE_STORE_CONVERT)
  TISSUE_LAW_MODEL_FIELDS(TISSUE_LAW_CONVERT)
#undef TISSUE_LAW_CONVERT
#undef TISSUE_STORE_CONVERT
  r.dt = m.dt;
  r.dt_crit = m.dt_crit;
  r.dt_crit_elem = m.dt_crit_elem;
  r.damping = m.damping;
  r.total_mass = m.total_mass;
  r.added_mass = m.added_mass;
  r.scaled_elems = m.scaled_elems;
  r.max_density_scale = m.max_density_scale;
  r.dt_crit_physical = m.dt_crit_physical;
  r.reoriented = m.reoriented;
  r.ianp = m.ianp;
  return r;
}

template TissueModel<float> convert<float>(const TissueModel<double>&);
template TissueModel<double> convert<double>(const TissueModel<double>&);

template <class T>
double median_surface_edge(const TissueModel<T>& m) {
  const index_t n = m.n_nodes, nt = m.n_tris;
  std::vector<double> len;
  len.reserve(3 * std::size_t(nt));
  for (index_t t = 0; t < nt; ++t)
    for (int k = 0; k < 3; ++k) {
      const index_t a = m.tris[k * nt + t], b = m.tris[((k + 1) % 3) * nt + t];
      double d2 = 0;
      for (int c = 0; c < 3; ++c) d2 += (double(m.X[c * n + a]) - m.X[c * n + b]) * (double(m.X[c * n + a]) - m.X[c * n + b]);
      len.push_back(std::sqrt(d2));
    }
  if (len.empty()) return 0;
  std::nth_element(len.begin(), len.begin() + long(len.size() / 2), len.end());
  return len[len.size() / 2];
}

template double median_surface_edge(const TissueModel<float>&);
template double median_surface_edge(const TissueModel<double>&);

}  // namespace tissue
