#include "apps/viewer/session.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <limits>
#include <memory>

#include "apps/commands.hpp"
#include "backends/registry.hpp"
#include "scene/validate.hpp"

namespace tissue::viewer {

void young_poisson(const MaterialParams& m, double* E, double* nu) {
  *E = youngs_modulus(m);
  *nu = poisson_ratio(m);
}

scene::Scene with_params(scene::Scene s, const LiveParams& p) {
  if (p.E > 0)
    for (scene::Material& m : s.materials) {
      m.form = scene::Material::Form::YoungPoisson;
      m.a = p.E;
      m.b = p.nu;
    }
  for (scene::Material& m : s.materials) {
    if (p.fibre_eta >= 0) {
      m.fibre_eta = p.fibre_eta;
      if (!m.fibre_line) m.fibre_line = m.line;  // validated as a <fibre> of the material (direction: x)
    }
    if (p.prony_terms >= 0) {
      m.prony.clear();
      for (int i = 0; i < std::min(p.prony_terms, kMaxProny); ++i) m.prony.push_back({p.prony_g[i], p.prony_tau[i], m.line});
    }
  }
  if (p.friction >= 0)
    for (scene::Tool& t : s.tools) t.friction = p.friction;
  if (p.scalpel && !s.tools.empty() && s.tools.front().kind != scene::Tool::Kind::Blade) {
    scene::Tool& t = s.tools.front();  // its path, device and direction kept; the button cuts
    t.kind = scene::Tool::Kind::Blade;
    t.radius = 0.5 * kScalpelThickness;
    t.shaft = kScalpelLength;
  }
  s.solver.depth = p.depth;
  s.solver.precision = p.precision;
  return s;
}

Simulated build_simulation(const scene::Scene& base, const LiveParams& p) {
  scene::Scene s = with_params(base, p);
  // a blade's cuts are a Session's; every other scene runs its engine alone, as it always has
  if (has_blade(s)) return std::make_unique<tissue::Session>(std::move(s));
  return build_engine(s);
}

EngineFactory Session::factory() const {
  auto shared = std::make_shared<const scene::Scene>(scene);
  return [shared](const LiveParams& p) { return build_simulation(*shared, p); };
}

Session make_session(scene::Scene scene, const std::string& backend, const std::string& precision,
                     const std::string& depth) {
  if (!backend.empty()) scene.solver.backend = backend;
  if (!precision.empty()) scene.solver.precision = app::parse_precision(precision);
  if (!depth.empty()) scene.solver.depth = app::parse_depth(depth);
  scene::validate(scene);
  Session s;
  s.params.depth = scene.solver.depth;
  s.params.scalpel = !scene.tools.empty() && scene.tools.front().kind == scene::Tool::Kind::Blade;
  s.params.precision = scene.solver.precision;
  // one material: its (E, nu), which rebuild the same model; several: E = 0
  // keeps them all until the user sets one E and nu for every set
  if (!scene.materials.empty()) young_poisson(scene.materials.front().params(), &s.params.E, &s.params.nu);
  if (scene.materials.size() != 1) s.params.E = 0;
  if (scene.materials.size() == 1) {  // its fibre and Prony terms, edited live; several: the scene's
    const scene::Material& m = scene.materials.front();
    s.params.fibre_eta = m.fibre_eta;
    s.params.prony_terms = int(std::min<size_t>(m.prony.size(), kMaxProny));
    for (int i = 0; i < s.params.prony_terms; ++i) {
      s.params.prony_g[i] = m.prony[i].g;
      s.params.prony_tau[i] = m.prony[i].tau;
    }
  }
  // the tools' friction, edited live for all of them; tools that differ: the scene's until then
  s.params.friction = scene.tools.empty() ? 0 : scene.tools.front().friction;
  for (const scene::Tool& t : scene.tools)
    if (t.friction != s.params.friction) s.params.friction = -1;
  const double inf = std::numeric_limits<double>::infinity();
  s.bounds = {{inf, inf, inf}, {-inf, -inf, -inf}};
  for (size_t i = 0; i + 2 < scene.nodes.size(); i += 3)
    for (int c = 0; c < 3; ++c) {
      s.bounds.lo[c] = std::min(s.bounds.lo[c], scene.nodes[i + c]);
      s.bounds.hi[c] = std::max(s.bounds.hi[c], scene.nodes[i + c]);
    }
  s.press_dir = {0, 0, -1};
  s.approach = 0.1 * s.bounds.diagonal();
  s.tool_start = s.bounds.center() + Vec3<double>{0, 0, 0.5 * (s.bounds.hi.z - s.bounds.lo.z) + 0.1 * s.bounds.diagonal()};
  if (!scene.tools.empty()) {
    const scene::Tool& tool = scene.tools.front();
    s.tool_radius = tool.radius;
    if (!tool.path.empty()) {
      s.tool_start = tool.path.front().p;
      for (const Waypoint& w : tool.path)
        if (norm(w.p - s.tool_start) > 1e-9) {
          s.approach = norm(w.p - s.tool_start);
          s.press_dir = (1.0 / s.approach) * (w.p - s.tool_start);
          break;
        }
    }
  }
  s.scene = std::move(scene);
  return s;
}

}  // namespace tissue::viewer
