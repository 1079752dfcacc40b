// The contact stage of a TLED step on the device (core/contact.hpp's rule,
// docs/contact.md): one thread per surface triangle sweeps it along the
// tools' motion in the step (core sweep_triangle) and stores the corner
// proposals it has (most triangles have none); then one thread per surface
// node merges its triangles' proposals in ascending slot order (core
// merge_corner, the cpu backend's order), moves the node in u_next (and its
// velocity, in u), records its contact and clears the proposals it read.
// Grasped nodes follow their tool. Device functions for the per-step
// kernels and the persistent kernels of cuda/tled.cuh; nvcc only.
#pragma once

#include "core/contact.hpp"
#include "core/node_rules.hpp"
#include "cuda/launch.cuh"
#include "cuda/views.hpp"

namespace tissue::gpu {

/// Whether the kernels of a checked tick must do nothing (StateView::skip);
/// read after the previous kernel has finished.
template <class T>
__device__ __forceinline__ bool skipped(const StateView<T>& s) {
  return s.skip != nullptr && *s.skip != 0;
}

/// Where grasped node a goes at the end of step k (its tool's pose then).
template <class T>
__device__ __forceinline__ Vec3<T> grasped_target(const ContactTools<T>& tools, int k, const StateView<T>& s,
                                                  index_t a) {
  const ToolStep<T>& tool = tools.tool[s.contact_tool[a]];
  Vec3<T> tip, axis;
  interpolate_pose(tool.tip0, tool.axis0, tool.tip1, tool.axis1, T(k + 1) / T(tools.steps), tip, axis);
  return grasped_position(tip, axis, tool.grasp_axis, s.grasp_offset[a].vec());
}

/// What the sweep of a triangle (and the region's reach check) reads from
/// the model: its corners and their reference positions (the kernels load
/// them before they wait for the previous one, like the passes' model data).
template <class T>
struct TriangleModel {
  index_t c[3];
  Vec3<T> X[3];
};

template <class T>
__device__ __forceinline__ TriangleModel<T> load_triangle(const ModelView<T>& m, index_t t) {
  TriangleModel<T> tm;
#pragma unroll
  for (int i = 0; i < 3; ++i) tm.c[i] = __ldg(m.tris + i * m.n_tris + t);
#pragma unroll
  for (int i = 0; i < 3; ++i) tm.X[i] = m.X[tm.c[i]].vec();
  return tm;
}

/// The state of a triangle's corners that a sweep reads, loaded together
/// before any of it is used (grasped or not): one round trip to memory.
template <class T>
struct CornerState {
  std::uint8_t contact[3], role[3], held[3];
  Vec3<T> free[3];  ///< X + u: where a corner that is not grasped is
};

template <class T>
__device__ __forceinline__ CornerState<T> load_corner_state(const StateView<T>& s, const TriangleModel<T>& tm,
                                                            const Packed3<T>* u) {
  CornerState<T> cs;
#pragma unroll
  for (int i = 0; i < 3; ++i) {
    const index_t a = tm.c[i];
    cs.contact[i] = s.contact[a];
    cs.role[i] = s.role[a];
    cs.held[i] = s.held[a];
    cs.free[i] = tm.X[i] + u[a].vec();
  }
  return cs;
}

/// Corner i's position for the sweep of step k: a grasped corner at its
/// tool, the others at X + u.
template <class T>
__device__ __forceinline__ Vec3<T> sweep_position(const ContactTools<T>& tools, int k, const StateView<T>& s,
                                                  const TriangleModel<T>& tm, const CornerState<T>& cs, int i) {
  return cs.contact[i] == kGrasped ? grasped_target(tools, k, s, tm.c[i]) : cs.free[i];
}

/// Every slot holds no proposal between steps (core proposes: anything
/// else is a no-op for merge_corner): the sweep stores only the corners
/// that propose something, and the merge of a proposed node clears its
/// slots. Storing every slot every step cost 54 bytes a triangle (5.5 MB a
/// step on a surface of 100k triangles) for a handful of proposals.
template <class T>
__device__ __forceinline__ void clear_slot(const StateView<T>& s, index_t slot) {
  s.corner_dx[slot] = Packed3<T>::of(Vec3<T>{T(0), T(0), T(0)});
  s.corner_blocked[slot] = 0;
}

/// clear_slot over `count` slots listed at `slot` (a surface node's).
template <class T>
__device__ __forceinline__ void clear_slots(const StateView<T>& s, const index_t* slot, int count) {
  for (int j = 0; j < count; ++j) clear_slot(s, slot[j]);
}

/// Sweeps surface triangle t (its model part tm) in step k; stores the
/// proposals of its corners (slots 3 t + i) that propose anything. After
/// the previous kernel, one round trip to memory (the corners' state)
/// before the sweep's arithmetic (three before 2026-11-26: the corners,
/// their contact state, their positions).
template <class T>
__device__ void sweep_loaded_triangle(const StateView<T>& s, const ContactTools<T>& tools, int k,
                                      const Packed3<T>* u_next, index_t t, const TriangleModel<T>& tm) {
  const CornerState<T> cs = load_corner_state(s, tm, u_next);
  Vec3<T> x[3];
  std::uint8_t block[3];
#pragma unroll
  for (int i = 0; i < 3; ++i) {
    x[i] = sweep_position(tools, k, s, tm, cs, i);
    block[i] = corner_block(cs.role[i] == kInner, cs.held[i] == kAllAxes, cs.contact[i] == kGrasped);
  }
  CornerContact<T> out[3];
  sweep_triangle(tools, k, x, block, out);
#pragma unroll
  for (int i = 0; i < 3; ++i) {
    if (!proposes(out[i])) continue;  // its slot already holds none (see clear_slot)
    s.corner_dx[3 * t + i] = Packed3<T>::of(out[i].dx);
    s.corner_tool[3 * t + i] = out[i].tool;
    s.corner_blocked[3 * t + i] = out[i].blocked;
    s.proposed[tm.c[i]] = 1;  // several triangles may store the same 1: no atomics needed
  }
}

template <class T>
__device__ void sweep_triangle_at(const ModelView<T>& m, const StateView<T>& s, const ContactTools<T>& tools, int k,
                                  const Packed3<T>* u_next, index_t t) {
  sweep_loaded_triangle(s, tools, k, u_next, t, load_triangle(m, t));
}

/// Proposals of one surface node (its surface triangles) that the gather
/// holds in registers; a node with more merges them from memory.
inline constexpr int kHeldProposals = 12;

/// What the merge of surface node i reads from the model: the node, its
/// reference position and its proposal slots (the first kHeldProposals of
/// them; loaded before the kernel waits for the previous one).
template <class T>
struct SurfaceNodeModel {
  index_t a, first;
  int count;
  Vec3<T> X;
  index_t slot[kHeldProposals];
};

template <class T>
__device__ __forceinline__ SurfaceNodeModel<T> load_surface_node(const ModelView<T>& m, index_t i) {
  SurfaceNodeModel<T> n;
  n.a = __ldg(m.surf_nodes + i);
  n.first = __ldg(m.surf_slot_start + i);
  n.count = int(__ldg(m.surf_slot_start + i + 1) - n.first);
  n.X = m.X[n.a].vec();
#pragma unroll
  for (int j = 0; j < kHeldProposals; ++j) n.slot[j] = j < n.count ? __ldg(m.surf_slot + n.first + j) : index_t(0);
  return n;
}

/// Merges surface node i's proposals (ascending slots; its model part n)
/// and applies them to u_next, and to u (u^n) the contact's velocity rule
/// (core contact_previous); grasped nodes go to their tool. A node for which
/// no triangle proposed anything (s.proposed; almost every node, every
/// step) does not read its slots: merging only zero proposals gives no
/// contact. (With a tool set and not touching the kidney, the contact stage
/// went from 10.9 to 6.7 us per step on an H100.) The node's state is loaded
/// before the first store (a load after a store waits for it: the compiler
/// cannot tell the arrays apart), so after the previous kernel the chain is
/// the state, then the proposals: two round trips to memory (about seven
/// before 2026-11-26).
template <class T>
__device__ void merge_loaded_node(const StateView<T>& s, const ContactTools<T>& tools, int k, Packed3<T>* u,
                                  Packed3<T>* u_next, const SurfaceNodeModel<T>& n, const index_t* surf_slot) {
  const index_t a = n.a;
  const bool proposed = s.proposed[a] != 0;
  const std::uint8_t was = s.contact[a], held = s.held[a];
  const Vec3<T> u_now = u[a].vec(), u_free = u_next[a].vec();
  if (proposed) s.proposed[a] = 0;  // for the next step's sweep
  if (was == kGrasped) {
    u_next[a] = Packed3<T>::of(grasped_target(tools, k, s, a) - n.X);
    if (proposed) clear_slots(s, surf_slot + n.first, n.count);  // a grasped corner's block: never merged
    return;
  }
  if (!proposed) {  // merging only zero proposals gives no contact (stored only if it was in one:
    if (was != kNoContact) {  // a node in no contact has no tool, as every writer keeps it)
      s.contact[a] = kNoContact;
      s.contact_tool[a] = -1;
    }
    return;
  }
  const auto at = [&](index_t slot) {
    return CornerContact<T>{s.corner_dx[slot].vec(), s.corner_tool[slot], s.corner_blocked[slot]};
  };
  NodeContact<T> acc;
  if (n.count <= kHeldProposals) {  // every proposal read once, the loads issued together
    CornerContact<T> held_proposals[kHeldProposals];
#pragma unroll
    for (int j = 0; j < kHeldProposals; ++j)
      if (j < n.count) held_proposals[j] = at(n.slot[j]);
#pragma unroll
    for (int j = 0; j < kHeldProposals; ++j)  // cleared at once: the stores need not wait for the loads
      if (j < n.count) clear_slot(s, n.slot[j]);
    acc = merge_proposals_unrolled<kHeldProposals, T>(n.count, [&](int j) { return held_proposals[j]; });
  } else {
    acc = merge_proposals<T>(n.count, [&](int j) { return at(surf_slot[n.first + j]); });
    clear_slots(s, surf_slot + n.first, n.count);
  }
  s.contact[a] = acc.kind;
  s.contact_tool[a] = acc.tool;
  if (acc.kind != kPushed) return;
  const Vec3<T> dx = free_part(held, acc.dx);  // a roller's held component does not move
  const Vec3<T> u1 = u_free + dx, normal = unit_or(dx, Vec3<T>{T(0), T(0), T(0)});
  u_next[a] = Packed3<T>::of(u1);
  s.contact_normal[a] = Packed3<T>::of(normal);
  const Vec3<T> w = tool_motion_at(tools.tool[acc.tool], tools.steps, k, n.X + u1);
  u[a] = Packed3<T>::of(contact_previous(held, u_now, u1, normal, w));
}

template <class T>
__device__ void gather_contact_at(const ModelView<T>& m, const StateView<T>& s, const ContactTools<T>& tools, int k,
                                  Packed3<T>* u, Packed3<T>* u_next, index_t i) {
  merge_loaded_node(s, tools, k, u, u_next, load_surface_node(m, i), m.surf_slot);
}

template <class T>
__global__ void sweep_triangles_kernel(ModelView<T> m, StateView<T> s, const ContactTools<T>* tools, int k,
                                       const Packed3<T>* u_next) {
  let_next_pass_launch();
  const index_t t = thread_index();
  const bool active = t < m.n_tris;
  TriangleModel<T> tm;
  if (active) tm = load_triangle(m, t);
  wait_for_previous_pass();
  if (active && !skipped(s)) sweep_loaded_triangle(s, *tools, k, u_next, t, tm);
}

template <class T>
__global__ void gather_contacts_kernel(ModelView<T> m, StateView<T> s, const ContactTools<T>* tools, int k,
                                       Packed3<T>* u, Packed3<T>* u_next) {
  let_next_pass_launch();
  // the nodes a tool pushes are neighbours: dealt to different warps in runs of 8, their merges run side
  // by side, not one after another in one warp (docs/benchmarks/README.md, "The reduction's tail")
  const index_t i = dealt_index<8>();
  const bool active = i < m.n_surf;
  SurfaceNodeModel<T> n;
  if (active) n = load_surface_node(m, i);
  wait_for_previous_pass();
  if (active && !skipped(s)) merge_loaded_node(s, *tools, k, u, u_next, n, m.surf_slot);
}

}  // namespace tissue::gpu
