// The contact stage of a TLED step on the device (core/contact.hpp's rule,
// docs/contact.md): each thread tests one surface triangle against the
// tools (core triangle_may_touch: most are clear), then groups of lanes
// sweep the triangles that may touch along the tools' motion in the step
// (core sweep_touching_triangle, its independent parts one a lane) and
// store the corner proposals they have; then one thread per surface node
// merges its triangles' proposals in ascending slot order (core
// merge_corner, the cpu backend's order), moves the node in u_next (and its
// velocity, in u), records its contact and clears the proposals it read.
// Grasped nodes follow their tool. Device functions for the per-step
// kernels and the persistent kernels of cuda/tled.cuh; nvcc only.
#pragma once

#include <type_traits>

#include "core/contact.hpp"
#include "core/model.hpp"
#include "core/node_rules.hpp"
#include "core/region.hpp"
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

/// The role and held mask of a triangle's corners. The region build and the
/// constraints set them between advances, never a step's kernels, so the
/// sweep kernel loads them before its wait (load_corner_roles).
struct CornerRoles {
  std::uint8_t role[3], held[3];
};

/// The state of a triangle's corners that a sweep reads: their roles, and
/// what the steps change, loaded together before any of it is used
/// (grasped or not): one round trip to memory.
template <class T>
struct CornerState : CornerRoles {
  std::uint8_t contact[3];
  Vec3<T> free[3];  ///< X + u: where a corner that is not grasped is
};

template <class T>
__device__ __forceinline__ CornerRoles load_corner_roles(const StateView<T>& s, const TriangleModel<T>& tm) {
  CornerRoles r;
#pragma unroll
  for (int i = 0; i < 3; ++i) {
    r.role[i] = s.role[tm.c[i]];
    r.held[i] = s.held[tm.c[i]];
  }
  return r;
}

/// The corners' state at u, their roles already loaded.
template <class T>
__device__ __forceinline__ CornerState<T> load_corner_state(const StateView<T>& s, const TriangleModel<T>& tm,
                                                            const Packed3<T>* u, const CornerRoles& roles) {
  CornerState<T> cs;
  static_cast<CornerRoles&>(cs) = roles;
#pragma unroll
  for (int i = 0; i < 3; ++i) {
    cs.contact[i] = s.contact[tm.c[i]];
    cs.free[i] = tm.X[i] + u[tm.c[i]].vec();
  }
  return cs;
}

