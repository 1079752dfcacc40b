#include "bench/bench.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <ctime>
#include <fstream>
#include <memory>
#include <numeric>
#include <optional>
#include <stdexcept>
#include <thread>
#include <tbb/task_arena.h>

#include "backends/registry.hpp"
#include "io/atomic_file.hpp"
#include "core/box_mesh.hpp"
#include "core/scheduler.hpp"
#include "io/kidney.hpp"
#include "io/scene_xml.hpp"
#include "scene/validate.hpp"
#include "session/engine.hpp"
#include "session/scene_batch.hpp"
#include "session/session.hpp"

namespace tissue::bench {
namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

/// Adds the terms of a bench law (BenchOptions::laws) to a material: two
/// Prony terms (g = 0.3, 0.2; tau = 0.5, 5 s) and/or fibres along x with
/// eta = 2 mu.
void apply_law(const std::string& law, MaterialParams& p) {
  if (law != "neo-hookean" && law != "visco" && law != "fibre" && law != "fibre-visco")
    throw std::invalid_argument("unknown bench law '" + law + "' (neo-hookean, visco, fibre, fibre-visco)");
  if (law == "visco" || law == "fibre-visco") {
    p.prony_terms = 2;
    p.prony_g[0] = 0.3, p.prony_tau[0] = 0.5;
    p.prony_g[1] = 0.2, p.prony_tau[1] = 5;
  }
  if (law == "fibre" || law == "fibre-visco") {
    p.fibre_eta = 2 * p.mu;
    p.fibre_dir = {1, 0, 0};
  }
}

/// A generated test mesh: box of c^3 cells x 6 tets, soft tissue material
/// with a bench law's terms. (fix_bottom: the nodes at z = 0 are fixed -- a
/// pressed slab must not fly off)
TissueModel<double> box_model(int nx, int ny, int nz, double lx, double ly, double lz, bool fix_bottom = false,
                              const std::string& law = "neo-hookean") {
  ModelInput in;
  box_mesh(in, nx, ny, nz, lx, ly, lz);
  in.materials = {{3000 / 2.9, 3000 / 0.3, 1000}};  // E = 3000 Pa, nu = 0.45
  apply_law(law, in.materials[0]);
  if (fix_bottom) {
    in.fixed.assign(in.nodes.size() / 3, 0);
    for (std::size_t i = 0; i < in.fixed.size(); ++i) in.fixed[i] = in.nodes[3 * i + 2] == 0.0;
  }
  in.source = fmt::format("box {}x{}x{}", nx, ny, nz);
  return build_model(in);
}

struct NamedModel {
  std::string name;
  TissueModel<double> model;
};

/// The built-in kidney scene with a bench law's terms on its material.
scene::Scene kidney_with_law(const std::string& law) {
  scene::Scene s = io::default_kidney_scene();
  for (scene::Material& m : s.materials) {
    MaterialParams p = m.params();
    apply_law(law, p);
    m.fibre_eta = p.fibre_eta;
    m.fibre_dir = p.fibre_dir;
    for (int i = 0; i < p.prony_terms; ++i) m.prony.push_back({p.prony_g[i], p.prony_tau[i], 0});
  }
  return s;
}

NamedModel mesh_by_name(const std::string& name, bool quick, const std::string& law = "neo-hookean") {
  if (name == "kidney") return {name, scene::load_model(kidney_with_law(law))};
  // cells per side of a cube with 6 c^3 ~ the asked count
  const long want = name == "100k" ? 100'000 : name == "1m" ? 1'000'000 : name == "4m" ? 4'000'000 : -1;
  if (want < 0) throw std::invalid_argument("unknown bench mesh '" + name + "' (kidney, 100k, 1m, 4m)");
  int c = static_cast<int>(std::lround(std::cbrt(want / 6.0)));
  if (quick) c = std::min(c, 8);
  return {name, box_model(c, c, c, 0.1, 0.1, 0.1, false, law)};
}

struct Row {
  std::string text = "{";
  void add(const std::string& k, const std::string& v) { sep(), text += fmt::format("\"{}\": \"{}\"", k, v); }
  void add(const std::string& k, double v) { sep(), text += fmt::format("\"{}\": {:.6g}", k, v); }
  void add(const std::string& k, long v) { sep(), text += fmt::format("\"{}\": {}", k, v); }
  std::string done() const { return text + "}"; }
  void sep() {
    if (text.size() > 1) text += ", ";
  }
};

struct Context {
  const BenchOptions& o;
  std::string device;
  double bandwidth = 0;  // bytes/s
  std::string date;
  std::vector<std::string> rows;

