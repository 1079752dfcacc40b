#include "scene/checks.hpp"

#include <fmt/format.h>

#include <cmath>
#include <limits>

#include "core/vec.hpp"

namespace tissue::scene {
namespace {

/// The material of element e (its set's), or nullptr.
const Material* material_of(const Scene& s, index_t e) {
  for (const ElementSet& es : s.sets) {
    bool in = es.all;
    for (size_t k = 0; !in && k < es.elements.size(); ++k) in = es.elements[k] == e;
    if (!in) continue;
    for (const Material& m : s.materials)
      if (m.name == es.material) return &m;
  }
  return nullptr;
}

std::string describe(const Material& m) {
  static constexpr const char* kNames[3][2] = {{"E", "nu"}, {"mu", "K"}, {"lambda", "mu"}};
  const auto& n = kNames[static_cast<int>(m.form)];
  const char* unit_b = m.form == Material::Form::YoungPoisson ? "" : " Pa";
  return fmt::format("material '{}' ({} = {} Pa, {} = {}{}, rho = {} kg/m^3)", m.name, n[0], m.a, n[1], m.b, unit_b,
                     m.rho);
}

double path_duration(const Tool& t) {
  return t.path.size() < 2 ? 0 : t.path.back().t - t.path.front().t;
}

}  // namespace

WorkEstimate estimate_work(const TissueModel<double>& m, double tick, double ticks) {
  WorkEstimate w;
  w.steps_per_tick = std::round(tick / m.dt);
  w.ticks = ticks;
  w.steps = w.steps_per_tick * ticks;
  w.element_steps = w.steps * m.n_elems;
  return w;
}

std::string step_cause(const Scene& s, const TissueModel<double>& m) {
  const index_t e = m.dt_crit_elem;
  if (e < 0 || e >= m.n_elems) return "no element";
  const MaterialParams p = material_of(s, e) ? material_of(s, e)->params() : MaterialParams{};
  Vec3<double> X[4];
  for (int a = 0; a < 4; ++a) {
    const index_t i = m.elem_nodes[size_t(a) * m.n_elems + e];
    X[a] = {m.X[i], m.X[size_t(m.n_nodes) + i], m.X[2 * size_t(m.n_nodes) + i]};
  }
  const double c = p.rho > 0 ? wave_speed(p) : 0;
  const Material* mat = material_of(s, e);
  return fmt::format("element {} of {}: wave speed c = {:.4g} m/s across its smallest altitude L = {:.4g} m gives "
                     "dt_crit = L / c = {:.4g} s{}",
                     e, mat ? describe(*mat) : "no material", c, c > 0 ? m.dt_crit_physical * c : 0.0,
                     m.dt_crit_physical,
                     m.scaled_elems > 0 ? fmt::format(" ({:.4g} s after mass scaling)", m.dt_crit) : "");
}

index_t supported_nodes(const TissueModel<double>& m) {
  index_t n = 0;
  for (std::uint8_t f : m.node_flags) n += fixed_axes(f) != 0;
  return n;
}

std::vector<std::string> incompressibility_findings(const Scene& s) {
  const double eps = s.solver.precision == Precision::Float ? std::numeric_limits<float>::epsilon()
                                                             : std::numeric_limits<double>::epsilon();
  std::vector<std::string> out;
  for (const Material& m : s.materials) {
    const MaterialParams p = m.params();
    const double ratio = p.K / p.mu;
    if (!(ratio * eps > 1e-2)) continue;
    out.push_back(fmt::format(
        "{} is nearly incompressible (K / mu = {:.3g}): in {} precision a rounding of J by {:.2g} moves the pressure "
        "by {:.3g} x mu, more than this mesh of linear tets can carry (expect an inverted element, NaN or a pressure "
        "of rounding noise); use "
        "nu <= {:.6g}{}",
        describe(m), ratio, to_string(s.solver.precision), eps, ratio * eps,
        // K / mu = 2 (1 + nu) / (3 (1 - 2 nu)) = 1e-2 / eps, solved for nu
        (3 * (1e-2 / eps) - 2) / (6 * (1e-2 / eps) + 2),
        s.solver.precision == Precision::Float ? " or precision double" : ""));
  }
  return out;
}

std::vector<std::string> scene_warnings(const Scene& s, const TissueModel<double>& m) {
  std::vector<std::string> out;
  const index_t held = supported_nodes(m);
  if (held == 0)
    out.push_back(fmt::format("{}: no node is fixed: nothing holds the body against the tool, so it is pushed away "
                              "as a rigid body and never reaches an equilibrium; add a <fixed> constraint (the "
                              "support)",
                              s.source));
  else if (held == m.n_nodes)
    out.push_back(fmt::format("{}: every node ({}) is fixed: nothing can move, the tool feels no force; fix only "
                              "the support",
                              s.source, m.n_nodes));
  if (m.reoriented > 0)
    out.push_back(fmt::format("{}: {} of {} tetrahedra had a negative volume and were reoriented (corners 1 and 2 "
                              "swapped); check the corner order the mesh was written with",
                              s.source, m.reoriented, m.n_elems));
  const double tick = s.solver.tick;
  for (const Tool& t : s.tools) {  // every scripted tool (a scene may have several)
    if (t.device != "scripted") continue;
    const double d = path_duration(t);
    if (tick > d)
      out.push_back(fmt::format("{}: the haptic tick {:.4g} s is longer than the whole tool path ({:.4g} s) of tool "
                                "'{}': the tool moves from its first to its last waypoint in one tick; use a tick of "
                                "about 1e-3 s",
                                s.source, tick, d, t.name));
  }
  if (tick < 1e-5 || tick > 0.1)
    out.push_back(fmt::format("{}: the haptic tick {:.4g} s is far from a haptic device's period (1e-3 s)", s.source,
                              tick));
  const double steps = std::round(tick / m.dt);
  if (steps > kManyStepsPerTick)
    out.push_back(fmt::format("{}: {:.0f} TLED steps per {:.4g} s tick (typical scenes need 1..20): {}", s.source,
                              steps, tick, step_cause(s, m)));
  for (const std::string& f : incompressibility_findings(s)) out.push_back(fmt::format("{}: {}", s.source, f));
  return out;
}

}  // namespace tissue::scene
