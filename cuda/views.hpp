// Non-owning views of the device store, passed to kernels by value. The
// arrays are owned by DeviceStore (cuda/device_store.hpp).
//
// Device layouts. Model arrays keep core/model.hpp's component-major
// layouts (coalesced per-element loads), except those kernels gather:
//   X, u, u_prev, u_next, u_held, f   one Packed3 per node (x, y, z, pad):
//                                     one 16-byte (float) or two (double)
//                                     loads per gathered corner
//   elem_dv                           pass 1's (J_e - 1) V_e, once per element
//                                     (the same for its four corners), stored
//                                     coalesced; pass 2 gathers a node's through
//                                     node_elem (4 e + a) in its stored order
//                                     (the cpu backend's layout and order).
//   f_slot                            pass 3's per (element, corner) forces in
//                                     node order: slot k holds the force of
//                                     node_elem[k], so pass 4 reads a node's
//                                     forces contiguously, in the stored order,
//                                     with no index indirection. Pass 3 writes
//                                     them through slot_of (the inverse of
//                                     node_elem). (Element order, pass 4
//                                     gathering as pass 2 does, was measured
//                                     slower: docs/cuda.md.)
#pragma once

#include <cstdint>
#include <type_traits>

#include "core/contact.hpp"
#include "core/hd.hpp"
#include "core/store.hpp"
#include "core/tet.hpp"
#include "core/vec.hpp"
#include "cuda/gradients.hpp"

namespace tissue::gpu {

/// A 3-vector padded to 4 scalars: one aligned vector load per node.
template <class T>
struct alignas(4 * sizeof(T)) Packed3 {
  T x, y, z, w;
  TISSUE_HD Vec3<T> vec() const { return {x, y, z}; }
  TISSUE_HD static Packed3 of(Vec3<T> v) { return {v.x, v.y, v.z, T(0)}; }
};

/// A store array's element on the device (core/store.hpp): one Packed3 per
/// entry for a 3-component array, else the declared type.
template <class V, int Components>
struct DeviceElement {
  using type = V;
};
template <class V>
struct DeviceElement<V, 3> {
  using type = Packed3<V>;
};
template <class T, class Kind, int Components>
using device_element_t = typename DeviceElement<Kind, Components>::type;

/// Threads per block of the packed fused passes (cuda/tled.cuh): a block
/// computes the slots of a window of nodes, one slot a thread.
inline constexpr int kPackedBlock = 128;

/// A reference position as the element passes at precision T recompute an
/// element's gradients from it: a point of the model's reference grid in
/// float (core GridPoint: 16 bytes, one load; core/tet.hpp
/// tet_shape_gradients_on_grid), its coordinates in double in double (32
/// bytes, two loads; tet_shape_gradients_from). The grid's float gradients
/// are the double coordinates' to an ulp or two where the edges are not far
/// smaller than the mesh, and the upload checks every element (docs/cuda.md,
/// "Reference positions on a grid"); in double the grid would cost accuracy.
template <class T>
using ReferencePoint = std::conditional_t<sizeof(T) == 4, GridPoint, Packed3<double>>;

template <class P>
TISSUE_HD P* moved_by(P* p, std::int64_t bytes);

/// Read-only model on the device (shapes as core/model.hpp unless noted).
template <class T>
struct ModelView {
  index_t n_nodes = 0, n_elems = 0, n_tris = 0;
  const Packed3<T>* X = nullptr;          ///< reference positions (n_nodes) m
  const index_t* elem_nodes = nullptr;    ///< (4 x n_elems)
  /// Element shape gradients and volumes, stored: (12 x n_elems) 1/m and
  /// (n_elems) m^3; both null when the passes always recompute them from
  /// X_ref (docs/cuda.md, "Element gradients"; cuda/tled.cuh recomputes).
  const T* dndx = nullptr;
  const T* volume = nullptr;
  /// Reference positions (n_nodes), kept when the passes may recompute the
  /// gradients; null when they always load them. On the model's reference
  /// grid in float (core ReferenceGrid; grid_step m a step), in double m in
  /// double (ReferencePoint).
  const ReferencePoint<T>* X_ref = nullptr;
  T grid_step = 0;
  // mu, K (n_elems) Pa, mass (n_nodes) kg, cd_A, cd_B, cd_C (the central
  // difference's constants, n_nodes each): core/store.hpp's material arrays
#define TISSUE_MATERIAL_POINTER(name, type, per, components, unit, what) \
  const device_element_t<T, typename StoreTypes<T>::type, components>* name = nullptr;
  TISSUE_MATERIAL_ARRAYS(TISSUE_MATERIAL_POINTER)
#undef TISSUE_MATERIAL_POINTER
  const index_t* node_elem_start = nullptr;  ///< (n_nodes + 1)
  const index_t* node_elem = nullptr;        ///< element * 4 + corner (nnz)
  /// The fused passes' windows over the slots (cuda/tled.cuh run_packed):
  /// window w holds the nodes whose first slot lies in [w S, (w + 1) S),
  /// S = pack_span = kPackedBlock - (most slots of a node) + 1, so that
  /// their slots span at most kPackedBlock; pack_first[w] is its first node
  /// (n_windows + 1 entries, the last n_nodes). n_windows 0 and pack_span 0
  /// when a node has more than kPackedBlock slots.
  const index_t* pack_first = nullptr;
  index_t n_windows = 0, pack_span = 0;
  /// Regions of at least this many nodes run the chained node passes (2
  /// and 4) with two of a node's lanes a thread (cuda/tled.cuh
  /// nodal_pressure_lanes_kernel, node_update_kernel with L = 2): where the
  /// kNodeLanes threads a node take two waves or more of the device's
  /// resident threads (DeviceStore::upload; docs/cuda.md, "Node passes with
  /// two lanes a thread").
  index_t lanes_node_min = 0;
  /// Pass 4 over the whole mesh (the chained node kernel) drops the force
  /// slots' lines it has read from the L2 (cuda/tled.cuh discard_slots): set
  /// at upload where the slots exceed half the device's L2 (1M tets in
  /// float on an H100; docs/cuda.md, "Pass 4 drops the slots it has read").
  bool discard_slots = false;
  const index_t* slot_of = nullptr;       ///< position of (e, a) in node_elem (4 x n_elems, [a * n_elems + e])
  const T* node_divisor = nullptr;        ///< V_a / K_a (core nodal_pressure_divisors) (n_nodes) m^3/Pa
  const index_t* tris = nullptr;          ///< (3 x n_tris)
  const std::uint8_t* node_flags = nullptr;  ///< NodeFlag bits (n_nodes)
  index_t n_surf = 0;                     ///< surface nodes
  const index_t* surf_nodes = nullptr;    ///< (n_surf) ascending
  const index_t* surf_slot_start = nullptr;  ///< (n_surf + 1)
  const index_t* surf_slot = nullptr;     ///< each surface node's (triangle, corner) slots 3 t + k (3 n_tris)
  double dt = 0;                          ///< s
  bool ianp = true;

