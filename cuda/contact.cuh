// The contact stage of a TLED step on the device (core/contact.hpp's rule,
// docs/contact.md): one thread per surface triangle sweeps it along the
// tools' motion in the step (core sweep_triangle) and writes its three
// corner proposals; then one thread per surface node merges its triangles'
// proposals in ascending slot order (core merge_corner, the cpu backend's
// order), moves the node in u_next (and its velocity, in u) and records
// its contact. Grasped nodes
// follow their tool. Device functions for the per-step kernels and the
// persistent kernels of cuda/tled.cuh; nvcc only.
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

/// A corner's position for the sweep of step k: grasped nodes at their
/// tool, the others at X + u_next.
template <class T>
__device__ __forceinline__ Vec3<T> sweep_position(const ModelView<T>& m, const StateView<T>& s,
                                                  const ContactTools<T>& tools, int k, const Packed3<T>* u_next,
                                                  index_t a) {
  if (s.contact[a] == kGrasped) return grasped_target(tools, k, s, a);
  return m.X[a].vec() + u_next[a].vec();
}

/// Sweeps surface triangle t in step k; writes its corner slots 3 t + i.
/// Every corner's state is loaded before any is used (grasped or not), so
/// the loads go out together: two round trips to memory (the corners, then
/// their state) before the sweep's arithmetic instead of three.
template <class T>
__device__ void sweep_triangle_at(const ModelView<T>& m, const StateView<T>& s, const ContactTools<T>& tools, int k,
                                  const Packed3<T>* u_next, index_t t) {
  index_t c[3];
#pragma unroll
  for (int i = 0; i < 3; ++i) c[i] = m.tris[i * m.n_tris + t];
  std::uint8_t contact[3], role[3], held[3];
  Vec3<T> free[3];
#pragma unroll
  for (int i = 0; i < 3; ++i) {
    const index_t a = c[i];
    contact[i] = s.contact[a];
    role[i] = s.role[a];
    held[i] = s.held[a];
    free[i] = m.X[a].vec() + u_next[a].vec();
  }
  Vec3<T> x[3];
  std::uint8_t block[3];
#pragma unroll
  for (int i = 0; i < 3; ++i) {
    x[i] = contact[i] == kGrasped ? grasped_target(tools, k, s, c[i]) : free[i];  // sweep_position's rule
    block[i] = corner_block(role[i] == kInner, held[i] == kAllAxes, contact[i] == kGrasped);
  }
  CornerContact<T> out[3];
  sweep_triangle(tools, k, x, block, out);
#pragma unroll
  for (int i = 0; i < 3; ++i) {
    s.corner_dx[3 * t + i] = Packed3<T>::of(out[i].dx);
    s.corner_tool[3 * t + i] = out[i].tool;
    s.corner_blocked[3 * t + i] = out[i].blocked;
    // any non-zero component (a superset of merge_corner's |dx|^2 > 0); several
    // triangles may store the same 1, so no atomics are needed
    if (out[i].blocked || out[i].dx.x != T(0) || out[i].dx.y != T(0) || out[i].dx.z != T(0)) s.proposed[c[i]] = 1;
  }
}

/// Proposals of one surface node (its surface triangles) that the gather
/// holds in registers; a node with more merges them from memory.
inline constexpr int kHeldProposals = 12;

/// Merges surface node i's proposals (ascending slots) and applies them to
/// u_next, and to u (u^n) the contact's velocity rule (core
/// contact_previous); grasped nodes go to their tool. A node for which no
/// triangle proposed anything (s.proposed; almost every node, every step)
/// does not read its slots: merging only zero proposals gives no contact.
/// (With a tool set and not touching the kidney, the contact stage went from
/// 10.9 to 6.7 us per step on an H100.)
template <class T>
__device__ void gather_contact_at(const ModelView<T>& m, const StateView<T>& s, const ContactTools<T>& tools, int k,
                                  Packed3<T>* u, Packed3<T>* u_next, index_t i) {
  // what depends only on i, then everything of node a, loaded before the first store: the chain is
  // the node, its state, its slots, its proposals (four round trips to memory; loads after a store
  // would wait for it, as the compiler cannot tell the arrays apart)
  const index_t a = m.surf_nodes[i];
  const index_t first = m.surf_slot_start[i];
  const int count = int(m.surf_slot_start[i + 1] - first);
  const bool proposed = s.proposed[a] != 0;
  const std::uint8_t was = s.contact[a], held = s.held[a];
  const Vec3<T> X = m.X[a].vec(), u_now = u[a].vec(), u_free = u_next[a].vec();
  if (proposed) s.proposed[a] = 0;  // for the next step's sweep
  if (was == kGrasped) {
    u_next[a] = Packed3<T>::of(grasped_target(tools, k, s, a) - X);
    return;
  }
  if (!proposed) {  // merging only zero proposals gives no contact
    s.contact[a] = kNoContact;
    s.contact_tool[a] = -1;
    return;
  }
  const auto proposal = [&](int j) {
    const index_t slot = m.surf_slot[first + j];
    return CornerContact<T>{s.corner_dx[slot].vec(), s.corner_tool[slot], s.corner_blocked[slot]};
  };
  NodeContact<T> acc;
  if (count <= kHeldProposals) {  // every proposal read once, the loads issued together
    CornerContact<T> held_proposals[kHeldProposals];
#pragma unroll
    for (int j = 0; j < kHeldProposals; ++j)
      if (j < count) held_proposals[j] = proposal(j);
    acc = merge_proposals_unrolled<kHeldProposals, T>(count, [&](int j) { return held_proposals[j]; });
  } else {
    acc = merge_proposals<T>(count, proposal);
  }
  s.contact[a] = acc.kind;
  s.contact_tool[a] = acc.tool;
  if (acc.kind != kPushed) return;
  const Vec3<T> dx = free_part(held, acc.dx);  // a roller's held component does not move
  const Vec3<T> u1 = u_free + dx, normal = unit_or(dx, Vec3<T>{T(0), T(0), T(0)});
  u_next[a] = Packed3<T>::of(u1);
  s.contact_normal[a] = Packed3<T>::of(normal);
  const Vec3<T> w = tool_motion_at(tools.tool[acc.tool], tools.steps, k, X + u1);
  u[a] = Packed3<T>::of(contact_previous(held, u_now, u1, normal, w));
}

template <class T>
__global__ void sweep_triangles_kernel(ModelView<T> m, StateView<T> s, const ContactTools<T>* tools, int k,
                                       const Packed3<T>* u_next) {
  let_next_pass_launch();
  const index_t t = thread_index();
  wait_for_previous_pass();
  if (t < m.n_tris && !skipped(s)) sweep_triangle_at(m, s, *tools, k, u_next, t);
}

template <class T>
__global__ void gather_contacts_kernel(ModelView<T> m, StateView<T> s, const ContactTools<T>* tools, int k,
                                       Packed3<T>* u, Packed3<T>* u_next) {
  let_next_pass_launch();
  const index_t i = thread_index();
  wait_for_previous_pass();
  if (i < m.n_surf && !skipped(s)) gather_contact_at(m, s, *tools, k, u, u_next, i);
}

}  // namespace tissue::gpu
