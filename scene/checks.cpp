#include "scene/checks.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include "core/vec.hpp"
#include "scene/constraints.hpp"
#include "scene/validate.hpp"

namespace tissue::scene {
namespace {

/// The material of element e (its set's), or nullptr.
const Material* material_of(const Scene& s, index_t e) {
  for (const ElementSet& es : s.sets) {
    const Body* b = es.body >= 0 && std::size_t(es.body) < s.bodies.size() ? &s.bodies[std::size_t(es.body)] : nullptr;
    bool in = es.all && (!b || (e >= b->first_element && e < b->first_element + b->n_elements));
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
  return fmt::format("material '{}' ({} = {} Pa, {} = {}{}, {}rho = {} kg/m^3)", m.name, n[0], m.a, n[1], m.b, unit_b,
                     m.fibre_eta > 0 ? fmt::format("fibre stiffness eta = {} Pa, ", m.fibre_eta) : std::string(),
                     m.rho);
}

double path_duration(const Tool& t) {
  return t.path.size() < 2 ? 0 : t.path.back().t - t.path.front().t;
}

/// "load box min (..) max (..)": the load's selection in words.
std::string describe_as_load(const Constraint& c) { return "load" + describe(c).substr(5); }

/// A warning for each <load> whose force lands only on nodes fixed in every
/// component: the support takes the whole force and the body feels nothing.
void fixed_load_warnings(const Scene& s, const TissueModel<double>& m, std::vector<std::string>& out) {
  for (const Load& l : s.loads) {
    Scene one = s;  // the nodes this load alone acts on (an area load: its faces' corners)
    one.loads = {l};
    SceneLoads r;
    try {
      r = resolve_loads(one, m);
    } catch (const SceneError&) {
      continue;  // a load that cannot be applied is an error where the loads are applied
    }
    if (r.nodes.empty()) continue;
    const bool all_fixed = std::all_of(r.nodes.begin(), r.nodes.end(),
                                       [&](index_t a) { return fixed_axes(m.node_flags[a]) == kAllAxes; });
    if (all_fixed)
      out.push_back(fmt::format("{}: {} acts only on fixed nodes ({} node(s), every one held by a <fixed> "
                                "constraint): the support takes its whole force and the body does not feel it; "
                                "move the load or the support",
                                location(s, l.where.line), describe_as_load(l.where), r.nodes.size()));
  }
}


/// A warning for each piece of a mesh of several that no constraint holds
/// (the body as a whole is held): the tool pushes that piece away as a rigid
/// body, as it would a body with no support at all.
void unsupported_piece_warnings(const Scene& s, const TissueModel<double>& m, std::vector<std::string>& out) {
  std::vector<index_t> piece;
  const index_t n = mesh_pieces(m, piece);
  if (n < 2) return;
  std::vector<index_t> elems(n, 0), first(n, -1);
  std::vector<std::uint8_t> held(n, 0);
  for (index_t a = 0; a < m.n_nodes; ++a)
    if (piece[a] >= 0 && fixed_axes(m.node_flags[a]) != 0) held[piece[a]] = 1;
  for (index_t e = 0; e < m.n_elems; ++e) {
    const index_t p = piece[m.elem_nodes[e]];
    ++elems[p];
    if (first[p] < 0) first[p] = e;
  }
  for (index_t p = 0; p < n; ++p) {
    if (held[p]) continue;
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (index_t a = 0; a < m.n_nodes; ++a)
      if (piece[a] == p)
        for (int c = 0; c < 3; ++c) {
          lo[c] = std::min(lo[c], m.X[size_t(c) * m.n_nodes + a]);
          hi[c] = std::max(hi[c], m.X[size_t(c) * m.n_nodes + a]);
        }
    std::string body;  // in a scene of bodies, the body the piece belongs to
    for (const Body& b : s.bodies)
      if (first[p] >= b.first_element && first[p] < b.first_element + b.n_elements)
        body = elems[p] == b.n_elements ? fmt::format(" (all of body '{}')", b.name)
                                        : fmt::format(" (of body '{}')", b.name);
    out.push_back(fmt::format("{}: piece {} of the {} disconnected pieces of the mesh{} ({} element(s) from element "
                              "{}, box ({:.4g}, {:.4g}, {:.4g}) .. ({:.4g}, {:.4g}, {:.4g}) m) has no fixed node: "
                              "nothing holds it against the tool, so it is pushed away as a rigid body; fix a node "
                              "of it, or join it to the body",
                              s.source, p + 1, n, body, elems[p], first[p], lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]));
  }
}

}  // namespace

index_t mesh_pieces(const TissueModel<double>& m, std::vector<index_t>& piece) {
  std::vector<index_t> parent(m.n_nodes);
  std::iota(parent.begin(), parent.end(), 0);
  auto root = [&](index_t a) {
    while (parent[a] != a) a = parent[a] = parent[parent[a]];
    return a;
  };
  for (index_t e = 0; e < m.n_elems; ++e)
    for (int c = 1; c < 4; ++c) {
      const index_t a = root(m.elem_nodes[e]), b = root(m.elem_nodes[size_t(c) * m.n_elems + e]);
      if (a != b) parent[std::max(a, b)] = std::min(a, b);
    }
  piece.assign(m.n_nodes, -1);
  std::vector<index_t> id(m.n_nodes, -1);
  index_t n = 0;
  for (index_t e = 0; e < m.n_elems; ++e)  // pieces numbered by their lowest element
    for (int c = 0; c < 4; ++c) {
      const index_t a = m.elem_nodes[size_t(c) * m.n_elems + e], r = root(a);
      if (id[r] < 0) id[r] = n++;
      piece[a] = id[r];
    }
  return n;
}

StepCost nominal_step_cost(const std::string& backend) {
  if (backend == "cuda") return {1.5e-5, 1e-10};
  return {2e-6, 1.5e-8};
}

WorkEstimate estimate_work(const TissueModel<double>& m, double tick, double ticks, const std::string& backend) {
  WorkEstimate w;
  w.steps_per_tick = std::max(1.0, std::round(tick / m.dt));
  w.ticks = ticks;
  w.steps = w.steps_per_tick * ticks;
  w.element_steps = w.steps * m.n_elems;
  const StepCost c = nominal_step_cost(backend);
  w.seconds = w.steps * c.per_step + w.element_steps * c.per_element;
  return w;
}

std::vector<std::string> stop_causes(const Scene& s, const TissueModel<double>& m, const SceneLoads* host_loads) {
  std::vector<std::string> out;
  double softest_E = INFINITY;
  for (const Material& mat : s.materials) {
    const MaterialParams p = mat.params();
    const double E = youngs_modulus(p);  // from any pair of constants
    softest_E = std::min(softest_E, E);
    if (E < kTissueE[0] || E > kTissueE[1])
      out.push_back(fmt::format("{}: Young's modulus E = {:.4g} Pa is far outside soft tissue's 1e3..1e6 Pa (check "
                                "the value and its unit, Pa)",
                                location(s, mat.line) + ": material '" + mat.name + "'", E));
    if (mat.rho < kTissueRho[0] || mat.rho > kTissueRho[1])
      out.push_back(fmt::format("{}: material '{}': density rho = {:.4g} kg/m^3 is far from soft tissue's ~1000 "
                                "kg/m^3 (check the value and its unit, kg/m^3)",
                                location(s, mat.line), mat.name, mat.rho));
    if (mat.fibre_eta > 1e3 * p.mu)
      out.push_back(fmt::format("{}: material '{}': fibre stiffness eta = {:.4g} Pa is {:.3g} x its shear modulus "
                                "mu = {:.4g} Pa (fibres are stiffer than the matrix by 1..1e3)",
                                location(s, mat.fibre_line ? mat.fibre_line : mat.line), mat.name, mat.fibre_eta,
                                mat.fibre_eta / p.mu, p.mu));
    for (size_t k = 0; k < mat.prony.size(); ++k)
      if (mat.prony[k].tau < m.dt)
        out.push_back(fmt::format("{}: material '{}': Prony term {}: tau = {:.4g} s is shorter than the step dt = "
                                  "{:.4g} s, so the term relaxes within one step (its modulus g = {:g} drops at once "
                                  "instead of acting as a viscosity); use a tau of many steps or remove the term",
                                  location(s, mat.prony[k].line ? mat.prony[k].line : mat.line), mat.name, k + 1,
                                  mat.prony[k].tau, m.dt, mat.prony[k].g));
  }
  // the body's largest extent: the loads' nominal stress F / L^2 over it is a lower bound of the stress they cause
  double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
  for (index_t a = 0; a < m.n_nodes; ++a)
    for (int c = 0; c < 3; ++c) {
      lo[c] = std::min(lo[c], m.X[size_t(c) * m.n_nodes + a]);
      hi[c] = std::max(hi[c], m.X[size_t(c) * m.n_nodes + a]);
    }
  const double L = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
  const auto nominal_stress = [&](const SceneLoads& r, double& F) {
    double f[3] = {0, 0, 0};
    for (size_t k = 0; k < r.nodes.size(); ++k)
      for (int c = 0; c < 3; ++c) f[c] += r.force[3 * k + c];
    F = std::sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]);
    return F / (L * L);
  };
  if (host_loads != nullptr) {
    double F = 0;
    const double stress = nominal_stress(*host_loads, F);
    if (L > 0 && stress > kMaxLoadStrain * softest_E)
      out.push_back(fmt::format("the loads set through the API (set_loads, on {} node{}): their total force {:.4g} N "
                                "over the body's extent L = {:.4g} m squared is a nominal stress F / L^2 = {:.4g} Pa, "
                                "{:.3g} x the softest material's E = {:.4g} Pa (a strain far beyond what the elements "
                                "can follow); check the forces (N, 3 per node)",
                                host_loads->nodes.size(), host_loads->nodes.size() == 1 ? "" : "s", F, L, stress,
                                stress / softest_E, softest_E));
  }
  for (const Load& l : host_loads != nullptr ? std::vector<Load>{} : s.loads) {
    Scene one = s;
    one.loads = {l};
    SceneLoads r;
    try {
      r = resolve_loads(one, m);
    } catch (const SceneError&) {
      continue;
    }
    double F = 0;
    const double stress = nominal_stress(r, F);
    if (L > 0 && stress > kMaxLoadStrain * softest_E)
      out.push_back(fmt::format("{}: {}: its total force {:.4g} N over the body's extent L = {:.4g} m squared is a "
                                "nominal stress F / L^2 = {:.4g} Pa, {:.3g} x the softest material's E = {:.4g} Pa "
                                "(a strain far beyond what the elements can follow); check the force (N){}",
                                location(s, l.where.line), describe_as_load(l.where), F, L, stress,
                                stress / softest_E, softest_E, l.each ? ", given to each of the selected nodes" : ""));
  }
  for (const std::string& c : incompressibility_findings(s)) out.push_back(c);
  if (supported_nodes(m) == 0) out.push_back("no node is fixed (nothing holds the body)");
  return out;
}

