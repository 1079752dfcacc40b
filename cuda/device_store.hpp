// The device mirror of the tissue store: every model and state array of
// core/model.hpp and core/state.hpp as one DeviceArray each, allocated and
// uploaded once per scene by upload(), and handed to kernels as views
// (cuda/views.hpp, which also gives the device layouts).
#pragma once

#include <cuda_runtime.h>

#include <array>
#include <cstdint>
#include <span>

#include "core/model.hpp"
#include "cuda/cuda_backend.hpp"
#include "cuda/device_array.hpp"
#include "cuda/views.hpp"

namespace tissue::gpu {

/// The three rotating displacement buffers: roles (u_prev, u, u_next) are
/// (buf[p], buf[p+1], buf[p+2]) mod 3 for phase p; a step advances p by one.
/// A captured graph bakes the pointers of its starting phase into its
/// kernels, so graphs are cached per phase (cuda/stepper.hpp).
template <class T>
struct BufferRing {
  std::array<DeviceArray<Packed3<T>>, 3> buf;
  int phase = 0;  ///< 0..2

  StepBuffers<T> at(int p) { return {buf[p % 3].data(), buf[(p + 1) % 3].data(), buf[(p + 2) % 3].data()}; }
  StepBuffers<T> current() { return at(phase); }
  void advance(int steps) { phase = (phase + steps % 3) % 3; }
};

template <class T>
class DeviceStore {
 public:
  /// Allocates every array for the model's sizes and uploads the model
  /// (counted in `log`); the state is then reset (reset_state()). `ref` is
  /// the model in double (m converted), whose positions and gradients
  /// decide and serve `gradients` (CudaGradients).
  void upload(const TissueModel<T>& m, const TissueModel<double>& ref, CudaGradients gradients, Transfers& log,
              cudaStream_t stream);

  /// Copies m's nodal masses and central-difference constants (mass, cd_A,
  /// cd_B, cd_C; n_nodes each, the upload's sizes) into the arrays the
  /// upload allocated, in place (the tick graphs keep their pointers).
  void set_masses(const TissueModel<T>& m, Transfers& log, cudaStream_t stream);

  /// u = u_prev = u_next = 0, u_held = 0, f = f_slot = elem_dv = node_p = 0,
  /// elem_J = 1 (both pass-array sets; set 0 the state's), held = the
  /// fixed axes, driven = 0, every node inner, no bad element, no contact.
  void reset_state(cudaStream_t stream);

  /// Zeroes the law terms' state (the Prony q_i): no history.
  void clear_law_state(cudaStream_t stream);

  /// The applied load (Backend::set_loads): 3 x n_nodes component-major
  /// (N), or empty for none (frees it; state().load is then null).
  void set_load(std::span<const double> load, Transfers& log, cudaStream_t stream);
  /// From the next upload on, keep the load's array allocated (at upload,
  /// in a group's slot) whether or not a load is set, so that it lies at
  /// the same place in every member's slot; state().load stays null while
  /// no load is set.
  void set_reserve_load(bool reserve) { reserve_load_ = reserve; }
  /// The load's array (reserved or set), or null.
  const void* load_space() const { return load_.size() ? load_.data() : nullptr; }

  ModelView<T> model() const { return model_; }
  /// Overrides ModelView::lanes_node_min until the next upload (tests: 0
  /// runs every region's chained node passes two lanes a thread; the same
  /// bits).
  void set_lanes_node_min(index_t nodes) { model_.lanes_node_min = nodes; }
  /// Overrides ModelView::discard_slots until the next upload (tests: the
  /// same bits either way).
  void set_discard_slots(bool discard) { model_.discard_slots = discard; }
  LawView<T> law() const { return law_; }
  StateView<T> state();

  /// The pass arrays (elem_dv, elem_J, node_p) come in two sets: the
  /// state's, which the steps use, and a scratch set, into which the
  /// reduction runs passes 1-2 at the current u (its strain energy). When
  /// the steps go on from that u, the sets swap roles and the first step
  /// starts at pass 3 (the cpu backend's take_passes). state() views the
  /// state's set; this view is state() with the scratch set instead.
  StateView<T> pressure_scratch();
  /// The scratch set becomes the state's (and the state's the scratch).
  void swap_pressures() { pressures_ ^= 1; }
  /// Which of the two sets is the state's (0 or 1).
  int pressure_set() const { return pressures_; }
  /// Copies the state's set whole into the scratch set (so that the two
  /// agree outside any region the reduction runs over).
  void copy_pressures_to_scratch(cudaStream_t stream);

  index_t n_nodes() const { return model_.n_nodes; }
  index_t n_elems() const { return model_.n_elems; }
  index_t n_tris() const { return model_.n_tris; }

  BufferRing<T> u;  ///< u^{n-1}, u^n, u^{n+1}

 private:
  ModelView<T> model_;
  LawView<T> law_;
  // model (read-only after upload)
  DeviceArray<Packed3<T>> X_;
  DeviceArray<ReferencePoint<T>> X_ref_;  // empty when the gradients are stored
  DeviceArray<index_t> elem_nodes_, node_elem_start_, node_elem_, slot_of_, tris_, pack_first_;
  DeviceArray<index_t> surf_nodes_, surf_slot_start_, surf_slot_;
  DeviceArray<T> dndx_, volume_, node_divisor_;
  DeviceArray<std::uint8_t> node_flags_;
  /// The arrays of core/store.hpp's lists, one DeviceArray each (a Packed3
  /// per entry for vectors): the material's (read-only after upload), the
  /// state's and the device's own; the pass arrays in two sets
  /// (pressure_scratch()).
  struct StoreArrays {
#define TISSUE_DEVICE_ARRAY(name, type, per, components, ...) \
  DeviceArray<device_element_t<T, typename StoreTypes<T>::type, components>> name;
#define TISSUE_DEVICE_ARRAY_PAIR(name, type, per, components, ...) \
  DeviceArray<device_element_t<T, typename StoreTypes<T>::type, components>> name[2];
    TISSUE_MATERIAL_ARRAYS(TISSUE_DEVICE_ARRAY)
    TISSUE_STATE_ARRAYS(TISSUE_DEVICE_ARRAY)
    TISSUE_DEVICE_STATE_ARRAYS(TISSUE_DEVICE_ARRAY)
    TISSUE_PASS_ARRAYS(TISSUE_DEVICE_ARRAY_PAIR)
#undef TISSUE_DEVICE_ARRAY_PAIR
#undef TISSUE_DEVICE_ARRAY
  };
  StoreArrays arrays_;
  int pressures_ = 0;  ///< the pass arrays' set that is the state's
  /// The law terms' arrays, one per line of core/material.hpp's lists (empty when unused).
  struct LawArrays {
#define TISSUE_LAW_DEVICE_ARRAY(kind, name, len) DeviceArray<typename LawFieldTypes<T>::kind> name;
    TISSUE_LAW_MODEL_FIELDS(TISSUE_LAW_DEVICE_ARRAY)
    TISSUE_LAW_STATE_FIELDS(TISSUE_LAW_DEVICE_ARRAY)
#undef TISSUE_LAW_DEVICE_ARRAY
  };
  LawArrays law_arrays_;
  DeviceArray<Packed3<T>> load_;  // applied load: empty when none (unless reserved)
  bool load_on_ = false;          // a load is set (state().load)
  bool reserve_load_ = false;     // set_reserve_load
};

}  // namespace tissue::gpu