  Row row(const std::string& bench, const Backend& b) const {
    Row r;
    r.add("bench", bench);
    r.add("backend", b.name());
    r.add("precision", std::string(to_string(b.precision())));
    r.add("float_math", float_math(b));
    if (!backend_tuning(b).empty()) r.add("cpu_tuning", backend_tuning(b));
    r.add("device", device);
    r.add("date", date);
    r.add("measured_bandwidth_GBps", bandwidth * 1e-9);
    return r;
  }
  void emit(const Row& r) {
    rows.push_back(r.done());
    fmt::print("{}\n", rows.back());
    std::fflush(stdout);
  }
};

/// Times advance() in batches until min_seconds have passed; returns steps/s.
double time_steps(Backend& b, double min_seconds, long& steps_done) {
  b.advance(2);  // warm-up (graph capture, caches)
  b.reduce();
  int batch = 1;
  steps_done = 0;
  const auto t0 = Clock::now();
  double t = 0;
  while ((t = since(t0)) < min_seconds) {
    b.advance(batch);
    b.reduce();  // synchronises device backends
    steps_done += batch;
    if (since(t0) < 0.1 * min_seconds) batch *= 2;
  }
  return steps_done / t;
}

/// A slow uniform push of the top so that the tet math runs on real, non-zero strains.
void preload(Backend& b, const TissueModel<double>& m) {
  std::vector<double> u(3 * size_t(m.n_nodes), 0.0);
  double zlo = 1e300, zhi = -1e300;
  for (index_t i = 0; i < m.n_nodes; ++i) {
    zlo = std::min(zlo, m.X[2 * m.n_nodes + i]);
    zhi = std::max(zhi, m.X[2 * m.n_nodes + i]);
  }
  for (index_t i = 0; i < m.n_nodes; ++i) {
    const double s = (m.X[2 * m.n_nodes + i] - zlo) / (zhi - zlo);
    u[2 * m.n_nodes + i] = -0.02 * s * (zhi - zlo);  // 2% compression
    u[0 * m.n_nodes + i] = 0.005 * s * (zhi - zlo);  // and a little shear
  }
  b.set_displacements(u);
}

void bench_tled(Context& c, const std::string& mesh, Precision p, const std::string& law) {
  NamedModel nm = mesh_by_name(mesh, c.o.quick, law);
  auto b = create_backend(c.o.backend, p);
  b->upload(nm.model);
  preload(*b, nm.model);
  const RegionSizes whole = b->build_region({}, kDepthAll);
  long steps = 0;
  const double sps = time_steps(*b, c.o.min_seconds, steps);
  const int s = p == Precision::Float ? 4 : 8;
  const std::string gradients = element_gradients(*b);
  const double bytes = bytes_per_step(nm.model.n_nodes, nm.model.n_elems, s, gradients == "recomputed");
  Row r = c.row("tled_whole_mesh", *b);
  r.add("mesh", nm.name);
  r.add("gradients", gradients);
  r.add("law", law);
  r.add("nodes", long(nm.model.n_nodes));
  r.add("elements", long(nm.model.n_elems));
  r.add("region_elements", long(whole.n_elems));
  r.add("steps", steps);
  r.add("steps_per_s", sps);
  r.add("element_steps_per_s", sps * nm.model.n_elems);
  r.add("bytes_per_step", bytes);
  r.add("achieved_GBps", sps * bytes * 1e-9);
  if (c.bandwidth > 0) r.add("bandwidth_fraction", sps * bytes / c.bandwidth);
  c.emit(r);

  if (mesh != "kidney" || law != "neo-hookean") return;
  // region-limited (depth 5) against the whole mesh, seeded at the middle surface triangle
  const index_t t = nm.model.n_tris / 2;
  std::vector<index_t> seeds;
  for (int v = 0; v < 3; ++v) seeds.push_back(nm.model.tris[v * nm.model.n_tris + t]);
  std::sort(seeds.begin(), seeds.end());
  const RegionSizes reg = b->build_region(seeds, 5);
  const double sps5 = time_steps(*b, c.o.min_seconds, steps);
  Row q = c.row("tled_region_depth5", *b);
  q.add("mesh", nm.name);
  q.add("nodes", long(nm.model.n_nodes));
  q.add("elements", long(nm.model.n_elems));
  q.add("region_nodes", long(reg.nodes()));
  q.add("region_elements", long(reg.n_elems));
  q.add("steps", steps);
  q.add("steps_per_s", sps5);
  q.add("element_steps_per_s", sps5 * reg.n_elems);
  q.add("speedup_vs_whole", sps5 / sps);
  c.emit(q);

  // the whole mesh again with a tool set but 1 m away: every step runs the contact
  // stage (the sweep of the surface, the merge per surface node) and finds nothing
  b->build_region({}, kDepthAll);
  const ToolShape tool{"probe", 0.002, 0.02};
  b->set_tools(std::span<const ToolShape>(&tool, 1));
  const ToolPose away{{1.0, 1.0, 1.0}, {0, 0, 1}};
  const ToolMotion still{away, away};
  b->move_tools(std::span<const ToolMotion>(&still, 1));
  const double sps_tool = time_steps(*b, c.o.min_seconds, steps);
  Row w = c.row("tled_whole_mesh_tool", *b);
  w.add("mesh", nm.name);
  w.add("elements", long(nm.model.n_elems));
  w.add("surface_triangles", long(nm.model.n_tris));
  w.add("steps", steps);
  w.add("steps_per_s", sps_tool);
  w.add("contact_stage_us_per_step", 1e6 * (1 / sps_tool - 1 / sps));
  c.emit(w);
}

void bench_contact(Context& c, long want_tris, Precision p, double mu, double radius = 0.002) {
  // a flat slab of N x N x 1 cells (4 (N^2 + 2N) surface triangles), a sphere (2 mm; 10 mm: a large
  // instrument, hundreds of triangles in reach) pressed 0.5 mm (at most a quarter of the slab) into its
  // top and sliding slowly; the region is one ring around the contact so that a step's time is mostly
  // the contact stage's: the query of the surface and the sweep of the triangles it finds
  int N = static_cast<int>(std::lround(std::sqrt(want_tris / 4.0)));
  if (c.o.quick) N = std::min(N, 10);
  const TissueModel<double> m = box_model(N, N, 1, 0.1, 0.1, 0.1 / N, true);
  auto b = create_backend(c.o.backend, p);
  b->upload(m);
  const ToolShape tool{"probe", radius, 0, mu};
  b->set_tools(std::span<const ToolShape>(&tool, 1));
  const double top = 0.1 / N;
  const double press = std::min(5e-4, 0.25 * top);  // the 100k slab is 0.63 mm thick: a quarter of it
  auto pose = [&](int k) { return ToolPose{{0.05 + 1e-5 * k, 0.05, top + tool.radius - press}, {0, 0, 1}}; };
  ToolMotion mv{pose(0), pose(0)};
  b->move_tools(std::span<const ToolMotion>(&mv, 1));
  // an empty region first, as the Scheduler starts: after upload the whole
  // mesh is the region, and candidates are only nodes outside it
  b->build_region({}, 1);
  const std::vector<index_t> seeds = b->contact_candidates();
  if (seeds.empty()) throw std::runtime_error("bench: the contact tool does not reach the slab");
  const RegionSizes reg = b->build_region(seeds, 1);
  std::vector<double> lat;
  for (int k = 0; k < 200; ++k) {
    mv = {pose(k), pose(k + 1)};
    b->move_tools(std::span<const ToolMotion>(&mv, 1));
    const auto t0 = Clock::now();
    const Reductions r = b->advance_reduce(1);  // as the Scheduler's tick: one graph on the cuda backend
    lat.push_back(since(t0));
    if (r.tools[0].contact == 0)
      throw std::runtime_error(fmt::format("bench: the contact tool lost the slab ({} triangles, step {})", m.n_tris, k));
  }
  std::sort(lat.begin(), lat.end());
  // the contact stage's own share of a step (no upload, reduction or download): the
  // same region stepped in batches with the tool resting in the slab, then without it
  long steps = 0;
  const double sps_tool = time_steps(*b, c.o.min_seconds, steps);
  b->set_tools({});
  const double sps_bare = time_steps(*b, c.o.min_seconds, steps);
  Row r = c.row("contact_step", *b);
  r.add("surface_triangles", long(m.n_tris));
  r.add("tool_radius_mm", 1e3 * radius);
  r.add("friction", mu);
  r.add("region_elements", long(reg.n_elems));
  r.add("steps", long(lat.size()));
  r.add("latency_us_p50", 1e6 * lat[lat.size() / 2]);
  r.add("latency_us_p99", 1e6 * lat[lat.size() * 99 / 100]);
  r.add("contact_stage_us_per_step", 1e6 * (1 / sps_tool - 1 / sps_bare));
  c.emit(r);
}

/// The contact stage's chains alone (a device backend's; none on the cpu):
/// what a step's stage in contact costs before any memory or kernel boundary.
void bench_contact_chains(Context& c, Precision p) {
  const auto times = contact_chain_times(c.o.backend, p);
  if (times.empty()) return;
  auto b = create_backend(c.o.backend, p);
  Row r = c.row("contact_chains", *b);
  for (const auto& [name, value] : times) r.add(name, value);
  c.emit(r);
}

/// A scene of the haptic-tick rows: the kidney with a bench law, or a
/// --scene file.
struct TickScene {
  std::string mesh, law;
  scene::Scene scene;
};

std::vector<TickScene> tick_scenes(const BenchOptions& o) {
  std::vector<TickScene> out;
  for (const std::string& law : o.laws) out.push_back({"kidney", law, kidney_with_law(law)});
  for (const std::string& path : o.scenes) {
    std::optional<scene::Scene> builtin = io::builtin_scene(path);
    scene::Scene s = builtin ? std::move(*builtin) : io::read_scene(path);
    if (s.tools.empty() || s.tools.front().path.size() < 2)
      throw std::invalid_argument("bench --scene " + path +
                                  ": its first tool has no scripted path (the haptic-tick rows press along it)");
    out.push_back({path.substr(path.find_last_of('/') + 1), "scene", std::move(s)});
  }
  return out;
}

void bench_tick(Context& c, Precision p, int depth, std::optional<double> dt_safety, std::optional<double> mu,
                const TickScene& ts) {
  scene::Scene s = ts.scene;
  if (!s.contacts.empty() && depth != kDepthAll) return;  // bodies in contact compute the whole mesh
  if (mu) {
    for (scene::Tool& t : s.tools) t.friction = *mu;
    for (scene::BodyContact& bc : s.contacts) bc.friction = *mu;
  }
  s.solver.dt_safety = dt_safety.value_or(s.solver.dt_safety);
  s.solver.backend = c.o.backend;
  s.solver.precision = p;
  SchedulerSettings st = scene::scheduler_settings(s);
  st.depth = depth;
  // the ticks in contact along the scene's scripted press, sorted
  const auto press = [&](Scheduler& sched) {
    ScriptedDevice dev(s.tools.front().path);
    std::vector<double> lat;
    const long n = std::lround((c.o.quick ? 0.3 : dev.duration()) / st.tick);
    for (long k = 0; k < n; ++k) {
      const auto t0 = Clock::now();
      sched.tick(dev);
      if (sched.in_contact()) lat.push_back(since(t0));
    }
    if (lat.empty()) throw std::runtime_error("bench: the tool path of " + ts.mesh + " never touched it");
    std::sort(lat.begin(), lat.end());
    return lat;
  };
  // a scene of bodies in contact also runs with its contact off, in the same run: the difference of the
  // medians per TLED step is what the body contact costs (the bodies then pass through each other, so the
  // tools' stage differs a little too)
  std::vector<double> apart;
  if (!s.contacts.empty()) {
    scene::Scene off = s;
    off.contacts.clear();
    SchedulerSettings st_off = st;
    st_off.body_contact = {};
    Engine e = build_engine(off, st_off);
    apart = press(*e.scheduler);
  }
  Engine engine = build_engine(s, st);
  const std::unique_ptr<Backend>& b = engine.backend;
  Scheduler& sched = *engine.scheduler;
  const std::vector<double> lat = press(sched);
  // the reduction alone, where the path ended (the region as the ticks left it, the tool there): one call of
  // the backend's reduce() -- on the cuda backend its passes 1-2 and reduction kernel as launches of their
  // own, a copy down and the wait, where a tick runs the same kernels inside its graph and writes the answer
  // into mapped host memory: an upper bound on what the reduction adds to a tick
  std::vector<double> red;
  for (int k = 0; k < (c.o.quick ? 5 : 200); ++k) {
    const auto t0 = Clock::now();
    b->reduce();
    red.push_back(since(t0));
  }
  std::sort(red.begin(), red.end());
  Row r = c.row("haptic_tick", *b);
  r.add("mesh", ts.mesh);
  r.add("law", ts.law);
  r.add("elements", long(engine.model->n_elems));
  r.add("depth", depth == kDepthAll ? std::string("all") : std::to_string(depth));
  r.add("dt_safety", s.solver.dt_safety);
  r.add("friction", s.tools.front().friction);
  r.add("steps_per_tick", long(sched.steps_per_tick()));
  r.add("ticks_in_contact", long(lat.size()));
  r.add("tick_ms_p50", 1e3 * lat[lat.size() / 2]);
  r.add("tick_ms_p99", 1e3 * lat[lat.size() * 99 / 100]);
  r.add("tick_ms_max", 1e3 * lat.back());
  r.add("reduce_ms_p50", 1e3 * red[red.size() / 2]);
  if (!s.contacts.empty()) {
    r.add("bodies", long(s.bodies.size()));
    r.add("body_pairs", long(s.contacts.size()));
    r.add("body_friction", s.contacts.front().friction);
    r.add("tick_ms_p50_bodies_apart", 1e3 * apart[apart.size() / 2]);
    r.add("body_contact_ms_per_step",
          1e3 * (lat[lat.size() / 2] - apart[apart.size() / 2]) / double(sched.steps_per_tick()));
    r.add("body_list_builds", b->body_list_builds());
  }
  c.emit(r);
}

/// The tip of scene i's tool at tick k of a batch run: on the kidney's press axis (its path's touch and deep
/// points), coming down over the first `ramp` ticks and then pressing in and out between a quarter of the
/// press and all of it with a period of 200 ticks, each scene at its own phase.
Vec3<double> batch_tip(const std::vector<Waypoint>& path, long k, std::size_t i, std::size_t n, long ramp) {
  const Vec3<double> touch = path.at(1).p, deep = path.at(2).p;
  const double phase = 2 * M_PI * double(i) / double(n);
  auto cycle = [&](long t) { return 0.625 - 0.375 * std::cos(2 * M_PI * double(t) / 200.0 + phase); };
  const double s = k < ramp ? -0.5 + (cycle(ramp) + 0.5) * double(k) / double(ramp) : cycle(k);
  return touch + s * (deep - touch);
}

struct BatchRun {
  double ticks_per_s = 0, tick_p50 = 0, tick_p99 = 0, tick_max = 0;
  long ticks = 0;
  int steps_per_tick = 0;
  double region_nodes = 0, region_elems = 0;  ///< means over the scenes at the end
  std::size_t running = 0, in_contact = 0;
  BatchMemory memory;
  std::string skipped;  ///< why the batch did not run ("" = it ran)
  std::size_t groups = 0;   ///< groups of scenes stepped as one (SceneBatch::groups)
  double together = 0;      ///< of the timed scene ticks, the fraction run in a group
  double start_s = 0, device_s = 0, end_s = 0;  ///< mean of a timed tick's phases (SceneBatch::TickPhases)
};

/// N kidneys stepped together (SceneBatch) on c's backend; ticks timed one batch tick at a time.
BatchRun run_batch(Context& c, Precision p, std::size_t n, double min_seconds, int worker_threads = -1) {
  BatchRun out;
  // the whole mesh: every scene's region is the kidney from the first tick (no region grows while timed)
  scene::Scene kidney = kidney_with_law(c.o.laws.front());
  kidney.solver.depth = kDepthAll;
  const auto scene = std::make_shared<const scene::Scene>(std::move(kidney));
  std::unique_ptr<SceneBatch> batch;
  try {
    batch = std::make_unique<SceneBatch>(std::vector<std::shared_ptr<const scene::Scene>>(n, scene), c.o.backend, p);
  } catch (const std::runtime_error& e) {
    out.skipped = e.what();
    return out;
  }
  if (worker_threads >= 0)
    for (std::size_t i = 0; i < n; ++i) (*batch)[i].backend().set_worker_threads(worker_threads);
  out.memory = batch->memory();
  const std::vector<Waypoint>& path = scene->tools.front().path;
  const long ramp = c.o.quick ? 5 : 30;
  long k = 0;
  auto drive = [&] {
    for (std::size_t i = 0; i < n; ++i) (*batch)[i].device(0).set_pose(batch_tip(path, k, i, n, ramp), {0, 0, 0});
  };
  for (; k < ramp; ++k) {  // down to the tissue: regions grow, graphs are captured
    drive();
    batch->tick();
  }
  std::vector<double> lat;
  const std::int64_t together0 = batch->ticks_together(), alone0 = batch->ticks_alone();
  const auto t0 = Clock::now();
  while (lat.size() < (c.o.quick ? 3u : 20u) || since(t0) < min_seconds) {
    drive();
    const auto t1 = Clock::now();
    out.running = batch->tick();
    lat.push_back(since(t1));
    out.start_s += batch->last_phases().start;
    out.device_s += batch->last_phases().device;
    out.end_s += batch->last_phases().end;
    ++k;
  }
  out.ticks = long(lat.size());
  out.start_s /= double(out.ticks);
  out.device_s /= double(out.ticks);
  out.end_s /= double(out.ticks);
  out.groups = batch->groups();
  const std::int64_t together = batch->ticks_together() - together0, alone = batch->ticks_alone() - alone0;
  out.together = together + alone > 0 ? double(together) / double(together + alone) : 0.0;
  const double busy = std::accumulate(lat.begin(), lat.end(), 0.0);
  out.ticks_per_s = double(lat.size()) / busy;
  std::sort(lat.begin(), lat.end());
  out.tick_p50 = lat[lat.size() / 2];
  out.tick_p99 = lat[std::min(lat.size() - 1, lat.size() * 99 / 100)];
  out.tick_max = lat.back();
  out.steps_per_tick = (*batch)[0].scheduler().steps_per_tick();
  for (std::size_t i = 0; i < n; ++i) {
    const TickReport& r = (*batch)[i].last();
    out.region_nodes += double(r.region_nodes) / double(n);
    out.region_elems += double(r.region_elems) / double(n);
    if (r.contact_nodes > 0) ++out.in_contact;
  }
  return out;
}

void emit_batch(Context& c, Precision p, std::size_t n, const BatchRun& run, double one_thread_steps,
                double scaling) {
  auto probe = create_backend(c.o.backend, p);
  Row r = c.row("batch", *probe);
  r.add("mesh", std::string("kidney"));
  r.add("law", c.o.laws.front());
  r.add("scenes", long(n));
  if (!run.skipped.empty()) {
    r.add("skipped", run.skipped);
    c.emit(r);
    return;
  }
  const int s = p == Precision::Float ? 4 : 8;
  const double scene_steps = double(n) * run.steps_per_tick * run.ticks_per_s;
  const TissueModel<double> m = scene::load_model(kidney_with_law(c.o.laws.front()));
  const double bytes_region = bytes_per_step(std::lround(run.region_nodes), std::lround(run.region_elems), s);
  r.add("elements", long(m.n_elems));
  r.add("region_elements_mean", run.region_elems);
  r.add("steps_per_tick", long(run.steps_per_tick));
  r.add("scenes_running", long(run.running));
  r.add("scenes_in_contact", long(run.in_contact));
  r.add("ticks_timed", run.ticks);
  r.add("groups", long(run.groups));
  r.add("group_tick_fraction", run.together);
  if (run.groups > 0) {  // where a tick's time goes
    r.add("tick_ms_host_start", 1e3 * run.start_s);
    r.add("tick_ms_device", 1e3 * run.device_s);
    r.add("tick_ms_host_end", 1e3 * run.end_s);
  }
  r.add("scene_steps_per_s", scene_steps);
  r.add("element_steps_per_s", scene_steps * run.region_elems);
  r.add("bytes_per_element_step", bytes_region / std::max(run.region_elems, 1.0));
  r.add("bandwidth_fraction", c.bandwidth > 0 ? scene_steps * bytes_region / c.bandwidth : 0.0);
  r.add("host_bytes_per_scene", long(run.memory.per_scene_host));
  r.add("device_bytes_per_scene", long(run.memory.per_scene_device));
  r.add("tick_ms_p50", 1e3 * run.tick_p50);
  r.add("tick_ms_p99", 1e3 * run.tick_p99);
  r.add("tick_ms_max", 1e3 * run.tick_max);
  r.add("real_time", std::string(run.tick_p99 <= 1e-3 ? "yes" : "no"));
  if (one_thread_steps > 0) {
    r.add("speedup_vs_one_thread", scene_steps / one_thread_steps);
    r.add("scaling_limit", scaling);
    r.add("fraction_of_scaling_limit", scene_steps / one_thread_steps / scaling);
  }
  c.emit(r);
}

void bench_batches(Context& c, Precision p) {
  const bool host = !create_backend(c.o.backend, p)->asynchronous_ticks();
  double one_thread = 0, scaling = 0;
  const int threads = std::max(1, tbb::this_task_arena::max_concurrency());
  if (host) {
    // the machine's own limit, and one kidney on one thread, in this run
    scaling = arithmetic_scaling(threads);
    const BatchRun one = run_batch(c, p, 1, c.o.min_seconds, 1);
    one_thread = one.steps_per_tick * one.ticks_per_s;
    Row r = c.row("cpu_scaling_limit", *create_backend(c.o.backend, p));
    r.add("threads", long(threads));
    r.add("arithmetic_scaling", scaling);
    r.add("kidney_steps_per_s_one_thread", one_thread);
    c.emit(r);
  }
  std::vector<long> sizes = c.o.batch;
  std::sort(sizes.begin(), sizes.end());
  long pass = 0, fail = 0;  // the largest real-time size seen, the smallest that was not
  for (long n : sizes) {
    if (c.o.stop && c.o.stop()) return;
    const BatchRun run = run_batch(c, p, std::size_t(n), c.o.min_seconds);
    emit_batch(c, p, std::size_t(n), run, one_thread, scaling);
    if (!run.skipped.empty()) continue;
    if (run.tick_p99 <= 1e-3) pass = std::max(pass, n);
    else if (fail == 0 || n < fail) fail = n;
  }
  // the largest real-time batch between the sizes: bisection, a few short runs
  for (int k = 0; k < 6 && pass > 0 && fail > pass + 1 && !(c.o.stop && c.o.stop()); ++k) {
    const long mid = (pass + fail) / 2;
    const BatchRun run = run_batch(c, p, std::size_t(mid), std::min(c.o.min_seconds, 0.3));
    if (!run.skipped.empty()) break;
    (run.tick_p99 <= 1e-3 ? pass : fail) = mid;
  }
  Row r = c.row("batch_real_time", *create_backend(c.o.backend, p));
  r.add("mesh", std::string("kidney"));
  r.add("law", c.o.laws.front());
  r.add("real_time_scenes", pass);
  r.add("first_size_not_real_time", fail);
  r.add("rule", std::string("batch tick p99 <= 1 ms, every scene's tool moving in contact"));
  c.emit(r);
}

std::string today() {
  const std::time_t t = std::time(nullptr);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%d", std::gmtime(&t));
  return buf;
}

}  // namespace

