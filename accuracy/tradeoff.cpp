#include "accuracy/tradeoff.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <cmath>
#include <memory>
#include <optional>

#include "accuracy/point_locator.hpp"
#include "accuracy/reference.hpp"
#include "accuracy/remesh.hpp"
#include "backends/registry.hpp"
#include "core/scheduler.hpp"
#include "scene/validate.hpp"
#include "session/engine.hpp"

namespace tissue::accuracy {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

std::string depth_name(int d) {
  if (d == kDepthAll) return "all";
  if (d == kDepthAuto) return "auto";
  return std::to_string(d);
}

/// The reference of one mesh: the tool held at its indentation.
struct RefEntry {
  HeldTool tool;
  ReferenceSolution ref;
};

/// One mesh of the sweep with its reference.
struct MeshCase {
  std::string name;
  scene::Scene scene;
  TissueModel<double> model;     ///< at the scene's settings (reference input)
  std::optional<RefEntry> ref;   ///< computed on first use
  std::string failed;            ///< why its reference failed (the mesh is then skipped)
  std::vector<double> fine_u;    ///< the finest mesh's reference at this mesh's nodes (3 x n_nodes)
  Vec3<double> fine_force = {};  ///< the finest mesh's force on the tool (N)
  std::vector<Vec3<double>> press_force;  ///< the dynamic reference's force per tick up to the hold (N);
                                          ///< empty until first needed (dynamic_reference)
};

const std::vector<Waypoint>& tool_path(const scene::Scene& s) {
  if (s.tools.empty() || s.tools.front().path.empty())
    throw std::runtime_error(s.source + ": tradeoff needs a scripted tool path (the scene's first tool)");
  return s.tools.front().path;
}

/// The path up to the start of its hold (the device then holds that point).
std::vector<Waypoint> path_to_hold(const std::vector<Waypoint>& path) {
  const double t_hold = hold_start(path);
  std::vector<Waypoint> out;
  for (const Waypoint& w : path)
    if (w.t <= t_hold + 1e-12) out.push_back(w);
  return out;
}

/// max_a |u_a - ref_a| / max_a |ref_a| (both 3 x n, component-major); the
/// error's max runs over the nodes `use` marks (empty = all).
double relative_disp_error(std::span<const double> u, std::span<const double> ref,
                           const std::vector<std::uint8_t>& use = {}) {
  const std::size_t n = u.size() / 3;
  double err2 = 0, ref2 = 0;
  for (std::size_t a = 0; a < n; ++a) {
    double e = 0, r = 0;
    for (int c = 0; c < 3; ++c) {
      e += (u[c * n + a] - ref[c * n + a]) * (u[c * n + a] - ref[c * n + a]);
      r += ref[c * n + a] * ref[c * n + a];
    }
    if (use.empty() || use[a]) err2 = std::max(err2, e);
    ref2 = std::max(ref2, r);
  }
  return std::sqrt(err2 / std::max(ref2, 1e-300));
}

/// Nodes of the model farther than `radius` from p (1 = far).
std::vector<std::uint8_t> far_nodes(const TissueModel<double>& m, Vec3<double> p, double radius) {
  std::vector<std::uint8_t> far(m.n_nodes);
  for (index_t a = 0; a < m.n_nodes; ++a)
    far[a] = norm(Vec3<double>{m.X[a], m.X[m.n_nodes + a], m.X[2 * m.n_nodes + a]} - p) > radius;
  return far;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  const std::size_t h = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + h, v.end());
  if (v.size() % 2) return v[h];
  return 0.5 * (v[h] + *std::max_element(v.begin(), v.begin() + h));
}

double relative_force_error(Vec3<double> f, Vec3<double> ref) { return norm(f - ref) / std::max(norm(ref), 1e-300); }

TradeoffReference reference_row(const MeshCase& mc, const RefEntry& r) {
  TradeoffReference t;
  t.mesh = mc.name;
  t.nodes = mc.model.n_nodes;
  t.elems = mc.model.n_elems;
  t.steps = r.ref.relax.steps;
  t.wall = r.ref.relax.wall;
  t.residual = r.ref.relax.residual;
  t.force = r.ref.tool_force;
  t.max_disp = r.ref.max_disp;
  t.contact_nodes = r.ref.contact_nodes;
  return t;
}

