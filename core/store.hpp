// The tissue store, declared once (docs/design.md, "The store"): every
// array of the model and of the per-step state, one line each, with what
// it is per, its type, its components, how it resets and its unit. From
// these lists come
//   - TissueModel's and TissueState's members (core/model.hpp, core/state.hpp),
//     convert(), TissueState::resize() and the upload's size check
//     (Backend::upload);
//   - the cuda backend's device arrays, their allocation and reset, the
//     StateView pointers, the slot layout a scene group checks and the
//     pointers a group's launch moves to each scene's slot
//     (cuda/device_store.*, cuda/views.hpp, cuda/cuda_backend.cu);
//   - the download (Fields), the VTU file's arrays (io/vtu_writer.cpp) and,
//     through the public field list (api/include/tissue/fields.h), the C
//     constants, the C++ Field and the Python methods.
// The optional law terms' arrays (fibre, Prony) are core/material.hpp's
// lists, which every generator above includes.
//
// A new per-node state array is one line in TISSUE_STATE_ARRAYS plus its use.
//
// Columns:
//   name        the member's name (host and device alike)
//   type        Scalar (the backend's T), Index (index_t), Mask (std::uint8_t),
//               Tool (signed char: a tool index, -1 none), Key (unsigned long long)
//   per         what the array has one entry per (Per, below)
//   components  values per entry: 1, 3 (x, y, z), 4, 9, 12
//   init        the state's value after an upload or a reset (Init, below)
//   unit        SI unit ("1": dimensionless, "": an index or a flag)
//
// Layouts (unchanged by the lists): per-node vectors on the host are
// component-major (v[c * n + i]), per-slot vectors xyz interleaved; on the
// device a 3-component array is one Packed3 (x, y, z, pad) per entry
// (cuda/views.hpp).
#pragma once

#include <cstddef>
#include <cstdint>

#include "core/hd.hpp"