double bytes_per_step(long n, long ne, int s, bool recomputed) {
  // the element gradients and volume (dN 12s, V s per element), or the
  // corners' reference positions they are recomputed from, in passes 1 and
  // 3: in float a node's 16-byte grid point, in double its x, y, z (24 bytes
  // read, counted as the 32-byte record, one memory sector, that holds them)
  const double gradients = recomputed ? (s == 4 ? 16.0 : 32.0) * n : 13.0 * s * ne;
  // pass 1: corners 16, K s, u 3s per node; writes p_e V_e and J
  const double p1 = ne * (16.0 + 3 * s) + 3.0 * s * n + gradients;
  // pass 2: CSR offsets 4 per node, entries 16 per element, p V and V; writes p_a
  const double p2 = 4.0 * n + ne * (16.0 + 2 * s) + 1.0 * s * n;
  // pass 3: corners, u, p_a, mu, K; writes 12 force components
  const double p3 = ne * (16.0 + 14 * s) + 4.0 * s * n + gradients;
  // pass 4: CSR, element forces, u^n, u^{n-1}, A/B/C, held flag and target; writes u^{n+1}, f (float's
  // carried bits ride in u's padding on the device; the cpu's u_carry, 6 s n more, is not counted)
  const double p4 = 5.0 * n + ne * (16.0 + 12 * s) + 18.0 * s * n;
  return p1 + p2 + p3 + p4;
}