/// The mesh's reference (computed on first use and kept): the whole mesh in
/// double, the scene's first tool held at its indentation, relaxed to the
/// reference tolerance. Every setting on this mesh is measured against it.
const RefEntry& reference_for(MeshCase& mc, const TradeoffOptions& o, std::vector<TradeoffReference>& report) {
  if (mc.ref) return *mc.ref;
  const std::vector<Waypoint>& path = tool_path(mc.scene);
  const std::string backend = o.backend.empty() ? mc.scene.solver.backend : o.backend;
  const ToolSetting tool = scene::scheduler_settings(mc.scene).tools.front();
  if (o.verbose) fmt::print(stderr, "  reference: {} mesh, tool held at its indentation\n", mc.name);
  ReferenceOptions ro;
  ro.backend = backend;
  ro.relax.residual_tol = o.reference_tol;
  RefEntry e;
  try {
    e.tool = held_tool(mc.model, tool, path, mc.scene.solver.tick, hold_start(path));
    e.ref = reference_solution(mc.model, {}, ro, &e.tool);
  } catch (const std::exception& err) {
    TradeoffReference t;
    t.mesh = mc.name;
    t.nodes = mc.model.n_nodes;
    t.elems = mc.model.n_elems;
    t.failed = err.what();
    report.push_back(t);
    if (o.verbose) fmt::print(stderr, "  reference failed: {}\n", t.failed);
    throw;
  }
  mc.ref = std::move(e);
  report.push_back(reference_row(mc, *mc.ref));
  const TradeoffReference& r = report.back();
  if (o.verbose)
    fmt::print(stderr, "  {} nodes, {} tets: reference residual {:.2g} after {} steps ({:.1f} s), |F| = {:.5g} N\n",
               r.nodes, r.elems, r.residual, r.steps, r.wall, norm(r.force));
  return *mc.ref;
}

MeshCase make_mesh_case(const scene::Scene& base, int target, const std::string& name) {
  MeshCase mc;
  mc.name = name;
  mc.scene = target > 0 ? remesh_scene(base, target) : base;
  mc.model = scene::load_model(mc.scene);
  return mc;
}

/// max_k |f_k - ref_k| / max_k |ref_k| over the ticks both have (N / N).
double press_force_error(const std::vector<Vec3<double>>& f, const std::vector<Vec3<double>>& ref) {
  double err = 0, scale = 0;
  for (std::size_t k = 0; k < std::min(f.size(), ref.size()); ++k) {
    err = std::max(err, norm(f[k] - ref[k]));
    scale = std::max(scale, norm(ref[k]));
  }
  return scale > 0 ? err / scale : NAN;
}

