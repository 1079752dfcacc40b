// cuda_step_timing: steps/s of whole-mesh TLED advance on the cuda backend
// for every step mode (launch, graph, grid, cluster, auto: the registry's
// step_modes), float and double, on the default kidney (~8.4k tets) and box meshes of about 8.6k,
// 100k, 1M and 4M tets, plus the latency of one full Scheduler tick
// (depth 5) along a press path with a 2 mm sphere. Not a test: a measurement to
// run on a GPU machine (docs/cuda.md, "Step modes", sums them up). It reaches the
// backend through the registry and the Backend interface only.
//   cuda_step_timing [--quick] [--gradients auto|stored|recomputed] [cases...]
//   cases: kidney 8k 100k 1m 4m
#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "backends/registry.hpp"
#include "bench/bench.hpp"
#include "core/box_mesh.hpp"
#include "core/scheduler.hpp"
#include "io/kidney.hpp"
#include "scene/validate.hpp"

using namespace tissue;

namespace {

/// A timed mesh: its model and a tool path that presses its surface.
struct Case {
  std::string name;
  TissueModel<double> model;
  std::vector<Waypoint> path;
};

/// Brain-tissue-like material (E = 3000 Pa, nu = 0.45, rho = 1000) on a box
/// 0.1 m wide (nx x ny x nz cells, 6 tets each) fixed at z = 0, pressed 3 mm
/// at the middle of its top face.
Case box_case(const std::string& name, int nx, int ny, int nz) {
  ModelInput in;
  const double top = 0.1 * nz / nx;
  box_mesh(in, nx, ny, nz, 0.1, 0.1, top);
  const double E = 3000, nu = 0.45;
  in.materials = {{E / (2 * (1 + nu)), E / (3 * (1 - 2 * nu)), 1000}};
  in.fixed.assign(in.nodes.size() / 3, 0);
  for (size_t i = 0; i < in.fixed.size(); ++i) in.fixed[i] = in.nodes[3 * i + 2] == 0.0;
  in.source = "box " + name;
  return {name, build_model(in), press_path({0.0503, 0.0497, top + 0.002}, {0, 0, -1}, 0.003, 0.01, 0.1005)};
}

Case kidney_case() {
  const scene::Scene sc = io::default_kidney_scene();
  return {"kidney", scene::load_model(sc), sc.tools.at(0).path};
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

/// Median steps/s of advance(batch) + reduce() (the reduce synchronises).
double steps_per_second(Backend& be, double min_seconds) {
  be.advance(30);
  be.reduce();
  int batch = 30;
  for (;;) {  // grow the batch until one takes >= 20 ms
    const auto t0 = std::chrono::steady_clock::now();
    be.advance(batch);
    be.reduce();
    if (seconds_since(t0) > 0.02 || batch > (1 << 22)) break;
    batch *= 2;
  }
  std::vector<double> rates;
  const auto t_all = std::chrono::steady_clock::now();
  while (rates.size() < 5 || seconds_since(t_all) < min_seconds) {
    const auto t0 = std::chrono::steady_clock::now();
    be.advance(batch);
    be.reduce();
    rates.push_back(batch / seconds_since(t0));
  }
  std::sort(rates.begin(), rates.end());
  return rates[rates.size() / 2];
}

template <class T>
T median(std::vector<T> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

void time_case(const Case& cs, double bw, double min_seconds, bool quick, const std::string& gradients,
               std::vector<std::string>& rows) {
  const TissueModel<double>& model = cs.model;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> dist(-1e-5, 1e-5);  // a non-zero start: no timing on zeros
  std::vector<double> u0(3 * size_t(model.n_nodes));
  for (auto& v : u0) v = dist(rng);
  for (Precision p : {Precision::Float, Precision::Double}) {
    auto be = create_backend("cuda", p);
    set_element_gradients(*be, gradients);
    be->upload(model);
    const bool recomputed = element_gradients(*be) == "recomputed";
    std::vector<std::string> modes = step_modes(*be);  // "auto" first: timed last
    std::rotate(modes.begin(), modes.begin() + 1, modes.end());
    for (const std::string& mode : modes) {
      try {
        set_step_mode(*be, mode);
      } catch (const std::exception& e) {
        fmt::print("{} {} {}: skipped ({})\n", cs.name, to_string(p), mode, e.what());
        continue;
      }
      if (mode == "cluster" && model.n_elems > 200000) continue;  // one cluster: far too slow
      be->set_displacements(u0);
      const double sps = steps_per_second(*be, min_seconds);
      const Reductions r = be->reduce();
      const double frac =
          sps * bench::bytes_per_step(model.n_nodes, model.n_elems, p == Precision::Float ? 4 : 8, recomputed) / bw;
      rows.push_back(fmt::format("{:>6} {:>8} {:>7} {:>6} {:>8}{} {:>12.0f} {:>10.3g} {:>6.3f} {} {}", cs.name,
                                 model.n_elems, model.n_nodes, to_string(p), step_mode(*be),
                                 mode == "auto" ? "*" : " ", sps, sps * model.n_elems, frac,
                                 r.finite && r.bad_elem < 0 ? "ok" : "NONFINITE/BAD", element_gradients(*be)));
      fmt::print("{}\n", rows.back());
    }
    // full haptic ticks
    set_step_mode(*be, "auto");
    be->upload(model);
    ScriptedDevice dev(cs.path);
    SchedulerSettings st;
    st.depth = 5;
    Scheduler sched(*be, model, st);
    std::vector<double> tt;
    const TransferCounters t_before = be->transfers();
    const int ticks = quick ? 200 : 600;
    for (int k = 0; k < ticks; ++k) {
      const auto t0 = std::chrono::steady_clock::now();
      sched.tick(dev);
      tt.push_back(seconds_since(t0));
    }
    const TransferCounters t_after = be->transfers();
    std::vector<double> sorted = tt;
    std::sort(sorted.begin(), sorted.end());
    rows.push_back(fmt::format(
        "{:>6} {:>6} ({} surface tris) tick median {:.1f} us p99 {:.1f} us ({} steps/tick, depth-5 "
        "region {} elems); copies/tick h2d {:.2f} d2h {:.2f}",
        cs.name, to_string(p), model.n_tris, sorted[sorted.size() / 2] * 1e6,
        sorted[sorted.size() * 99 / 100] * 1e6, sched.steps_per_tick(), sched.region().n_elems,
        double(t_after.h2d - t_before.h2d) / ticks, double(t_after.d2h - t_before.d2h) / ticks));
    fmt::print("{}\n", rows.back());
  }
}

}  // namespace

int main(int argc, char** argv) {
  std::string device;
  for (const BackendInfo& b : list_backends())
    if (b.name == "cuda") {
      if (!b.available) {
        fmt::print("no GPU: {}\n", b.detail);
        return 1;
      }
      device = b.detail;
    }
  bool quick = false;
  std::string gradients = "auto";
  std::vector<std::string> want;
  for (int k = 1; k < argc; ++k) {
    const std::string a = argv[k];
    if (a == "--quick") {
      quick = true;
    } else if (a == "--gradients" && k + 1 < argc) {
      gradients = argv[++k];
      if (gradients != "auto" && gradients != "stored" && gradients != "recomputed") {
        fmt::print(stderr, "--gradients {}: expected auto, stored or recomputed\n", gradients);
        return 2;
      }
    } else {
      want.push_back(a);
    }
  }
  auto wanted = [&](const std::string& name) {
    return want.empty() || std::find(want.begin(), want.end(), name) != want.end();
  };
  const double bw = measure_device_bandwidth("cuda");
  fmt::print("device: {}\ncopy bandwidth: {:.1f} GB/s (read + write)\n", device, bw * 1e-9);
  const double min_seconds = quick ? 0.1 : 0.4;
  std::vector<std::string> rows;
  if (wanted("kidney")) time_case(kidney_case(), bw, min_seconds, quick, gradients, rows);
  const struct {
    const char* name;
    int nx, ny, nz;
  } boxes[] = {{"8k", 12, 12, 10}, {"100k", 26, 26, 25}, {"1m", 55, 55, 55}, {"4m", 88, 88, 86}};
  for (const auto& b : boxes)
    if (wanted(b.name)) time_case(box_case(b.name, b.nx, b.ny, b.nz), bw, min_seconds, quick, gradients, rows);
  fmt::print("\n{:>6} {:>8} {:>7} {:>6} {:>9} {:>12} {:>10} {:>6}\n", "mesh", "tets", "nodes", "prec", "mode",
             "steps/s", "elem-st/s", "bw-fr");
  for (const auto& r : rows) fmt::print("{}\n", r);
  return 0;
}