  /// The arrays that follow a scene's material (moduli, masses, the central
  /// difference's constants, the pressure divisors) of the scene `bytes`
  /// away in a group's arena: scenes of one mesh and one step but different
  /// materials share a group's launch, each reading its own (the mesh's
  /// arrays are read from the captured scene's copy for all).
  TISSUE_HD ModelView materials_moved(std::int64_t bytes) const {
    ModelView v = *this;
#define TISSUE_MATERIAL_MOVE(name, ...) v.name = moved_by(name, bytes);
    TISSUE_MATERIAL_ARRAYS(TISSUE_MATERIAL_MOVE)
#undef TISSUE_MATERIAL_MOVE
    v.node_divisor = moved_by(node_divisor, bytes);  // (derived from K and the volumes at upload)
    return v;
  }
};

/// The optional law terms (core/material.hpp) on the device: null when no
/// set uses them. Kept out of ModelView so that a Neo-Hookean model's
/// kernels take exactly the arguments they took before the terms existed;
/// only the law kernels and the persistent kernels receive it.
template <class T>
struct LawView {
  index_t n_visco = 0;                    ///< Prony state slots (core TissueModel::n_visco)
  int n_prony = 0;                        ///< Prony terms stored per slot (core TissueModel::n_prony)
  // one pointer per law array, generated from core/material.hpp's lists
  // (layouts there): the model's read-only, the state's writable
#define TISSUE_LAW_MODEL_POINTER(kind, name, len) const typename LawFieldTypes<T>::kind* name = nullptr;
#define TISSUE_LAW_STATE_POINTER(kind, name, len) typename LawFieldTypes<T>::kind* name = nullptr;
  TISSUE_LAW_MODEL_FIELDS(TISSUE_LAW_MODEL_POINTER)
  TISSUE_LAW_STATE_FIELDS(TISSUE_LAW_STATE_POINTER)
#undef TISSUE_LAW_MODEL_POINTER
#undef TISSUE_LAW_STATE_POINTER
  TISSUE_HD bool neo_hookean() const { return !fibre && !visco_slot; }
  /// Every law array (the model's, which follow the scene's material, and
  /// the Prony state) of the scene `bytes` away in a group's arena.
  TISSUE_HD LawView moved(std::int64_t bytes) const {
    LawView v = *this;
#define TISSUE_LAW_MOVE(kind, name, len) v.name = moved_by(name, bytes);
    TISSUE_LAW_MODEL_FIELDS(TISSUE_LAW_MOVE)
    TISSUE_LAW_STATE_FIELDS(TISSUE_LAW_MOVE)
#undef TISSUE_LAW_MOVE
    return v;
  }
};

/// The three displacement buffers of one step: pass 4 writes u_next from u
/// and u_prev; the backend then rotates the roles (prev <- u <- next <- prev).
template <class T>
struct StepBuffers {
  Packed3<T>* u_prev = nullptr;  ///< u^{n-1} (n_nodes) m
  Packed3<T>* u = nullptr;       ///< u^n (n_nodes) m
  Packed3<T>* u_next = nullptr;  ///< u^{n+1} (n_nodes) m
  TISSUE_HD StepBuffers rotated() const { return {u, u_next, u_prev}; }
  TISSUE_HD StepBuffers moved(std::int64_t bytes) const {
    return {moved_by(u_prev, bytes), moved_by(u, bytes), moved_by(u_next, bytes)};
  }
};

/// The region's active lists; a null list means the identity (whole mesh).
struct RegionView {
  const index_t* nodes = nullptr;  ///< inner and halo nodes, ascending (n_nodes)
  const index_t* elems = nullptr;  ///< computed elements, ascending (n_elems)
  index_t n_nodes = 0, n_elems = 0;
  const std::uint8_t* elem_sel = nullptr;  ///< 1 for a computed element (the mesh's n_elems); null: every one
  /// The fused passes' windows (cuda/tled.cuh run_packed; ModelView::pack_first):
  /// pack_first[w] is the first of the region's nodes (an index into its
  /// list) whose first slot lies in window w or later (n_windows + 1
  /// entries); packs lists the n_packs windows holding any of its nodes
  /// (null: every window, the whole mesh). n_packs 0: no windows (a node
  /// has more than kPackedBlock slots), the passes run apart.
  const index_t* pack_first = nullptr;
  const index_t* packs = nullptr;
  index_t n_packs = 0;
  TISSUE_HD index_t node(index_t i) const { return nodes ? nodes[i] : i; }
  TISSUE_HD index_t elem(index_t i) const { return elems ? elems[i] : i; }
};

/// Lanes that share one node in passes 2 and 4: lane j of a node's group
/// sums the node's slots begin + j, begin + j + kNodeLanes, ... (adjacent
/// lanes read adjacent force slots in pass 4, adjacent node_elem entries
/// in pass 2, which then gathers elem_dv), then the group adds its partial sums
/// pairwise. A node of the kidney touches up to ~60 elements: one thread per
/// node would wait on ~60 / 8 rounds of dependent loads, eight lanes on one.
inline constexpr int kNodeLanes = 8;

/// Whether the element passes over region r recompute the gradients
/// (ModelView::dndx): always when none are stored, never when no reference
/// positions are kept, else for regions of at least
/// kRecomputeMinElements elements.
template <class T>
TISSUE_HD bool recomputes(const ModelView<T>& m, const RegionView& r) {
  return !m.dndx || (m.X_ref && r.n_elems >= kRecomputeMinElements);
}

/// Where a launch over a group's scenes finds each scene's arrays
/// (cuda/scene_group.hpp). Such a launch has gridDim.y scenes, block row y
/// working on slot y. Every per-scene array of a group's scene lies at the
/// same offset of its slot of the group's SceneArena, so slot y's arrays
/// are those of the slot the launch was captured from (`captured`) moved by
/// (y - captured) slots; the group's own per-scene entries (the tools'
/// motion, the skip flags) are arrays of one entry a slot. A launch of one
/// scene (gridDim.y 1) moves nothing.
struct SceneSlots {
  int captured = 0;             ///< the slot whose pointers the launch holds
  std::int64_t stride = 0;      ///< bytes from one slot of the arena to the next
  std::int64_t tools_size = 0;  ///< bytes of one slot's entry of the group's tools array
};

#ifdef __CUDACC__
/// Slots from the captured scene to this block's (0 in a launch of one scene).
__device__ __forceinline__ std::int64_t slots_moved(const SceneSlots& g) {
  return gridDim.y > 1 ? std::int64_t(blockIdx.y) - g.captured : 0;
}
#endif

/// p moved by `bytes` (null stays null).
template <class P>
TISSUE_HD P* moved_by(P* p, std::int64_t bytes) {
  using Byte = std::conditional_t<std::is_const_v<P>, const char, char>;
  return p ? reinterpret_cast<P*>(reinterpret_cast<Byte*>(p) + bytes) : p;
}

/// Mutable per-step state on the device (shapes as core/state.hpp, layouts
/// as described at the top of this file). Pointers are deliberately not
/// __restrict__/read-only: persistent kernels read what other blocks wrote.
template <class T>
struct StateView {
  // One pointer per state array the device holds (core/store.hpp:
  // TISSUE_STATE_ARRAYS, TISSUE_PASS_ARRAYS, TISSUE_DEVICE_STATE_ARRAYS),
  // a Packed3 per entry for vectors: u_held, held, driven, f_slot (per
  // node_elem slot), f, contact, contact_tool, contact_normal, grasp_offset;
  // elem_dv, elem_J, node_p (the pass arrays: one of the store's two sets);
  // role, bad (the lowest bad element key, see bad_key; ~0 = none),
  // corner_dx, corner_tool, corner_blocked (per triangle corner 3 t + k),
  // proposed (the gather clears it).
#define TISSUE_STATE_POINTER(name, type, per, components, init, unit, what) \
  device_element_t<T, typename StoreTypes<T>::type, components>* name = nullptr;
  TISSUE_STATE_ARRAYS(TISSUE_STATE_POINTER)
  TISSUE_PASS_ARRAYS(TISSUE_STATE_POINTER)
  TISSUE_DEVICE_STATE_ARRAYS(TISSUE_STATE_POINTER)
#undef TISSUE_STATE_POINTER
  const Packed3<T>* load = nullptr;    ///< applied load R (Backend::set_loads; n_nodes) N; null = none
  /// Set only in a tick graph that checks its region first (one int): while
  /// it is non-zero the region must grow before this tick, and the step and
  /// reduction kernels do nothing. In a group's tick, the group's flag of
  /// this scene: non-zero when the scene does not take part. Null: they
  /// always run.
  const int* skip = nullptr;
  SceneSlots slots;  ///< a group's launch: where the other scenes' arrays lie

  /// This view for the scene `d` slots on (skip: `d` flags on).
  TISSUE_HD StateView moved(std::int64_t d) const {
    StateView v = *this;
    const std::int64_t b = d * slots.stride;
#define TISSUE_STATE_MOVE(name, ...) v.name = moved_by(name, b);
    TISSUE_STATE_ARRAYS(TISSUE_STATE_MOVE)
    TISSUE_PASS_ARRAYS(TISSUE_STATE_MOVE)
    TISSUE_DEVICE_STATE_ARRAYS(TISSUE_STATE_MOVE)
#undef TISSUE_STATE_MOVE
    v.load = moved_by(load, b);
    v.skip = skip ? skip + d : skip;
    return v;
  }
  /// A slot's array of this scene `d` slots on.
  template <class P>
  TISSUE_HD P* slot_moved(P* p, std::int64_t d) const {
    return moved_by(p, d * slots.stride);
  }
  /// The tools' motion of the scene `d` slots on (the group's array of one entry a slot).
  TISSUE_HD const ContactTools<T>* tools_moved(const ContactTools<T>* t, std::int64_t d) const {
    return moved_by(t, d * slots.tools_size);
  }
};

}  // namespace tissue::gpu