/// Runs one setting; returns one row per tolerance in `tols` (ascending
/// order of capture). The force per tick up to the hold goes to `press`;
/// the rows' press_force_err compares it with mc.press_force (NaN while
/// that is empty).
std::vector<TradeoffRow> run_setting(const MeshCase& mc, const RefEntry& ref, const TradeoffSetting& st,
                                     const std::vector<double>& tols, const TradeoffOptions& o,
                                     std::vector<Vec3<double>>& press) {
  scene::Scene s = mc.scene;
  s.solver.dt.reset();
  s.solver.dt_safety = st.dt_safety;
  s.solver.mass_scaling = st.mass_scaling;
  s.solver.precision = st.precision;
  if (!o.backend.empty()) s.solver.backend = o.backend;
  SchedulerSettings settings = scene::scheduler_settings(s);
  settings.depth = st.depth;
  settings.auto_tol = st.auto_tol;
  settings.residual_tol = st.residual_tol;
  settings.contact.face = st.face_contact;
  settings.contact.max_travel = st.max_travel;
  Engine engine = build_engine(s, settings);
  const TissueModel<double>& model = *engine.model;
  const std::unique_ptr<Backend>& backend = engine.backend;
  Scheduler& sched = *engine.scheduler;
  const std::vector<Waypoint> path = path_to_hold(tool_path(s));
  const double t_hold = path.back().t;
  ScriptedDevice device(path);
  press.clear();

  std::vector<std::optional<TradeoffRow>> rows(tols.size());
  std::vector<double> tick_wall;  // per contact tick (s)
  tick_wall.reserve(4096);
  double contact_wall = 0, contact_cpu = 0, hold_wall = 0;
  long contact_steps = 0, hold_ticks = 0;
  long contact_ticks = 0;
  auto capture = [&](std::size_t k, const TickReport& rep, bool eq) {
    TradeoffRow r;
    r.setting = st;
    r.setting.residual_tol = tols[k];
    r.mesh_nodes = model.n_nodes;
    r.mesh_elems = model.n_elems;
    r.dt = model.dt;
    r.steps_per_tick = sched.steps_per_tick();
    r.added_mass = model.added_mass / model.total_mass;
    r.region_nodes = rep.region_nodes;
    r.region_elems = rep.region_elems;
    r.depth_reached = rep.depth;
    r.equilibrium = eq;
    r.hold_ticks = hold_ticks;
    r.hold_wall = hold_wall;
    r.residual = rep.residual;
    r.force = rep.force;
    r.max_disp = rep.max_disp;
    const Fields f = backend->download();
    r.disp_err = relative_disp_error(f.u, ref.ref.fields.u);
    r.force_err = relative_force_error(rep.force, ref.ref.tool_force);
    if (mc.fine_u.empty()) {  // no usable finest mesh
      r.disp_err_fine = r.disp_err_fine_far = r.force_err_fine = NAN;
    } else {
      r.disp_err_fine = relative_disp_error(f.u, mc.fine_u);
      r.disp_err_fine_far = relative_disp_error(f.u, mc.fine_u, far_nodes(model, ref.tool.held.tip, o.far_radius));
      r.force_err_fine = relative_force_error(rep.force, mc.fine_force);
    }
    rows[k] = r;
  };
  TickReport rep;
  while (true) {
    const auto t0 = Clock::now();
    const std::clock_t c0 = std::clock();
    rep = sched.tick(device);
    const double w = seconds_since(t0), cpu = double(std::clock() - c0) / CLOCKS_PER_SEC;
    if (rep.contact_nodes > 0) {
      tick_wall.push_back(w);
      contact_wall += w;
      contact_cpu += cpu;
      contact_steps += rep.steps;
      ++contact_ticks;
    }
    if (rep.time < t_hold - 1e-9) {
      press.push_back(rep.force);
      continue;
    }
    hold_wall += w;
    ++hold_ticks;
    const bool kinetic_ok = rep.kinetic_rel < settings.kinetic_tol;
    bool pending = false;
    for (std::size_t k = 0; k < tols.size(); ++k) {
      if (!rows[k] && rep.residual < tols[k] && kinetic_ok) capture(k, rep, true);
      pending = pending || !rows[k];
    }
    if (!pending || rep.time >= t_hold + o.max_hold - 1e-9) break;
  }
  std::vector<TradeoffRow> out;
  for (std::size_t k = 0; k < tols.size(); ++k) {
    if (!rows[k]) capture(k, rep, false);
    rows[k]->wall_per_tick = median(tick_wall);
    rows[k]->cpu_per_tick = contact_cpu / std::max(contact_ticks, 1L);
    rows[k]->steps_per_s = contact_steps / std::max(contact_wall, 1e-12);
    rows[k]->press_force_err = mc.press_force.empty() ? NAN : press_force_error(press, mc.press_force);
    out.push_back(*rows[k]);
  }
  return out;
}

/// The setting whose dynamics the press_force_err column measures against:
/// whole mesh, double, dt = 0.5 dt_crit, no mass scaling.
TradeoffSetting dynamic_reference_setting() {
  TradeoffSetting s;
  s.group = "dynamic reference";
  s.label = "dynamic reference: all, double, safety 0.5, no mass scaling";
  s.depth = kDepthAll;
  s.precision = Precision::Double;
  s.dt_safety = 0.5;
  s.mass_scaling = 0;
  return s;
}

/// Fills mc.press_force on first use (one extra run of the mesh).
void dynamic_reference(MeshCase& mc, const TradeoffOptions& o, std::vector<TradeoffReference>& report) {
  if (!mc.press_force.empty()) return;
  const TradeoffSetting d = dynamic_reference_setting();
  TradeoffOptions press_only = o;  // only the press is compared: stop at the hold
  press_only.max_hold = 0;
  std::vector<Vec3<double>> press;
  run_setting(mc, reference_for(mc, o, report), d, {d.residual_tol}, press_only, press);
  mc.press_force = std::move(press);
}

