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

namespace tissue {

template <class T>
struct TissueState {
  std::vector<T> u;        ///< displacement u^n (3 x n_nodes) m
  std::vector<T> u_prev;   ///< u^{n-1} (3 x n_nodes) m
  std::vector<T> u_next;   ///< u^{n+1}, written by pass 4 (3 x n_nodes) m
  std::vector<T> u_held;   ///< target of held nodes: fixed, tool-driven, halo (3 x n_nodes) m
  std::vector<std::uint8_t> held;  ///< axis mask (model.hpp kAllAxes): bit c = component c set, not
                                   ///< integrated; kAllAxes for fixed, halo and fully driven nodes (n_nodes)
  std::vector<std::uint8_t> driven;///< axis mask of the components the tool drives; 0 = not driven (n_nodes)
  std::vector<T> elem_dv;  ///< pass 1: volume change (J_e - 1) V_e (n_elems) m^3
  std::vector<T> elem_J;   ///< pass 1: J_e = det F (n_elems)
  std::vector<T> elem_F;   ///< pass 1: deformation gradient F (9 x n_elems, k = 3 i + j); host backends'
                           ///< pass 3 reads it instead of recomputing F
  std::vector<T> node_p;   ///< pass 2: nodal pressure p_a (n_nodes) Pa
  std::vector<T> f_slot;   ///< pass 3: element nodal forces in element order: slot 4 e + corner (the
                           ///< entries of model.node_elem), xyz interleaved (4 n_elems x 3) N
  std::vector<T> f;        ///< pass 4: internal nodal force minus the applied load (3 x n_nodes) N
  std::vector<T> load;     ///< applied load R (Backend::set_loads; 3 x n_nodes) N; empty = none
  std::vector<std::uint8_t> contact;      ///< ContactKind of each node after the last step (n_nodes)
  std::vector<signed char> contact_tool;  ///< the tool it touches, -1 none (n_nodes)
  std::vector<T> contact_normal;  ///< contact normal of pushed nodes, unit, out of the tool (3 x n_nodes)
  std::vector<T> grasp_offset;    ///< grasped nodes: position minus the tool tip when the grasp started
                                  ///< (3 x n_nodes) m
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

  /// Sizes every array for model m (and zeroes it): no load, no law history.
  template <class Model>
  void resize(const Model& m) {
    const index_t n_nodes = m.n_nodes, n_elems = m.n_elems;
    load.clear();
#define TISSUE_LAW_ZERO(kind, name, len) name.assign(len, typename LawFieldTypes<T>::kind(0));
    TISSUE_LAW_STATE_FIELDS(TISSUE_LAW_ZERO)
#undef TISSUE_LAW_ZERO
    for (auto* v : {&u, &u_prev, &u_next, &u_held, &f, &contact_normal, &grasp_offset})
      v->assign(3 * size_t(n_nodes), T(0));
    contact.assign(n_nodes, kNoContact);
    contact_tool.assign(n_nodes, -1);
    held.assign(n_nodes, 0);
    driven.assign(n_nodes, 0);
    elem_dv.assign(n_elems, T(0));
    elem_J.assign(n_elems, T(1));
    elem_F.assign(9 * size_t(n_elems), T(0));
    node_p.assign(n_nodes, T(0));
    f_slot.assign(12 * size_t(n_elems), T(0));
  }
};

}  // namespace tissue
