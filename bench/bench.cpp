#include "bench/bench.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>
#include <cstring>
#include <ctime>
#include <fstream>
#include <memory>
#include <stdexcept>
#include <thread>

#include "backends/registry.hpp"
#include "io/atomic_file.hpp"
#include "core/box_mesh.hpp"
#include "core/scheduler.hpp"
#include "cpu/element_lanes.hpp"
#include "io/kidney.hpp"
#include "scene/validate.hpp"

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
    if (b.name() == "cpu") r.add("cpu_tuning", std::string(cpu::to_string(cpu::lanes_tuning())));
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

void bench_contact(Context& c, long want_tris, Precision p, double radius = 0.002) {
  // a flat slab of N x N x 1 cells (4 (N^2 + 2N) surface triangles), a sphere (2 mm; 10 mm: a large
  // instrument, hundreds of triangles in reach) pressed 0.5 mm (at most a quarter of the slab) into its
  // top and sliding slowly; the region is one ring around the contact so that a step's time is mostly
  // the contact stage's: the query of the surface and the sweep of the triangles it finds
  int N = static_cast<int>(std::lround(std::sqrt(want_tris / 4.0)));
  if (c.o.quick) N = std::min(N, 10);
  const TissueModel<double> m = box_model(N, N, 1, 0.1, 0.1, 0.1 / N, true);
  auto b = create_backend(c.o.backend, p);
  b->upload(m);
  const ToolShape tool{"probe", radius, 0};
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

void bench_tick(Context& c, Precision p, int depth, std::optional<double> dt_safety, const std::string& law) {
  scene::Scene s = kidney_with_law(law);
  s.solver.dt_safety = dt_safety.value_or(s.solver.dt_safety);
  const TissueModel<double> m = scene::load_model(s);
  SchedulerSettings st = scene::scheduler_settings(s);
  st.depth = depth;
  auto b = create_backend(c.o.backend, p);
  b->upload(m);
  Scheduler sched(*b, m, st);
  ScriptedDevice dev(s.tools.front().path);
  std::vector<double> lat;
  const long n = std::lround((c.o.quick ? 0.3 : dev.duration()) / st.tick);
  for (long k = 0; k < n; ++k) {
    const auto t0 = Clock::now();
    sched.tick(dev);
    if (sched.in_contact()) lat.push_back(since(t0));
  }
  if (lat.empty()) throw std::runtime_error("bench: the kidney tool path never touched the kidney");
  std::sort(lat.begin(), lat.end());
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
  r.add("mesh", std::string("kidney"));
  r.add("law", law);
  r.add("depth", depth == kDepthAll ? std::string("all") : std::to_string(depth));
  r.add("dt_safety", s.solver.dt_safety);
  r.add("steps_per_tick", long(sched.steps_per_tick()));
  r.add("ticks_in_contact", long(lat.size()));
  r.add("tick_ms_p50", 1e3 * lat[lat.size() / 2]);
  r.add("tick_ms_p99", 1e3 * lat[lat.size() * 99 / 100]);
  r.add("tick_ms_max", 1e3 * lat.back());
  r.add("reduce_ms_p50", 1e3 * red[red.size() / 2]);
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
  // pass 4: CSR, element forces, u^n, u^{n-1}, A/B/C, held flag and target; writes u^{n+1}, f
  const double p4 = 5.0 * n + ne * (16.0 + 12 * s) + 18.0 * s * n;
  return p1 + p2 + p3 + p4;
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

std::vector<std::string> run_bench(const BenchOptions& o) {
  Context c{o, "", 0, today(), {}};
  {
    auto probe = create_backend(o.backend, Precision::Float);
    c.device = probe->device_name();
  }
  c.bandwidth = o.backend == "cpu" ? host_copy_bandwidth() : measure_device_bandwidth(o.backend);
  const auto stopped = [&] { return o.stop && o.stop(); };
  for (Precision p : o.precisions) {
    for (const std::string& mesh : o.sizes)
      for (const std::string& law : o.laws)
        if (!stopped()) bench_tled(c, mesh, p, law);
    for (long tris : {10'000L, 100'000L})
      if (!stopped()) bench_contact(c, tris, p);
    if (!stopped() && !c.o.quick) bench_contact(c, 100'000L, p, 0.010);  // a large instrument
    if (!stopped()) bench_contact_chains(c, p);
    std::vector<std::optional<double>> safeties(o.tick_dt_safety.begin(), o.tick_dt_safety.end());
    if (safeties.empty()) safeties.emplace_back();  // the scene's own
    for (int depth : {5, kDepthAll})
      for (const std::optional<double>& safety : safeties)
        for (const std::string& law : o.laws)
          if (!stopped()) bench_tick(c, p, depth, safety, law);
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