std::string fmt_tol(double x) { return fmt::format("{:g}", x); }

/// A JSON number; null for NaN and infinities (JSON has neither).
std::string json_num(double x) { return std::isfinite(x) ? fmt::format("{}", x) : "null"; }

/// A JSON string literal's contents: quotes, backslashes and control characters escaped.
std::string json_escape(const std::string& s) {
  std::string out;
  for (const char ch : s) {
    if (ch == '"' || ch == '\\')
      out += {'\\', ch};
    else if (static_cast<unsigned char>(ch) < 0x20)
      out += fmt::format("\\u{:04x}", int(ch));
    else
      out += ch;
  }
  return out;
}

}  // namespace

std::vector<TradeoffSetting> tradeoff_settings(const scene::Scene& scene, const TradeoffOptions& o) {
  TradeoffSetting base;
  base.group = "baseline";
  base.depth = scene.solver.depth;
  base.precision = scene.solver.precision;
  base.dt_safety = scene.solver.dt_safety;
  base.mass_scaling = scene.solver.mass_scaling;
  base.residual_tol = scene.solver.residual_tol;
  const auto it = std::find(o.mesh_targets.begin(), o.mesh_targets.end(), 0);
  base.mesh = it == o.mesh_targets.end() ? 0 : static_cast<int>(it - o.mesh_targets.begin());
  base.label = fmt::format("baseline: depth {}, {}, safety {:g}, mass {:g}", depth_name(base.depth),
                           to_string(base.precision), base.dt_safety, base.mass_scaling);
  // the anchor of the precision, safety, mesh and tolerance groups: the
  // baseline without truncation or float rounding, so that their own errors show
  TradeoffSetting anchor = base;
  anchor.group = "anchor";
  anchor.depth = o.anchor_depth;
  anchor.precision = o.anchor_precision;
  anchor.label = fmt::format("anchor: depth {}, {}, safety {:g}, mass {:g}", depth_name(anchor.depth),
                             to_string(anchor.precision), anchor.dt_safety, anchor.mass_scaling);
  std::vector<TradeoffSetting> out{base, anchor};
  auto vary = [&](const TradeoffSetting& from, const char* group, std::string label, auto&& set) {
    TradeoffSetting s = from;
    s.group = group;
    s.label = std::move(label);
    set(s);
    out.push_back(s);
  };
  for (int d : o.depths)
    if (d != base.depth) vary(base, "depth", "depth " + depth_name(d), [&](TradeoffSetting& s) { s.depth = d; });
  for (double t : o.auto_tols)
    vary(base, "auto", fmt::format("depth auto, tol {:g}", t), [&](TradeoffSetting& s) {
      s.depth = kDepthAuto;
      s.auto_tol = t;
    });
  for (Precision p : o.precisions)
    if (p != base.precision)
      vary(base, "precision", fmt::format("{}, depth {}", to_string(p), depth_name(base.depth)),
           [&](TradeoffSetting& s) { s.precision = p; });
  for (double f : o.safeties)
    if (f != anchor.dt_safety)
      vary(anchor, "safety", fmt::format("anchor, safety {:g}", f), [&](TradeoffSetting& s) { s.dt_safety = f; });
  for (double f : o.mass_scalings)
    if (f != anchor.mass_scaling)
      vary(anchor, "mass", f == 0 ? std::string("anchor, no mass scaling") : fmt::format("anchor, mass scaling {:g}", f),
           [&](TradeoffSetting& s) { s.mass_scaling = f; });
  for (std::size_t m = 0; m < o.mesh_targets.size(); ++m)
    if (int(m) != anchor.mesh)
      vary(anchor, "mesh", fmt::format("anchor, {} mesh", o.mesh_names.at(m)),
           [&](TradeoffSetting& s) { s.mesh = int(m); });
  for (const TradeoffSetting& c : o.contact)
    vary(anchor, "contact", c.label, [&](TradeoffSetting& s) {
      s.face_contact = c.face_contact;
      s.max_travel = c.max_travel;
    });
  for (double t : o.residual_tols)
    if (t != anchor.residual_tol)
      vary(anchor, "tolerance", fmt::format("anchor, tol {}", fmt_tol(t)), [&](TradeoffSetting& s) { s.residual_tol = t; });
  for (const TradeoffSetting& p : o.compare) {
    TradeoffSetting s = p;
    s.group = "compare";
    s.mesh = base.mesh;
    if (s.label.empty())
      s.label = fmt::format("compare: depth {}{}, {}, safety {:g}, mass {:g}, tol {}", depth_name(s.depth),
                            s.depth == kDepthAuto ? fmt::format(" {:g}", s.auto_tol) : "", to_string(s.precision),
                            s.dt_safety, s.mass_scaling, fmt_tol(s.residual_tol));
    out.push_back(s);
  }
  return out;
}

