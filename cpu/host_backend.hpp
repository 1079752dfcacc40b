// The cpu backend's class (private to cpu/ and its tests; everyone else uses
// make_cpu_backend() and the Backend interface). It owns the model and the
// state in its scalar T (float or double), allocated once in upload(); the
// step loop (advance and the four passes, reduce, collide) allocates nothing.
// Stages are the free functions of cpu/passes.hpp, cpu/constraints.hpp,
// cpu/reduce.hpp and cpu/embree_surface.hpp; this class only sequences them.
// Not thread-safe: one thread (the haptic loop) drives it.
#pragma once

#include <memory>
#include <vector>

#include "core/backend.hpp"
#include "core/state.hpp"
#include "cpu/bad_element.hpp"
#include "cpu/embree_surface.hpp"
#include "cpu/passes.hpp"
#include "cpu/reduce.hpp"

namespace tissue::cpu {

template <class T>
class CpuBackend final : public Backend {
 public:
  std::string name() const override { return "cpu"; }
  Precision precision() const override;
  std::string device_name() const override;

  void upload(const TissueModel<double>& model) override;
  /// Also moves the targets of halo nodes to the new u (they are held "at
  /// their current displacement") and recomputes pass 1 over all elements.
  /// Fixed and driven nodes keep their targets (the next step restores them).
  void set_displacements(std::span<const double> u) override;
  RegionSizes build_region(std::span<const index_t> seeds, int depth) override;
  Region region() override { return state_.region; }
  void set_driven(std::span<const index_t> nodes, std::span<const double> u) override;
  void clear_driven() override;
  void set_driven_axes(std::span<const index_t> nodes, std::span<const double> u,
                       std::span<const std::uint8_t> axes) override;

  void element_pressure() override;
  void nodal_pressure() override;
  void element_forces() override;
  void node_update() override;
  void advance(int steps) override;

  Hit collide(Vec3<double> a, Vec3<double> b) override;
  /// Also the strain energy over the region's elements and the front
  /// ring's displacement (cpu/reduce.hpp).
  Reductions reduce() override;
  Fields download() override;
  void write_positions(float* dst) override;

  /// The store, read-only (tests).
  const TissueModel<T>& model() const { return model_; }
  const TissueState<T>& state() const { return state_; }
  /// Embree refits done so far (tests: a query refits only after u changed).
  long surface_refits() const { return surface_ ? surface_->refits() : 0; }

 private:
  void require_upload(const char* what) const;
  void step();

  TissueModel<T> model_;
  TissueState<T> state_;
  std::vector<T> node_volume_;        ///< sum_e V_e per node (n_nodes) m^3, pass 2's denominator
  std::vector<index_t> all_elems_;    ///< 0..n_elems-1: pass 1 over every element
  std::vector<index_t> driven_list_;  ///< currently driven nodes
  std::unique_ptr<EmbreeSurface<T>> surface_;
  EnergyScratch<T> energy_;           ///< strain_energy's passes 1-2, taken by the next step
  BadElementFlag bad_;
  PassPartitioners parts_;
  tbb::affinity_partitioner all_elems_part_;
  bool uploaded_ = false;
};

}  // namespace tissue::cpu