namespace tissue {

/// What a store array has one entry per.
enum class Per : std::uint8_t {
  Node,            ///< n_nodes
  Element,         ///< n_elems
  Triangle,        ///< n_tris (surface triangles)
  SurfaceNode,     ///< n_surf
  Corner,          ///< 4 n_elems: an (element, corner) force slot (node_elem's entries)
  TriangleCorner,  ///< 3 n_tris: a (triangle, corner) slot 3 t + k
  NodeOffset,      ///< n_nodes + 1: CSR offsets per node
  SurfaceOffset,   ///< n_surf + 1: CSR offsets per surface node
  Scene,           ///< 1
};

/// Entries of a store array per `p` in model m (any TissueModel).
template <class Model>
std::size_t store_entries(Per p, const Model& m) {
  switch (p) {
    case Per::Node: return std::size_t(m.n_nodes);
    case Per::Element: return std::size_t(m.n_elems);
    case Per::Triangle: return std::size_t(m.n_tris);
    case Per::SurfaceNode: return std::size_t(m.n_surf);
    case Per::Corner: return 4 * std::size_t(m.n_elems);
    case Per::TriangleCorner: return 3 * std::size_t(m.n_tris);
    case Per::NodeOffset: return std::size_t(m.n_nodes) + 1;
    case Per::SurfaceOffset: return std::size_t(m.n_surf) + 1;
    case Per::Scene: return 1;
  }
  return 0;
}

inline const char* to_string(Per p) {
  switch (p) {
    case Per::Node: return "node";
    case Per::Element: return "element";
    case Per::Triangle: return "triangle";
    case Per::SurfaceNode: return "surface node";
    case Per::Corner: return "element corner";
    case Per::TriangleCorner: return "triangle corner";
    case Per::NodeOffset: return "node (+1)";
    case Per::SurfaceOffset: return "surface node (+1)";
    case Per::Scene: return "scene";
  }
  return "?";
}

/// A state array's value after an upload or a reset.
enum class Init : std::uint8_t {
  Zero,       ///< 0 (kNoContact, kOutside, not driven, nothing proposed)
  One,        ///< 1 (J of an undeformed element)
  NoTool,     ///< -1: no tool
  FixedAxes,  ///< the node's fixed axes (fixed_axes of its flags): held where the scene holds it
  Inner,      ///< kInner: every node computed (the whole mesh)
  NoBad,      ///< every bit set: no bad element found
};

/// The element type of a store array of type `kind` for scalar T.
template <class T>
struct StoreTypes {
  using Scalar = T;
  using Index = index_t;
  using Mask = std::uint8_t;
  using Tool = signed char;
  using Key = unsigned long long;
};

// ---- the model (read-only after build_model) --------------------------------
// ARRAY(name, type, per, components, unit, what)

/// The mesh: its geometry and connectivity, alike in every scene of one mesh
/// (a scene group reads one copy of them for all its scenes).
#define TISSUE_MESH_ARRAYS(ARRAY)                                                                                        \
  ARRAY(X, Scalar, Node, 3, "m", "reference positions")                                                                   \
  ARRAY(elem_nodes, Index, Element, 4, "", "corner node ids, elem_nodes[a * n_elems + e]")                                \
  ARRAY(dndx, Scalar, Element, 12, "1/m", "shape gradients dN_a/dX_j, dndx[(3 a + j) * n_elems + e]")                   \
  ARRAY(volume, Scalar, Element, 1, "m^3", "reference volume")                                                            \
  ARRAY(node_elem_start, Index, NodeOffset, 1, "", "CSR offsets into node_elem")                                          \
  ARRAY(node_elem, Index, Corner, 1, "", "each node's incident (element * 4 + corner) entries, sorted")                   \
  ARRAY(elem_slot, Index, Element, 4, "", "position in node_elem of each (corner, element), [a * n_elems + e]")           \
  ARRAY(tris, Index, Triangle, 3, "", "outward surface triangles")                                                        \
  ARRAY(tri_elem, Index, Triangle, 1, "", "the tet owning each surface triangle")                                         \
  ARRAY(surf_nodes, Index, SurfaceNode, 1, "", "surface nodes, ascending")                                                \
  ARRAY(surf_slot_start, Index, SurfaceOffset, 1, "", "CSR offsets into surf_slot per surface node")                      \
  ARRAY(surf_slot, Index, TriangleCorner, 1, "", "each surface node's (triangle, corner) slots 3 t + k, ascending")       \
  ARRAY(node_flags, Mask, Node, 1, "", "NodeFlag bits (fixed, surface, fixed axes)")

/// What follows a scene's material: scenes of one mesh but different
/// materials each read their own (a scene group moves these to each
/// scene's slot: cuda/views.hpp ModelView::materials_moved).
#define TISSUE_MATERIAL_ARRAYS(ARRAY)                                                           \
  ARRAY(mu, Scalar, Element, 1, "Pa", "shear modulus")                                          \
  ARRAY(K, Scalar, Element, 1, "Pa", "bulk modulus")                                            \
  ARRAY(mass, Scalar, Node, 1, "kg", "lumped nodal mass (with mass scaling's added mass)")      \
  ARRAY(cd_A, Scalar, Node, 1, "s^2/kg", "central difference: u' = A (R - f) + B u + C u_prev") \
  ARRAY(cd_B, Scalar, Node, 1, "1", "central difference's B")                                   \
  ARRAY(cd_C, Scalar, Node, 1, "1", "central difference's C")

/// Every model array of fixed shape (the law terms' arrays, whose lengths
/// follow their terms, are core/material.hpp's TISSUE_LAW_MODEL_FIELDS).
#define TISSUE_MODEL_ARRAYS(ARRAY) \
  TISSUE_MESH_ARRAYS(ARRAY)        \
  TISSUE_MATERIAL_ARRAYS(ARRAY)

// ---- the state (per step) ---------------------------------------------------
// ARRAY(name, type, per, components, init, unit, what)

/// Held on the host and the device alike.
#define TISSUE_STATE_ARRAYS(ARRAY)                                                                                       \
  ARRAY(u_held, Scalar, Node, 3, Zero, "m", "target of held nodes: fixed, tool-driven, halo")                             \
  ARRAY(held, Mask, Node, 1, FixedAxes, "", "axis mask: bit c = component c set from u_held, not integrated")            \
  ARRAY(driven, Mask, Node, 1, Zero, "", "axis mask of the components a tool drives; 0 = not driven")                     \
  ARRAY(f_slot, Scalar, Corner, 3, Zero, "N", "pass 3: element corner forces, one per node_elem entry")                   \
  ARRAY(f, Scalar, Node, 3, Zero, "N", "pass 4: internal nodal force minus the applied load")                            \
  ARRAY(contact, Mask, Node, 1, Zero, "", "ContactKind of each node after the last step")                                 \
  ARRAY(contact_tool, Tool, Node, 1, NoTool, "", "the tool a node touches, -1 none")                                      \
  ARRAY(contact_normal, Scalar, Node, 3, Zero, "1", "contact normal of pushed nodes, unit, out of the tool")             \
  ARRAY(grasp_offset, Scalar, Node, 3, Zero, "m", "grasped nodes: position minus the tool tip when the grasp started")

/// The pass arrays of passes 1-2: on the host and the device, where they
/// come in two sets (the state's and a scratch set into which the
/// reduction computes the strain energy: cuda/device_store.hpp
/// pressure_scratch).
#define TISSUE_PASS_ARRAYS(ARRAY)                                                          \
  ARRAY(elem_dv, Scalar, Element, 1, Zero, "m^3", "pass 1: volume change (J_e - 1) V_e") \
  ARRAY(elem_J, Scalar, Element, 1, One, "1", "pass 1: J_e = det F")                      \
  ARRAY(node_p, Scalar, Node, 1, Zero, "Pa", "pass 2: IANP nodal pressure p_a")

/// Held on the host only: the displacements (the device keeps them as a
/// ring of three rotating buffers, cuda/device_store.hpp BufferRing, and
/// float's carried bits in their spare fourth lane, cuda/tled.cuh
/// pack_carry) and the host passes' F (the device's pass 3 recomputes it).
#define TISSUE_HOST_STATE_ARRAYS(ARRAY)                                                       \
  ARRAY(u, Scalar, Node, 3, Zero, "m", "displacement u^n")                                    \
  ARRAY(u_prev, Scalar, Node, 3, Zero, "m", "u^(n-1)")                                        \
  ARRAY(u_next, Scalar, Node, 3, Zero, "m", "u^(n+1), written by pass 4")                     \
  ARRAY(u_carry, Scalar, Node, 3, Zero, "m", "float: the low bits u^(n+1) lost to rounding")  \
  ARRAY(elem_F, Scalar, Element, 9, Zero, "1", "pass 1: deformation gradient F, k = 3 i + j")

/// Held on the device only (the cpu's contact stage and region keep their
/// own forms of these: cpu/contact.hpp, core/region.hpp).
#define TISSUE_DEVICE_STATE_ARRAYS(ARRAY)                                                                           \
  ARRAY(role, Mask, Node, 1, Inner, "", "NodeRole in the region")                                                   \
  ARRAY(bad, Key, Scene, 1, NoBad, "", "the lowest bad element's key (cuda/tled.cuh bad_key), ~0 = none")          \
  ARRAY(corner_dx, Scalar, TriangleCorner, 3, Zero, "m", "the contact sweep's correction per triangle corner")     \
  ARRAY(corner_tool, Tool, TriangleCorner, 1, NoTool, "", "its tool, -1 none")                                      \
  ARRAY(corner_blocked, Mask, TriangleCorner, 1, Zero, "", "ContactKind of a blocked penetration, 0 none")          \
  ARRAY(proposed, Mask, Node, 1, Zero, "", "1: a triangle proposed a correction or a block for the node this step")

// ---- the output -------------------------------------------------------------
// The state arrays a download carries (Fields, core/backend.hpp), in
// double whatever the backend's T, and that the VTU file writes, under
// these names. ARRAY(name, vtu name, public Field, per, components, unit)
#define TISSUE_OUTPUT_ARRAYS(ARRAY)                                              \
  ARRAY(u, "displacement", Displacement, Node, 3, "m")                           \
  ARRAY(node_p, "nodal_pressure", Pressure, Node, 1, "Pa")                       \
  ARRAY(f, "internal_force", InternalForce, Node, 3, "N")                        \
  ARRAY(elem_J, "J", Jacobian, Element, 1, "1")

}  // namespace tissue