TradeoffResult run_tradeoff(const scene::Scene& scene, const TradeoffOptions& o) {
  if (o.mesh_targets.empty() || o.mesh_names.size() != o.mesh_targets.size())
    throw std::invalid_argument("tradeoff: one mesh name per mesh target, at least one mesh");
  const auto t0 = Clock::now();
  TradeoffResult res;
  res.scene = scene.source;
  // references, finest last
  std::vector<MeshCase> meshes;
  for (std::size_t m = 0; m < o.mesh_targets.size(); ++m) {
    if (o.stop && o.stop()) {
      res.interrupted = true;
      res.wall = seconds_since(t0);
      return res;
    }
    if (o.verbose) fmt::print(stderr, "tradeoff: {} mesh and its reference ...\n", o.mesh_names[m]);
    meshes.push_back(make_mesh_case(scene, o.mesh_targets[m], o.mesh_names[m]));
    try {
      reference_for(meshes.back(), o, res.references);
    } catch (const std::exception& e) {
      meshes.back().failed = e.what();
    }
  }
  const MeshCase* fine = nullptr;  // the finest usable mesh
  for (const MeshCase& mc : meshes)
    if (mc.failed.empty()) fine = &mc;
  for (MeshCase& mc : meshes) {
    if (!fine) break;
    std::vector<double> pts(3 * std::size_t(mc.model.n_nodes));
    for (index_t i = 0; i < mc.model.n_nodes; ++i)
      for (int c = 0; c < 3; ++c) pts[3 * i + c] = mc.model.X[c * mc.model.n_nodes + i];
    mc.fine_u = sample_field(fine->model, fine->ref->ref.fields.u, pts);
    mc.fine_force = fine->ref->ref.tool_force;
  }
  {
    auto b = create_backend(o.backend.empty() ? scene.solver.backend : o.backend, Precision::Float);
    res.device = b->device_name();
  }
  // settings: the tolerance rows come from the baseline run
  const std::vector<TradeoffSetting> settings = tradeoff_settings(scene, o);
  const TradeoffSetting& anchor = settings.at(1);
  std::vector<double> base_tols{anchor.residual_tol};
  std::vector<const TradeoffSetting*> tol_settings{&anchor};
  for (const TradeoffSetting& s : settings)
    if (s.group == "tolerance") {
      base_tols.push_back(s.residual_tol);
      tol_settings.push_back(&s);
    }
  for (const TradeoffSetting& s : settings) {
    if (s.group == "tolerance") continue;
    if (o.stop && o.stop()) {
      res.interrupted = true;
      break;
    }
    const bool base = s.group == "anchor";  // its run serves the tolerance rows too
    const auto t1 = Clock::now();
    MeshCase& mc = meshes.at(s.mesh);
    std::vector<TradeoffRow> rows;
    try {
      if (!mc.failed.empty()) throw std::runtime_error("no reference on this mesh: " + mc.failed);
      dynamic_reference(mc, o, res.references);
      const RefEntry& ref = reference_for(mc, o, res.references);
      std::vector<Vec3<double>> press;
      rows = run_setting(mc, ref, s, base ? base_tols : std::vector<double>{s.residual_tol}, o, press);
    } catch (const std::exception& e) {
      rows.assign(base ? base_tols.size() : 1, TradeoffRow{});
      for (TradeoffRow& r : rows) {
        r.setting = s;
        r.mesh_nodes = mc.model.n_nodes;
        r.mesh_elems = mc.model.n_elems;
        r.failed = e.what();
      }
      if (o.verbose) fmt::print(stderr, "  {:<40} failed: {}\n", s.label, e.what());
    }
    for (std::size_t k = 0; k < rows.size(); ++k) {
      if (base) rows[k].setting = *tol_settings[k];
      if (!rows[k].failed.empty()) {
        res.rows.push_back(rows[k]);
        continue;
      }
      if (o.verbose)
        fmt::print(stderr, "  {:<40} {:8.3f} ms/tick  error {:.3g} (force {:.3g})  [{:.1f} s]\n",
                   rows[k].setting.label, 1e3 * rows[k].wall_per_tick, rows[k].disp_err, rows[k].force_err,
                   seconds_since(t1));
      res.rows.push_back(rows[k]);
    }
  }
  mark_pareto(res.rows);
  res.wall = seconds_since(t0);
  return res;
}