std::string stop_cause_text(const Scene& s, const TissueModel<double>& m, const SceneLoads* host_loads) {
  const std::vector<std::string> causes = stop_causes(s, m, host_loads);
  if (causes.empty())
    return "\n  the scene checks found no material, load or support problem: a tool has most likely pressed deeper "
           "than the elements under it can follow (reduce the indentation or refine the mesh there)";
  std::string out = "\n  likely cause:";
  for (const std::string& c : causes) out += "\n    " + c;
  return out;
}

std::string step_cause(const Scene& s, const TissueModel<double>& m) {
  const index_t e = m.dt_crit_elem;
  if (e < 0 || e >= m.n_elems) return "no element";
  const Material* mat = material_of(s, e);
  MaterialParams p = mat ? mat->params() : MaterialParams{};
  // the moduli the step was computed from: IANP takes the bulk modulus of the element's stiffest corner where
  // materials of different K meet (core build_model)
  bool corner_K = false;
  if (m.ianp && s.materials.size() > 1) {
    const std::vector<double> node_K = node_bulk_moduli(m);
    for (int a = 0; a < 4; ++a)
      if (const double k = node_K[m.elem_nodes[size_t(a) * m.n_elems + e]]; k > p.K) {
        p.K = k;
        corner_K = true;
      }
  }
  const double c = p.rho > 0 ? wave_speed(p) : 0;
  return fmt::format("element {} of {}{}: wave speed {} across its smallest altitude L = {:.4g} m{} gives "
                     "dt_crit = L / c = {:.4g} s{}",
                     e, mat ? describe(*mat) : "no material",
                     corner_K ? fmt::format(" (its stiffest corner's K = {:.4g} Pa, IANP)", p.K) : std::string(),
                     p.rho > 0 ? wave_speed_text(p) : std::string("c = 0 m/s"), c > 0 ? m.dt_crit_physical * c : 0.0,
                     m.ianp ? "" : " (x 0.85 for a plain tet)", m.dt_crit_physical,
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
  if (held > 0) unsupported_piece_warnings(s, m, out);
  fixed_load_warnings(s, m, out);
  // coordinates are metres: a body far outside an organ's size is most likely in other units
  const double extent = mesh_box(s.nodes).largest_extent();
  if (extent > kMaxBodyExtent || (extent > 0 && extent < kMinBodyExtent))
    out.push_back(fmt::format("{}: the body is {:.4g} m across, far from an organ's size ({:g}..{:g} m): "
                              "coordinates are read in metres; check the mesh's units (tissue mesh --unit)",
                              s.source, extent, kMinBodyExtent, kMaxBodyExtent));
  // a Prony term that relaxes within one step never acts as a viscosity at the simulated rates
  for (const Material& mat : s.materials)
    for (size_t k = 0; k < mat.prony.size(); ++k)
      if (mat.prony[k].tau < m.dt)
        out.push_back(fmt::format("{}: material '{}': Prony term {}: tau = {:.4g} s is shorter than the step dt = "
                                  "{:.4g} s: the term relaxes within one step, so its g = {:g} acts as if it were "
                                  "not there (the long-term modulus from the start); use a tau of many steps or "
                                  "remove the term",
                                  location(s, mat.prony[k].line ? mat.prony[k].line : mat.line), mat.name, k + 1,
                                  mat.prony[k].tau, m.dt, mat.prony[k].g));
  if (s.solver.damping) {
    // mass-proportional damping alpha gives the lowest mode the damping ratio alpha / (2 omega_1) (auto: 1,
    // critical); far above it the body creeps with the time constant alpha / omega_1^2 instead of responding
    const double omega = lowest_mode_estimate(m), alpha = *s.solver.damping;
    if (omega > 0 && alpha > kMaxDampingPerMode * omega)
      out.push_back(fmt::format(
          "{}: solver: damping = {:g} 1/s is {:.3g} times the lowest mode's {:.4g} rad/s (more than {:.0f}): the body "
          "is overdamped and creeps to the tool with a time constant of about alpha / omega^2 = {:.3g} s instead of "
          "responding within the run; use \"auto\" ({:.4g} 1/s, critical) or a damping below {:.4g} 1/s",
          location(s, s.solver.line), alpha, alpha / omega, omega, kMaxDampingPerMode, alpha / (omega * omega),
          2 * omega, kMaxDampingPerMode * omega));
  }
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
