// The per-step tissue state (structure of arrays, same layouts as model.hpp):
// what the four IANP passes read and write, the region and the constraint
// targets. A host backend owns one TissueState<T>; the CUDA backend keeps the
// same fields as device buffers.
#pragma once

#include <algorithm>
#include <vector>

#include "core/contact.hpp"
#include "core/model.hpp"
#include "core/region.hpp"
#include "core/store.hpp"

namespace tissue {

/// A state array's entries at `init` (core/store.hpp Init) for model m:
/// the node's fixed axes for FixedAxes, else one value for all.
template <class V, class Model>
void store_fill(std::vector<V>& v, std::size_t size, Init init, const Model& m) {
  if (init == Init::FixedAxes) {  // (per node, one component)
    v.resize(size);
    for (std::size_t a = 0; a < size; ++a) v[a] = V(fixed_axes(m.node_flags[a]));
    return;
  }
  const V value = init == Init::One      ? V(1)
                  : init == Init::NoTool ? V(-1)
                  : init == Init::Inner  ? V(kInner)
                  : init == Init::NoBad  ? V(~0ull)
                                         : V(0);
  v.assign(size, value);
}

template <class T>
struct TissueState {
  // u, u_prev, u_next, u_held, held, driven, elem_dv, elem_J, elem_F,
  // node_p, f_slot, f, contact, contact_tool, contact_normal, grasp_offset:
  // one std::vector each, declared in core/store.hpp (TISSUE_STATE_ARRAYS,
  // TISSUE_PASS_ARRAYS, TISSUE_HOST_STATE_ARRAYS) with their shapes, initial
  // values and units. Held nodes' components are set from u_held, not
  // integrated (held: kAllAxes for fixed, halo and fully driven nodes);
  // host backends' pass 3 reads elem_F instead of recomputing F.
#define TISSUE_STORE_MEMBER(name, type, per, components, init, unit, what) \
  std::vector<typename StoreTypes<T>::type> name;
  TISSUE_STATE_ARRAYS(TISSUE_STORE_MEMBER)
  TISSUE_PASS_ARRAYS(TISSUE_STORE_MEMBER)
  TISSUE_HOST_STATE_ARRAYS(TISSUE_STORE_MEMBER)
#undef TISSUE_STORE_MEMBER
  std::vector<T> load;     ///< applied load R (Backend::set_loads; 3 x n_nodes) N; empty = none
  // visco_q: the law terms' state, one std::vector each (core/material.hpp TISSUE_LAW_STATE_FIELDS)
#define TISSUE_LAW_MEMBER(kind, name, len) std::vector<typename LawFieldTypes<T>::kind> name;
  TISSUE_LAW_STATE_FIELDS(TISSUE_LAW_MEMBER)
#undef TISSUE_LAW_MEMBER
  Region region;           ///< active nodes and elements

  /// Zeroes the law terms' state (a new initial condition: no history).
  void clear_law_state() {
#define TISSUE_LAW_ZERO(kind, name, len) std::fill(name.begin(), name.end(), typename LawFieldTypes<T>::kind(0));
    TISSUE_LAW_STATE_FIELDS(TISSUE_LAW_ZERO)
#undef TISSUE_LAW_ZERO
  }

  /// Sizes every array for model m at its declared shape and initial value
  /// (core/store.hpp): no load, no law history.
  template <class Model>
  void resize(const Model& m) {
    load.clear();
#define TISSUE_LAW_ZERO(kind, name, len) name.assign(len, typename LawFieldTypes<T>::kind(0));
    TISSUE_LAW_STATE_FIELDS(TISSUE_LAW_ZERO)
#undef TISSUE_LAW_ZERO
#define TISSUE_STORE_RESIZE(name, type, per, components, init, unit, what) \
  store_fill(name, store_entries(Per::per, m) * (components), Init::init, m);
    TISSUE_STATE_ARRAYS(TISSUE_STORE_RESIZE)
    TISSUE_PASS_ARRAYS(TISSUE_STORE_RESIZE)
    TISSUE_HOST_STATE_ARRAYS(TISSUE_STORE_RESIZE)
#undef TISSUE_STORE_RESIZE
  }
};

}  // namespace tissue