double arithmetic_scaling(int threads) {
  // a chain of dependent multiply-adds per lane, eight independent lanes: registers only
  auto work = [](long iterations) {
    double x[8] = {1.0, 1.1, 1.2, 1.3, 1.4, 1.5, 1.6, 1.7};
    for (long k = 0; k < iterations; ++k)
      for (double& v : x) v = v * 0.999999 + 1e-7;
    double sum = 0;
    for (double v : x) sum += v;
    return sum;
  };
  const long iterations = 20'000'000;
  volatile double sink = work(iterations / 10);  // warm-up
  auto timed = [&](int n) {
    double best = 1e300;
    for (int r = 0; r < 3; ++r) {
      std::vector<std::thread> th;
      std::vector<double> out(static_cast<std::size_t>(n), 0.0);
      const auto t0 = Clock::now();
      for (int k = 0; k < n; ++k) th.emplace_back([&, k] { out[std::size_t(k)] = work(iterations); });
      for (auto& t : th) t.join();
      best = std::min(best, since(t0));
      sink = sink + out[0];
    }
    return best;
  };
  const double one = timed(1), all = timed(threads);
  return threads * one / all;
}

double host_copy_bandwidth() {
  const size_t bytes = size_t(1) << 28;  // 256 MiB each way, far above the caches
  std::vector<char> a(bytes, 1), b(bytes, 0);
  const unsigned nt = std::max(1u, std::thread::hardware_concurrency());
  auto copy = [&] {
    std::vector<std::thread> th;
    const size_t chunk = bytes / nt;
    for (unsigned k = 0; k < nt; ++k)
      th.emplace_back([&, k] { std::memcpy(b.data() + k * chunk, a.data() + k * chunk, chunk); });
    for (auto& t : th) t.join();
  };
  copy();
  double best = 1e300;
  for (int r = 0; r < 5; ++r) {
    const auto t0 = Clock::now();
    copy();
    best = std::min(best, since(t0));
  }
  return 2.0 * bytes / best;
}

