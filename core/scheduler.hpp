// The Scheduler runs one haptic tick on the active backend, as a list of
// stages: read device -> collide -> contact -> region -> N TLED steps ->
// reductions -> force to device. It knows nothing of CUDA, TBB or Embree.
//
// Contact rule (DESIGN.md section 3, made exact here): when the segment from
// the previous to the current tip position first crosses the deformed
// surface at point P0 of triangle t (outward normal n0, corner displacements
// u0_k), the three corners of t become tool-driven, each displaced by
// u_k = u0_k + (tip - P0): the contact triangle translates rigidly with the
// tip, so the tip stays at the same barycentric point of it. Contact ends on
// the first tick at which (tip - P0) . n0 > 0, i.e. the tool has withdrawn
// beyond the surface point it touched; the nodes are then released and the
// tissue relaxes. The region is rebuilt when a contact starts on a triangle
// whose corners differ from the current seeds, and kept after release so
// that the tissue can relax back.
//
// Adaptive region (depth = kDepthAuto): the first contact builds the region
// with auto_start rings; after every tick's reduction, while the largest
// displacement on the region's front ring (its outermost inner nodes,
// Reductions::front_disp) exceeds auto_tol times the largest displacement in
// the region, the region grows by one ring (same seeds), up to the whole
// connected mesh. The halo beyond the front is held where it is, so the
// front's displacement bounds how much the truncation holds back; the region
// never shrinks.
#pragma once

#include <stdexcept>
#include <string>

#include "core/backend.hpp"
#include "core/device.hpp"

namespace tissue {

struct SchedulerSettings {
  int depth = 5;               ///< region rings from the contact triangle; kDepthAll = whole mesh;
                               ///< kDepthAuto = adaptive (see above)
  double auto_tol = 0.02;      ///< depth auto: grow while front_disp > auto_tol * max_disp (dimensionless)
  int auto_start = 2;          ///< depth auto: rings of the region built at the first contact (>= 0)
  double tick = 1e-3;          ///< haptic period (s)
  double residual_tol = 1e-3;  ///< equilibrium: |f_free| / max(|f_held|, force_floor)
  double kinetic_tol = 1e-6;   ///< equilibrium: kinetic / max(energy scale, energy_floor)
  double force_floor = 1e-9;   ///< N
};

/// What one tick did (one CSV row).
struct TickReport {
  long tick = 0;
  double time = 0;             ///< simulated time at the end of the tick (s)
  Vec3<double> tool = {};      ///< tool tip (m)
  index_t contact_tri = -1;    ///< driving triangle, -1 none
  Vec3<double> force = {};     ///< force on the tool: -(sum of internal forces on driven nodes) (N)
  Vec3<double> internal = {};  ///< sum of internal forces over inner nodes (N)
  index_t region_nodes = 0, region_elems = 0;
  double residual = 0;         ///< relative free-node residual
  double kinetic = 0;          ///< J
  double kinetic_rel = 0;      ///< kinetic / (0.5 |f_held| max|u|): the equilibrium test's kinetic measure
  double strain_energy = -1;   ///< J, over the computed elements; -1 = the backend does not compute it
  double max_disp = 0;         ///< m
  double front_disp = -1;      ///< max |u| on the region's front ring (m); -1 = not computed
  int depth = kDepthAll;       ///< region depth in use at the end of the tick (rings; kDepthAll = whole)
  bool equilibrium = false;
  int steps = 0;               ///< TLED steps in this tick
};

/// NaN/Inf or an inverted element appeared mid-run.
struct SimulationError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

class Scheduler {
 public:
  /// The backend must already hold `model` (Backend::upload).
  Scheduler(Backend& backend, const TissueModel<double>& model, SchedulerSettings settings);

  /// One haptic tick; throws SimulationError naming tick, steps and element.
  TickReport tick(Device& device);

  int steps_per_tick() const { return steps_per_tick_; }
  long ticks() const { return tick_; }
  long total_steps() const { return total_steps_; }
  double time() const { return tick_ * settings_.tick; }
  bool in_contact() const { return contact_tri_ >= 0; }
  const RegionSizes& region() const { return region_; }
  /// Rings of the current region (kDepthAll = whole); under depth auto, the
  /// depth it has grown to.
  int depth() const { return depth_; }
  const std::vector<index_t>& seeds() const { return seeds_; }
  const SchedulerSettings& settings() const { return settings_; }

 private:
  void start_contact(const Hit& hit, const Vec3<double>& tip);
  void drive(const Vec3<double>& tip);
  bool grow_region(const Reductions& r);

  Backend& backend_;
  const TissueModel<double>& model_;
  SchedulerSettings settings_;
  int steps_per_tick_ = 1;
  int depth_ = kDepthAll;       ///< current rings (settings_.depth, or the grown depth under auto)
  bool auto_depth_ = false;
  long tick_ = 0;
  long total_steps_ = 0;
  bool has_prev_ = false;
  Vec3<double> prev_ = {};
  RegionSizes region_;
  std::vector<index_t> seeds_;  ///< seeds of the current region (sorted)
  // contact
  index_t contact_tri_ = -1;
  index_t nodes_[3] = {-1, -1, -1};
  Vec3<double> u0_[3] = {};
  Vec3<double> p0_ = {}, n0_ = {};
};

}  // namespace tissue