void mark_pareto(std::vector<TradeoffRow>& rows) {
  for (TradeoffRow& r : rows) {
    r.pareto = r.failed.empty();
    if (!r.pareto) continue;
    for (const TradeoffRow& q : rows) {
      if (!q.failed.empty()) continue;
      const bool no_worse = q.wall_per_tick <= r.wall_per_tick && q.disp_err <= r.disp_err;
      const bool better = q.wall_per_tick < r.wall_per_tick || q.disp_err < r.disp_err;
      if (&q != &r && no_worse && better) {
        r.pareto = false;
        break;
      }
    }
  }
}

std::string tradeoff_table(const TradeoffResult& res) {
  std::string out = fmt::format("tradeoff for {} on {}\n", res.scene, res.device);
  out += "references (whole mesh, double, dynamic relaxation):\n";
  for (const TradeoffReference& r : res.references)
    if (!r.failed.empty())
      out += fmt::format("  {:<8} {:6} nodes {:6} tets  FAILED: {}\n", r.mesh, r.nodes, r.elems, r.failed);
    else
      out += fmt::format("  {:<8} {:6} nodes {:6} tets  {:4} contact nodes  residual {:.2g}  {:6} steps {:6.1f} s  "
                       "|F| {:.5g} N  max|u| {:.4g} mm\n",
                       r.mesh, r.nodes, r.elems, r.contact_nodes, r.residual, r.steps, r.wall, norm(r.force),
                       1e3 * r.max_disp);
  out += fmt::format(
      "{:<44} {:>6} {:>6} {:>5} {:>6} {:>6} {:>5} {:>5} {:>6} {:>8} {:>8} {:>8} {:>6} {:>3} {:>9} {:>9} {:>9} {:>9} "
      "{:>9} {:>9} {}\n",
      "setting", "tets", "prec", "safe", "mass", "tol", "steps", "depth", "elems", "ms/tick", "cpu ms", "steps/s",
      "ticks", "eq", "u err", "F err", "press F", "u err*", "u far*", "F err*", "P");
  for (const TradeoffRow& r : res.rows) {
    const TradeoffSetting& s = r.setting;
    if (!r.failed.empty()) {
      out += fmt::format("{:<44} {:>6} {:>6} {:>5g} {:>6g} {:>6g}  failed: {}\n", s.label.substr(0, 44),
                         r.mesh_elems, to_string(s.precision), s.dt_safety, s.mass_scaling, s.residual_tol, r.failed);
      continue;
    }
    out += fmt::format(
        "{:<44} {:>6} {:>6} {:>5g} {:>6g} {:>6g} {:>5} {:>5} {:>6} {:>8.3f} {:>8.3f} {:>8.0f} {:>6} {:>3} {:>9.2e} "
        "{:>9.2e} {:>9.2e} {:>9.2e} {:>9.2e} {:>9.2e} {}\n",
        s.label.substr(0, 44), r.mesh_elems, to_string(s.precision), s.dt_safety, s.mass_scaling, s.residual_tol,
        r.steps_per_tick, depth_name(r.depth_reached), r.region_elems, 1e3 * r.wall_per_tick, 1e3 * r.cpu_per_tick,
        r.steps_per_s, r.hold_ticks, r.equilibrium ? "y" : "n", r.disp_err, r.force_err, r.press_force_err,
        r.disp_err_fine, r.disp_err_fine_far, r.force_err_fine, r.pareto ? "*" : "");
  }
  out += "ms/tick: median wall time of a haptic tick in contact; cpu ms: mean process CPU time (all threads)\n"
         "per tick. u err, F err: max nodal displacement error / max displacement and tool-force error, against\n"
         "the same mesh's reference; press F: the largest tool-force difference during the press from the same\n"
         "mesh run whole, double, safety 0.5, no mass scaling (the transient, relative to its peak force);\n"
         "mass: the mass scaling budget; u err*, F err*: against the finest mesh's reference (u far*: the error\n"
         "over nodes farther than far_radius from the held tool tip). ticks: haptic ticks from the start of the\n"
         "hold to the measured tick (eq: the tolerance passed). P: on the Pareto front of (ms/tick, u err).\n";
  out += fmt::format("sweep wall time {:.1f} s\n", res.wall);
  return out;
}