/// The live-cut rows (BenchOptions::cut): the built-in kidney pressed by its probe to contact, then cut
/// across (transverse planes at x = -30, -20, +20, +30 mm, the whole section each) between ticks, the
/// probe pressing on; each cut timed alone, then the haptic ticks after the last.
void bench_cut(Context& c, Precision p) {
  scene::Scene s = io::default_kidney_scene();
  s.solver.backend = c.o.backend;
  s.solver.precision = p;
  const auto pressed = [](Session& run) {  // the probe in contact, 50 ticks on
    while (!run.scheduler().in_contact() && run.scheduler().ticks() < 2000) run.tick();
    for (int k = 0; k < 50; ++k) run.tick();
  };
  const auto across = [](double x) { return CutSurface{{x, -0.06, -0.04}, {0, 0.12, 0}, {0, 0, 0.08}}; };
  constexpr double kPlanes[] = {-0.03, -0.02, 0.02, 0.03};
  Session session(s);
  pressed(session);
  std::vector<double> cut_s;
  const std::size_t elements_before = std::size_t(session.model().n_elems);
  const double dt_crit_before = session.model().dt_crit_physical;
  for (double x : kPlanes) {
    const auto t0 = Clock::now();
    session.cut(across(x));
    cut_s.push_back(since(t0));
    for (int k = 0; k < (c.o.quick ? 2 : 20); ++k) session.tick();
  }
  std::vector<double> lat;
  for (int k = 0; k < (c.o.quick ? 20 : 500); ++k) {
    const auto t0 = Clock::now();
    session.tick();
    lat.push_back(since(t0));
  }
  std::sort(lat.begin(), lat.end());
  std::vector<double> sorted = cut_s;
  std::sort(sorted.begin(), sorted.end());
  // the same cuts prepared while the probe presses on (Session::begin_cut, a blade's way), each taking
  // effect 0.1 s later, the ticks paced at the haptic rate as the haptic loop paces them
  // (the preparation runs on the cores they leave idle): every tick timed, the commits' among them
  Session live(s);
  pressed(live);
  const long delay = std::lround(std::ceil(0.1 / live.settings().tick - 1e-9));  // a blade's cut-delay="0.1"
  const auto period = std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(live.settings().tick));
  std::vector<double> cutting, commit_s, prepare_s;
  // the commit's parts (their medians), and the ticks from the commit's on (the most over the cuts)
  std::vector<double> parts[5];
  constexpr int kAfter = 8;
  std::vector<double> from_commit(kAfter + 1, 0.0);
  // the region rebuilds while cutting, and those in the ticks after a commit (every rebuild gives the cuda
  // backend new tick graphs)
  long rebuilds_cutting = 0, rebuilds_after_commit = 0;
  // and the step graphs captured (cuda): at the commits' ticks (the prepared backend's own among them) and after,
  // and of those after, how many updated a kept graph in place rather than instantiating one
  long captures_at_commit = 0, captures_after_commit = 0, updates_after_commit = 0;
  for (double x : kPlanes) {
    live.begin_cut(across(x), {}, CutSpace::Deformed, live.scheduler().ticks() + delay);
    auto deadline = Clock::now();
    int since_commit = -1;
    for (int k = 0; k < delay + (c.o.quick ? 2 : 20); ++k) {
      const long cuts = live.cuts(), rebuilds = live.scheduler().region_rebuilds();
      const Backend* was = &live.backend();
      const long captures = was->graph_captures(), updates = was->graph_updates();
      const auto t0 = Clock::now();
      live.tick();
      cutting.push_back(since(t0));
      const long rebuilt = live.scheduler().region_rebuilds() - rebuilds;
      const long captured = live.backend().graph_captures() - (&live.backend() == was ? captures : 0);
      const long updated = live.backend().graph_updates() - (&live.backend() == was ? updates : 0);
      rebuilds_cutting += rebuilt;
      if (live.cuts() != cuts) since_commit = 0;
      if (since_commit == 0) captures_at_commit += captured;
      if (since_commit >= 1 && since_commit <= kAfter)
        rebuilds_after_commit += rebuilt, captures_after_commit += captured, updates_after_commit += updated;
      if (since_commit >= 0 && since_commit <= kAfter) {
        from_commit[std::size_t(since_commit)] = std::max(from_commit[std::size_t(since_commit)], cutting.back());
        ++since_commit;
      }
      deadline += period;
      std::this_thread::sleep_until(deadline);
    }
    commit_s.push_back(live.last_cut_seconds());
    prepare_s.push_back(live.last_cut_prepare_seconds());
    const Session::CommitTimes& t = live.last_commit_times();
    for (int j = 0; const double part : {t.download, t.transfer, t.swap, t.loads, t.upload}) parts[j++].push_back(part);
  }
  // beside them, as many ticks paced alike with no cut (the machine's own stalls)
  std::vector<double> paced;
  auto deadline = Clock::now();
  for (std::size_t k = 0; k < cutting.size(); ++k) {
    const auto t0 = Clock::now();
    live.tick();
    paced.push_back(since(t0));
    deadline += period;
    std::this_thread::sleep_until(deadline);
  }
  std::sort(paced.begin(), paced.end());
  std::sort(cutting.begin(), cutting.end());
  std::sort(commit_s.begin(), commit_s.end());
  std::sort(prepare_s.begin(), prepare_s.end());
  Row r = c.row("live_cut", session.backend());
  r.add("mesh", std::string("kidney"));
  r.add("cuts", long(cut_s.size()));
  r.add("elements_before", long(elements_before));
  r.add("elements_after", long(session.model().n_elems));
  r.add("dt_crit_after_over_before", session.model().dt_crit_physical / dt_crit_before);
  r.add("cut_ms_median", 1e3 * sorted[sorted.size() / 2]);
  r.add("cut_ms_max", 1e3 * sorted.back());
  r.add("steps_per_tick", long(session.scheduler().steps_per_tick()));
  r.add("tick_ms_p50_after", 1e3 * lat[lat.size() / 2]);
  r.add("tick_ms_p99_after", 1e3 * lat[lat.size() * 99 / 100]);
  r.add("cut_delay_ticks", delay);
  r.add("prepare_ms_median", 1e3 * prepare_s[prepare_s.size() / 2]);
  r.add("commit_ms_median", 1e3 * commit_s[commit_s.size() / 2]);
  r.add("commit_ms_max", 1e3 * commit_s.back());
  for (int j = 0; const char* part : {"download", "transfer", "swap", "loads", "upload"}) {
    std::vector<double>& v = parts[j++];
    std::sort(v.begin(), v.end());
    r.add(fmt::format("commit_ms_median_{}", part), 1e3 * v[v.size() / 2]);
  }
  r.add("region_rebuilds_while_cutting", rebuilds_cutting);
  r.add("region_rebuilds_commit_plus_1_to_8", rebuilds_after_commit);
  r.add("graph_captures_at_commits", captures_at_commit);
  r.add("graph_captures_commit_plus_1_to_8", captures_after_commit);
  r.add("graph_updates_commit_plus_1_to_8", updates_after_commit);
  r.add("tick_ms_max_at_commit", 1e3 * from_commit[0]);
  for (int j = 1; j <= kAfter; ++j) r.add(fmt::format("tick_ms_max_commit_plus_{}", j), 1e3 * from_commit[std::size_t(j)]);
  r.add("tick_ms_p50_while_cutting", 1e3 * cutting[cutting.size() / 2]);
  r.add("tick_ms_p99_while_cutting", 1e3 * cutting[cutting.size() * 99 / 100]);
  r.add("tick_ms_max_while_cutting", 1e3 * cutting.back());
  r.add("tick_ms_p50_paced_uncut", 1e3 * paced[paced.size() / 2]);
  r.add("tick_ms_p99_paced_uncut", 1e3 * paced[paced.size() * 99 / 100]);
  r.add("tick_ms_max_paced_uncut", 1e3 * paced.back());
  // the share of ticks longer than the haptic period
  const auto late = [&](const std::vector<double>& t) {
    return double(t.end() - std::upper_bound(t.begin(), t.end(), live.settings().tick)) / double(t.size());
  };
  r.add("late_while_cutting", late(cutting));
  r.add("late_paced_uncut", late(paced));
  c.emit(r);
}