template <class T>
__device__ __forceinline__ CornerState<T> load_corner_state(const StateView<T>& s, const TriangleModel<T>& tm,
                                                            const Packed3<T>* u) {
  return load_corner_state(s, tm, u, load_corner_roles(s, tm));
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

/// Stores the proposals of surface triangle t's corners (slots 3 t + i,
/// corner nodes c) that propose anything.
template <class T>
__device__ __forceinline__ void store_proposals(const StateView<T>& s, index_t t, const index_t c[3],
                                                const CornerContact<T> out[3]) {
#pragma unroll
  for (int i = 0; i < 3; ++i) {
    if (!proposes(out[i])) continue;  // its slot already holds none (see clear_slot)
    s.corner_dx[3 * t + i] = Packed3<T>::of(out[i].dx);
    s.corner_tool[3 * t + i] = out[i].tool;
    s.corner_blocked[3 * t + i] = out[i].blocked;
    s.proposed[c[i]] = 1;  // several triangles may store the same 1: no atomics needed
  }
}

/// Lanes of a warp that sweep one touching triangle together: its deepest
/// point's six candidates (core deepest_candidate) one a lane, its three
/// corners' pushes (core corner_push) one a lane, each lane then taking
/// every lane's result in core's order. Every lane of the group runs the
/// rest of the sweep alike, with the same values, so its branches are the
/// group's. The same arithmetic and choices as one thread's sweep
/// (SweepInOrder): the same proposals to the rounding of a fused
/// multiply-add (cuda_tests, Sweep.LanesGiveOneThreadsProposals); every step
/// mode sweeps this way, so the modes give the same bits.
inline constexpr int kSweepLanes = 8;
static_assert(kSweepLanes >= kDeepestCandidates && 32 % kSweepLanes == 0);

template <class T>
struct SweepLanes {
  unsigned mask;  ///< the group's lanes in the warp
  int lane;       ///< this lane's number in the group

  template <class V>
  __device__ __forceinline__ V from(V v, int src) const {
    return __shfl_sync(mask, v, src, kSweepLanes);
  }
  __device__ __forceinline__ Vec3<T> from(Vec3<T> v, int src) const {
    return {from(v.x, src), from(v.y, src), from(v.z, src)};
  }

  __device__ Vec3<T> deepest(const Capsule<T>& cap, const Vec3<T> P[3], T w[3], Vec3<T>& c) const {
    const DeepestCandidate<T> mine = deepest_candidate(cap, P, lane < kDeepestCandidates ? lane : 0);
    int pick = 0;  // triangle_deepest_point's choice, made alike on every lane
    T best = from(mine.d2, 0);
#pragma unroll
    for (int k = 1; k < kDeepestCandidates; ++k) {
      const T d2 = from(mine.d2, k);
      if (deeper(from(int(mine.found), k) != 0, d2, best)) {
        best = d2;
        pick = k;
      }
    }
#pragma unroll
    for (int i = 0; i < 3; ++i) w[i] = from(mine.w[i], pick);
    c = from(mine.c, pick);
    return from(mine.q, pick);
  }

  __device__ void push_corners(const Capsule<T>& cap, const Vec3<T> x[3], bool through, Vec3<T> N,
                               CornerPush<T> push[3]) const {
    const CornerPush<T> mine = corner_push(cap, one_of_three(x, lane < 3 ? lane : 0), through, N);
#pragma unroll
    for (int j = 0; j < 3; ++j) push[j] = {from(mine.x, j), from(int(mine.inside), j) != 0};
  }
};

/// Lane `lane` (0..31) of a warp as a member of its group.
template <class T>
__device__ __forceinline__ SweepLanes<T> sweep_lanes_of(int lane) {
  return {((1u << kSweepLanes) - 1) << (lane / kSweepLanes * kSweepLanes), lane % kSweepLanes};
}

/// What a thread hands a lane group about a triangle that may touch a tool
/// (core triangle_may_touch): the triangle, its corners and sweep input.
template <class T>
struct TouchingTriangle {
  index_t t, c[3];
  Vec3<T> x[3];
  std::uint8_t block[3];
};

/// Surface triangle t's sweep input in step k (its model part tm, its
/// corners' roles) into tri: its corners' positions and blocks
/// (corner_block), from the rest of their state loaded together; whether it
/// may touch a tool.
template <class T>
__device__ __forceinline__ bool may_touch(const StateView<T>& s, const ContactTools<T>& tools,
                                          const StepCapsules<T>& capsule, const Packed3<T>* u_next, index_t t,
                                          const TriangleModel<T>& tm, const CornerRoles& roles,
                                          TouchingTriangle<T>& tri) {
  const CornerState<T> cs = load_corner_state(s, tm, u_next, roles);
  tri.t = t;
#pragma unroll
  for (int i = 0; i < 3; ++i) {
    tri.c[i] = tm.c[i];
    tri.x[i] = sweep_position(tools, capsule.k, s, tm, cs, i);
    tri.block[i] = corner_block(cs.role[i] == kInner, cs.held[i] == kAllAxes, cs.contact[i] == kGrasped);
  }
  return triangle_may_touch(tools, capsule, tri.x);
}

/// A lane group's sweep of a touching triangle; its lane 0 stores the
/// proposals. Every sweep of the cuda backend's step modes runs here, so
/// that they give the same bits.
template <class T>
__device__ __forceinline__ void sweep_in_lanes(const StateView<T>& s, const ContactTools<T>& tools,
                                               const StepCapsules<T>& capsule, const TouchingTriangle<T>& tri,
                                               const SweepLanes<T>& lanes) {
  CornerContact<T> out[3];
  sweep_touching_triangle(tools, capsule, tri.x, tri.block, out, lanes);
  if (lanes.lane == 0) store_proposals(s, tri.t, tri.c, out);
}

/// The sweep of triangles t = base + lane in step k by the 32 lanes of a
/// warp, which all call it (t past the surface: none): each lane tests its
/// triangle, then the warp's groups take its touching triangles in turn,
/// 32 / kSweepLanes at a time, handed over by shuffles. For the persistent
/// kernels, whose grid-stride loops give each warp 32 consecutive triangles.
template <class T>
__device__ void sweep_warp_triangles(const ModelView<T>& m, const StateView<T>& s, const ContactTools<T>& tools,
                                     int k, const Packed3<T>* u_next, index_t t) {
  const StepCapsules<T> capsule{tools, k};
  TouchingTriangle<T> mine{};
  bool touching = false;
  if (t < m.n_tris) {
    const TriangleModel<T> tm = load_triangle(m, t);
    touching = may_touch(s, tools, capsule, u_next, t, tm, load_corner_roles(s, tm), mine);
  }
  unsigned left = __ballot_sync(~0u, touching);
  const int lane = int(threadIdx.x % 32), group = lane / kSweepLanes;
  const SweepLanes<T> lanes = sweep_lanes_of<T>(lane);
  while (left != 0) {  // (uniform over the warp)
    unsigned rest = left;
    for (int j = 0; j < group; ++j) rest &= rest - 1;  // the earlier groups' triangles
    const int from = rest != 0 ? __ffs(int(rest)) - 1 : lane;
    TouchingTriangle<T> tri;
    tri.t = __shfl_sync(~0u, mine.t, from);
#pragma unroll
    for (int i = 0; i < 3; ++i) {
      tri.c[i] = __shfl_sync(~0u, mine.c[i], from);
      tri.x[i] = {__shfl_sync(~0u, mine.x[i].x, from), __shfl_sync(~0u, mine.x[i].y, from),
                  __shfl_sync(~0u, mine.x[i].z, from)};
      tri.block[i] = std::uint8_t(__shfl_sync(~0u, int(mine.block[i]), from));
    }
    if (rest != 0) sweep_in_lanes(s, tools, capsule, tri, lanes);
    for (int j = 0; j < 32 / kSweepLanes; ++j) left &= left - 1;
  }
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
/// the state, then the proposals: two round trips to memory.
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
  const Vec3<T> normal = unit_or(dx, Vec3<T>{T(0), T(0), T(0)});
  const ToolStep<T>& tool = tools.tool[acc.tool];
  Vec3<T> u1 = u_free + dx;
  const Vec3<T> w = tool_motion_at(tool, tools.steps, k, n.X + u1);
  u1 = coulomb_slip(held, u_now, u1, normal, w, dx, tool.friction);
  u_next[a] = Packed3<T>::of(u1);
  s.contact_normal[a] = Packed3<T>::of(normal);
  u[a] = Packed3<T>::of(contact_previous(held, u_now, u1, normal, w));
}

template <class T>
__device__ void gather_contact_at(const ModelView<T>& m, const StateView<T>& s, const ContactTools<T>& tools, int k,
                                  Packed3<T>* u, Packed3<T>* u_next, index_t i) {
  merge_loaded_node(s, tools, k, u, u_next, load_surface_node(m, i), m.surf_slot);
}

/// Copies the advance's tools into the block's shared `sh` (n_tools, steps,
/// face and the tools in use, which is all the sweep reads; not
/// sweep_substeps, which the reach check reads into each tool's substeps in
/// its copy after this one), by the block's threads, before
/// the kernel waits for the previous one; read after a __syncthreads(). The
/// tools are uploaded by a copy in the stream before the steps' first
/// kernel and do not change while they run, so the sweep need not wait for
/// the previous kernel to load them: their loads leave the chain that runs
/// after the wait (the kidney's contact stage with a tool set, not
/// touching: 3.9 -> 3.4 us a step on an H100). The merge does not copy
/// them: only a touched node reads them, and a copy in every block cost
/// the 100k slab's merge more than it saved (docs/cuda.md, "The tick
/// traced").
template <class T>
__device__ __forceinline__ void copy_tools(const ContactTools<T>* tools, ContactTools<T>& sh) {
  static_assert(sizeof(ToolStep<T>) % sizeof(int) == 0);
  const int n = min(__ldg(&tools->n_tools), kMaxTools);  // (set_tools refuses more)
  if (threadIdx.x == 0) {
    sh.n_tools = n;
    sh.steps = __ldg(&tools->steps);
    sh.face = __ldg(&tools->face);
  }
  constexpr int kWords = int(sizeof(ToolStep<T>) / sizeof(int));
  const int* from = reinterpret_cast<const int*>(tools->tool);
  int* to = reinterpret_cast<int*>(sh.tool);
  for (int w = int(threadIdx.x); w < n * kWords; w += int(blockDim.x)) to[w] = __ldg(from + w);
}

/// The sweep of step k over the surface, in blocks of kBlock threads (at
/// most: the shared list's size; whole warps): each
/// thread tests its triangle (core triangle_may_touch: most are clear of
/// every tool), then the block's triangles that may touch are swept by
/// groups of kSweepLanes lanes (SweepLanes), the groups dealt to the
/// block's warps in turn. One thread's sweep of a touching triangle was the
/// longest chain of the contact stage (docs/cuda.md). The merge
/// may launch only once this kernel's wait is over: launched as the sweep
/// started, its blocks waited on the multiprocessors beside the force
/// pass's (the kidney's ticks are 2.7-3.9 % shorter so). The triangle's corners' roles load
/// before the wait with its model part (load_corner_roles).
///
/// Its blocks of 256 are compiled to fit three an SM in float (80
/// registers, was 92: two an SM), so that a surface of 100k triangles (395
/// blocks) is tested in one wave on 132 SMs, not two (the 100k slab's
/// contact stage 10.3-10.4 -> 8.9-9.1 us a step on an H200; docs/cuda.md, "The sweep
/// in one wave"). In double (154 registers) three would spill hundreds of
/// bytes: it keeps one block an SM.
template <class T>
inline constexpr int kSweepBlocksPerSM = std::is_same_v<T, float> ? 3 : 1;

template <class T>
__global__ void __launch_bounds__(kBlock, kSweepBlocksPerSM<T>)
    sweep_triangles_kernel(ModelView<T> m, StateView<T> s, const ContactTools<T>* tools, int k,
                           const Packed3<T>* u_next) {
  if (const std::int64_t d = slots_moved(s.slots)) {  // a group's launch: this block row's scene
    tools = s.tools_moved(tools, d);
    u_next = s.slot_moved(u_next, d);
    s = s.moved(d);
  }
  __shared__ alignas(TouchingTriangle<T>) unsigned char raw[kBlock * sizeof(TouchingTriangle<T>)];
  __shared__ alignas(ContactTools<T>) unsigned char tools_raw[sizeof(ContactTools<T>)];
  __shared__ int n_touching;
  TouchingTriangle<T>* touching = reinterpret_cast<TouchingTriangle<T>*>(raw);
  ContactTools<T>& sh_tools = *reinterpret_cast<ContactTools<T>*>(tools_raw);
  const index_t t = thread_index();
  const bool active = t < m.n_tris;
  TriangleModel<T> tm;
  CornerRoles roles;
  if (active) {
    tm = load_triangle(m, t);
    roles = load_corner_roles(s, tm);
  }
  if (threadIdx.x == 0) n_touching = 0;
  copy_tools(tools, sh_tools);
  wait_for_previous_pass();
  let_next_pass_launch();
  __syncthreads();
  const StepCapsules<T> capsule{sh_tools, k};
  TouchingTriangle<T> tri;
  if (active && !skipped(s) && may_touch(s, sh_tools, capsule, u_next, t, tm, roles, tri))
    touching[atomicAdd(&n_touching, 1)] = tri;  // in any order: each triangle's sweep is its own
  __syncthreads();
  const int warps = int(blockDim.x) / 32, group = int(threadIdx.x % 32) / kSweepLanes;
  const SweepLanes<T> lanes = sweep_lanes_of<T>(int(threadIdx.x % 32));
  for (int j = group * warps + int(threadIdx.x / 32); j < n_touching; j += int(blockDim.x) / kSweepLanes)
    sweep_in_lanes(s, sh_tools, capsule, touching[j], lanes);
}

template <class T>
__global__ void gather_contacts_kernel(ModelView<T> m, StateView<T> s, const ContactTools<T>* tools, int k,
                                       Packed3<T>* u, Packed3<T>* u_next) {
  if (const std::int64_t d = slots_moved(s.slots)) {  // a group's launch: this block row's scene
    tools = s.tools_moved(tools, d);
    u = s.slot_moved(u, d);
    u_next = s.slot_moved(u_next, d);
    s = s.moved(d);
  }
  // the nodes a tool pushes are neighbours: dealt to different warps in runs of 8, their merges run side
  // by side, not one after another in one warp (docs/benchmarks/README.md, "The reduction's tail")
  const index_t i = dealt_index<8>();
  const bool active = i < m.n_surf;
  SurfaceNodeModel<T> n;
  if (active) n = load_surface_node(m, i);
  wait_for_previous_pass();
  // the next kernel (the next step's pressure pass, or the reduction's) launches only now: launched as the
  // merge starts, its blocks and those of the kernels it lets launch waited on the multiprocessors through
  // the sweep (docs/cuda.md, "Fused passes packed by windows")
  let_next_pass_launch();
  if (active && !skipped(s)) merge_loaded_node(s, *tools, k, u, u_next, n, m.surf_slot);
}

}  // namespace tissue::gpu