std::string tradeoff_json(const TradeoffResult& res) {
  std::string out = fmt::format("{{\n  \"scene\": \"{}\",\n  \"device\": \"{}\",\n  \"wall_s\": {},\n",
                                json_escape(res.scene), json_escape(res.device), res.wall);
  out += "  \"references\": [\n";
  for (std::size_t k = 0; k < res.references.size(); ++k) {
    const TradeoffReference& r = res.references[k];
    out += fmt::format(
        "    {{\"mesh\": \"{}\", \"nodes\": {}, \"tets\": {}, \"steps\": {}, \"wall_s\": {}, \"residual\": {}, "
        "\"force\": [{}, {}, {}], \"max_disp\": {}, \"contact_nodes\": {}, \"failed\": \"{}\"}}{}\n",
        r.mesh, r.nodes, r.elems, r.steps, r.wall, r.residual, r.force.x, r.force.y, r.force.z, r.max_disp,
        r.contact_nodes, json_escape(r.failed), k + 1 < res.references.size() ? "," : "");
  }
  out += "  ],\n  \"rows\": [\n";
  for (std::size_t k = 0; k < res.rows.size(); ++k) {
    const TradeoffRow& r = res.rows[k];
    const TradeoffSetting& s = r.setting;
    out += fmt::format(
        "    {{\"group\": \"{}\", \"label\": \"{}\", \"depth\": \"{}\", \"auto_tol\": {}, \"precision\": \"{}\", "
        "\"dt_safety\": {}, \"mass_scaling\": {}, \"mesh\": {}, \"face_contact\": {}, \"max_travel\": {}, \"residual_tol\": {}, \"mesh_nodes\": {}, "
        "\"mesh_tets\": {}, \"dt\": {}, \"added_mass\": {}, "
        "\"steps_per_tick\": {}, \"wall_per_tick_s\": {}, \"cpu_per_tick_s\": {}, \"steps_per_s\": {}, \"region_nodes\": {}, "
        "\"region_elems\": {}, \"depth_reached\": \"{}\", \"equilibrium\": {}, \"hold_ticks\": {}, "
        "\"hold_wall_s\": {}, \"residual\": {}, \"force\": [{}, {}, {}], \"max_disp\": {}, \"disp_err\": {}, "
        "\"force_err\": {}, \"press_force_err\": {}, \"disp_err_fine\": {}, \"disp_err_fine_far\": {}, "
        "\"force_err_fine\": {}, "
        "\"pareto\": {}, \"failed\": \"{}\"}}{}\n",
        s.group, json_escape(s.label), depth_name(s.depth), s.auto_tol, to_string(s.precision), s.dt_safety,
        s.mass_scaling, s.mesh, s.face_contact, s.max_travel, s.residual_tol, r.mesh_nodes, r.mesh_elems, r.dt, r.added_mass, r.steps_per_tick, r.wall_per_tick, r.cpu_per_tick,
        r.steps_per_s,
        r.region_nodes, r.region_elems, depth_name(r.depth_reached), r.equilibrium, r.hold_ticks, r.hold_wall,
        r.residual, r.force.x, r.force.y, r.force.z, r.max_disp, r.disp_err, r.force_err,
        json_num(r.press_force_err), json_num(r.disp_err_fine),
        json_num(r.disp_err_fine_far), json_num(r.force_err_fine), r.pareto, json_escape(r.failed), k + 1 < res.rows.size() ? "," : "");
  }
  out += "  ]\n}\n";
  return out;
}

}  // namespace tissue::accuracy