std::vector<std::string> run_bench(const BenchOptions& o) {
  Context c{o, "", 0, today(), {}};
  {
    auto probe = create_backend(o.backend, Precision::Float);
    c.device = probe->device_name();
  }
  c.bandwidth = o.backend == "cpu" ? host_copy_bandwidth() : measure_device_bandwidth(o.backend);
  const auto stopped = [&] { return o.stop && o.stop(); };
  for (Precision p : o.precisions) {
    if (o.cut) {
      if (!stopped()) bench_cut(c, p);
      continue;
    }
    if (!o.batch.empty()) {
      bench_batches(c, p);
      continue;
    }
    for (const std::string& mesh : o.sizes)
      for (const std::string& law : o.laws)
        if (!stopped()) bench_tled(c, mesh, p, law);
    std::vector<std::optional<double>> frictions(o.friction.begin(), o.friction.end());
    if (frictions.empty()) frictions.emplace_back();  // frictionless contact steps, the scenes' own tools
    for (const std::optional<double>& mu : frictions) {
      for (long tris : {10'000L, 100'000L})
        if (!stopped()) bench_contact(c, tris, p, mu.value_or(0));
      if (!stopped() && !c.o.quick) bench_contact(c, 100'000L, p, mu.value_or(0), 0.010);  // a large instrument
    }
    if (!stopped()) bench_contact_chains(c, p);
    std::vector<std::optional<double>> safeties(o.tick_dt_safety.begin(), o.tick_dt_safety.end());
    if (safeties.empty()) safeties.emplace_back();  // the scene's own
    const std::vector<TickScene> ticks = tick_scenes(o);
    for (int depth : {5, kDepthAll})
      for (const std::optional<double>& safety : safeties)
        for (const std::optional<double>& mu : frictions)
          for (const TickScene& ts : ticks)
            if (!stopped()) bench_tick(c, p, depth, safety, mu, ts);
  }
  if (!o.json_path.empty()) {
    io::AtomicTextFile f(o.json_path);
    f.out() << "[\n";
    for (size_t k = 0; k < c.rows.size(); ++k) f.out() << "  " << c.rows[k] << (k + 1 < c.rows.size() ? ",\n" : "\n");
    f.out() << "]\n";
    f.commit();
  }
  return c.rows;
}

}  // namespace tissue::bench
