// `tissue bench`: throughput and latency of the active backend, as JSON rows.
// Measured: whole-mesh TLED steps/s and element-steps/s on the kidney and on
// generated box meshes (~100k, 1M, 4M tets); region-limited (depth 5) versus
// whole mesh on the kidney; the kidney's whole mesh with a tool set far away
// (the contact stage's cost per step); the contact stage's step latency against ~10k and
// ~100k surface triangles (a one-ring region, so the step is mostly contact);
// the time of one full haptic tick; the device's measured copy
// bandwidth and the fraction of it a TLED step achieves (bytes_per_step below).
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "core/hd.hpp"

namespace tissue::bench {

struct BenchOptions {
  std::string backend = "cpu";
  std::vector<Precision> precisions = {Precision::Float, Precision::Double};
  std::vector<std::string> sizes = {"kidney", "100k", "1m", "4m"};  ///< whole-mesh TLED meshes
  /// Material laws of the whole-mesh and haptic-tick rows (docs/materials.md): neo-hookean,
  /// visco (2 Prony terms), fibre (transversely isotropic), fibre-visco.
  std::vector<std::string> laws = {"neo-hookean"};
  double min_seconds = 0.5;  ///< time each measurement at least this long
  std::string json_path;     ///< empty: rows only on stdout
  bool quick = false;        ///< CI smoke run: tiny meshes, short timings
  /// dt-safety values of the haptic-tick rows (empty: the kidney scene's own);
  /// more than one compares their tick cost in one run
  std::vector<double> tick_dt_safety;
  std::function<bool()> stop;  ///< asked before each measurement: true ends the run with the rows done
  /// Batch sizes (--batch): when given, only the batch rows run. Each row
  /// steps that many kidneys together (session/scene_batch.hpp), every
  /// scene's tool moving in contact; then the largest real-time batch is
  /// found between the sizes, and on the cpu the machine's scaling limit is
  /// measured in the same run (arithmetic_scaling).
  std::vector<long> batch;
  /// Scene files (--scene) whose haptic-tick rows run beside the kidney's:
  /// each pressed along its first tool's scripted path, with its own
  /// materials, mesh and solver settings (the rows' law is "scene").
  std::vector<std::string> scenes;
  /// Friction coefficients (--friction) of the contact-step and haptic-tick
  /// rows' tools, one set of those rows per value (empty: frictionless
  /// contact steps and each scene's own tools).
  std::vector<double> friction;
  /// --cut: only the live-cut rows: the kidney pressed by its probe, cut
  /// across between ticks (Session::cut) at several places, each cut timed
  /// (the download, the cut, the model's rebuild and upload, the motion set
  /// again), then the haptic tick of the cut kidney.
  bool cut = false;
};

/// How many times faster `threads` threads run a pure-arithmetic loop (no
/// memory traffic: registers only) than one thread: the machine's own
/// scaling limit, which memory-bound work can at best reach.
double arithmetic_scaling(int threads);

/// Fewest bytes one whole-mesh TLED step must move through memory (each
/// array the four passes read or write counted once per pass that touches
/// it), for n nodes, ne elements and scalar size s bytes; `recomputed`: the
/// element gradients and volumes are recomputed from reference positions
/// (grid points in float, double coordinates in double) in passes 1 and 3
/// instead of loaded (the cuda backend's CudaGradients). Used for the achieved-bandwidth column; see
/// docs/benchmarks/README.md for the list.
double bytes_per_step(long n, long ne, int s, bool recomputed = false);

/// Copy bandwidth of host memory (bytes/s, read + write counted), measured
/// with a parallel copy of a buffer much larger than the caches.
double host_copy_bandwidth();

/// Runs every benchmark; returns the JSON rows (one object per line) it also
/// printed. Throws if the backend cannot run here.
std::vector<std::string> run_bench(const BenchOptions& o);

}  // namespace tissue::bench
