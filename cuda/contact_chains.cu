// The contact stage's dependent arithmetic alone, on one warp of the device
// (docs/cuda.md, "The contact stage's own chains"). A step's contact stage
// tests each surface triangle against the tools (core triangle_may_touch),
// sweeps the touching ones by lane groups (SweepLanes, cuda/contact.cuh) and
// merges each touched node's proposals (core merge_proposals_unrolled): three
// chains, one after the other. Here each part runs over and over on
// registers, every call's input depending on the last call's result, and the
// multiprocessor's clock counts the cycles per call: no memory, no kernel
// boundary, no other work on the device. What a contact stage in contact
// costs however its kernels are arranged, short of a different contact rule.
#include <cuda_runtime.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "cuda/contact.cuh"
#include "cuda/cuda_backend.hpp"
#include "cuda/device_array.hpp"
#include "cuda/launch.cuh"

namespace tissue {
namespace gpu {
namespace {

/// A 2 mm sphere-tipped probe (20 mm shaft, along +z) pressed 0.5 mm into
/// the plane z = 0 and sliding and pressing slowly (one check a step), in
/// step 1 of a four-step tick; the faces below lie in that plane, their
/// outward normal +z.
template <class T>
ContactTools<T> chain_tools() {
  ContactTools<T> t{};
  t.n_tools = 1;
  t.steps = 4;
  t.face = 1;
  ToolStep<T>& s = t.tool[0];
  s.tip0 = {T(0), T(0), T(1.5e-3)};
  s.tip1 = {T(1e-5), T(0), T(1.45e-3)};
  s.axis0 = s.axis1 = {T(0), T(0), T(1)};
  s.radius = T(2e-3);
  s.shaft = T(2e-2);
  s.substeps = 1;
  s.grasping = 0;
  s.grasp_tip = s.tip0;
  s.grasp_axis = s.axis0;
  return t;
}
inline constexpr int kChainStep = 1;

/// A triangle of the plane around the probe's axis, `edge` (m) across:
/// 1.5 mm puts its corners inside the tip sphere (node contact moves them,
/// then face contact looks again: two deepest-point searches), 8 mm outside
/// it (face contact alone).
template <class T>
struct ChainTriangle {
  Vec3<T> x[3];
};

template <class T>
ChainTriangle<T> chain_triangle(double edge) {
  const auto p = [&](double a, double b) { return Vec3<T>{T(a * edge), T(b * edge), T(0)}; };
  return {{p(-0.5, -0.3), p(0.5, -0.3), p(0.0, 0.57)}};
}

/// A node's proposals from the faces around it, within about 17 degrees of
/// one direction (0.1 mm along it): the kidney's touched nodes have six.
template <class T>
CornerContact<T> chain_proposal(int j) {
  const double a = 0.8 * j;
  return {{T(3e-5 * std::cos(a)), T(3e-5 * std::sin(a)), T(1e-4)}, 0, 0};
}

/// The merges timed: of merge_count(m) proposals, m = 0, 1, 2; the second
/// (kNodeMerge) is the kidney's touched node's.
__host__ __device__ constexpr int merge_count(int m) {
  return m == 0 ? 3 : (m == 1 ? 6 : 8);
}
inline constexpr int kNodeMerge = 1;
static_assert(merge_count(kNodeMerge) == 6);

/// What the kernel times, built on the host.
template <class T>
struct ChainInput {
  ContactTools<T> tools;
  ChainTriangle<T> small, large;
  CornerContact<T> proposals[kHeldProposals];
  int counts[3];  ///< merge_count(m), handed over at run time: the stage's merge does not know its count either
};

template <class T>
ChainInput<T> chain_input() {
  ChainInput<T> in{};
  in.tools = chain_tools<T>();
  in.small = chain_triangle<T>(1.5e-3);
  in.large = chain_triangle<T>(8e-3);
  for (int j = 0; j < kHeldProposals; ++j) in.proposals[j] = chain_proposal<T>(j);
  for (int m = 0; m < 3; ++m) in.counts[m] = merge_count(m);
  return in;
}

template <class T>
struct ChainOut {
  long long test, sweep_pushed, sweep_face, merge[3];  ///< cycles per call
  CornerContact<T> pushed[3], face[3];                 ///< the sweeps' proposals (lane 0's)
  NodeContact<T> merged[3];
  int touching[2];  ///< triangle_may_touch of the small and the large triangle
};

/// Sweeps `tri` `iters` times on the lane group of this thread, each call
/// from corners that depend (by nothing) on the last call's proposals.
template <class T>
__device__ long long time_sweep(const ContactTools<T>& tools, ChainTriangle<T> tri, int iters,
                                CornerContact<T> out[3]) {
  const StepCapsules<T> capsule{tools, kChainStep};
  const SweepLanes<T> lanes = sweep_lanes_of<T>(int(threadIdx.x % 32));
  const std::uint8_t block[3] = {0, 0, 0};
  const long long c0 = clock64();
  for (int i = 0; i < iters; ++i) {
    sweep_touching_triangle(tools, capsule, tri.x, block, out, lanes);
    tri.x[0].x += out[0].dx.x * T(1e-30);
    tri.x[1].y += out[1].dx.y * T(1e-30);
    tri.x[2].z += out[2].dx.z * T(1e-30);
  }
  return (clock64() - c0) / iters;
}

template <class T>
__global__ void contact_chains_kernel(ChainInput<T> in, int iters, ChainOut<T>* out) {
  __shared__ ContactTools<T> tools;  // where the sweep kernel reads them (copy_tools)
  const ChainTriangle<T> small = in.small, large = in.large;
  if (threadIdx.x == 0) tools = in.tools;
  __syncthreads();
  ChainOut<T> r{};
  {  // the test of a triangle
    const StepCapsules<T> capsule{tools, kChainStep};
    ChainTriangle<T> tri = small;
    int touching = 0;
    const long long c0 = clock64();
    for (int i = 0; i < iters; ++i) {  // every corner depends on the last call: nothing leaves the loop
      const bool t = triangle_may_touch(tools, capsule, tri.x);
      touching += t;
      const T nudge = t ? T(1e-30) : T(2e-30);
      tri.x[0].x += nudge;
      tri.x[1].y += nudge;
      tri.x[2].z += nudge;
    }
    r.test = (clock64() - c0) / iters;
    r.touching[0] = touching == iters;
    r.touching[1] = triangle_may_touch(tools, capsule, large.x);
  }
  r.sweep_pushed = time_sweep(tools, small, iters, r.pushed);
  r.sweep_face = time_sweep(tools, large, iters, r.face);
  CornerContact<T> p[kHeldProposals];
#pragma unroll
  for (int j = 0; j < kHeldProposals; ++j) p[j] = in.proposals[j];
  for (int m = 0; m < 3; ++m) {
    const int count = in.counts[m];
    const long long c0 = clock64();
    for (int i = 0; i < iters; ++i) {  // every proposal depends on the last call: nothing leaves the loop
      r.merged[m] = merge_proposals_unrolled<kHeldProposals, T>(count, [&](int j) { return p[j]; });
      const T nudge = r.merged[m].dx.x * T(1e-30);
#pragma unroll
      for (int j = 0; j < kHeldProposals; ++j) p[j].dx.x += nudge;
    }
    r.merge[m] = (clock64() - c0) / iters;
  }
  if (threadIdx.x == 0) *out = r;
}

template <class T>
CudaContactChains measure(int iters) {
  DeviceArray<ChainOut<T>> d(1);
  // zeroed first: the kernel's store of its result writes the members, not their padding (22 of
  // ChainOut<float>'s 216 bytes), and the copy back reads every byte
  d.fill_bytes(0, nullptr);
  const ChainInput<T> in = chain_input<T>();
  launch_blocks(1, 32, nullptr, contact_chains_kernel<T>, in, iters, d.data());
  ChainOut<T> o{};
  CUDA_CHECK(cudaMemcpy(&o, d.data(), sizeof(o), cudaMemcpyDeviceToHost));
  CudaContactChains c;
  c.clock_mhz = current_device_attribute(cudaDevAttrClockRate) / 1000.0;
  c.test_cycles = double(o.test);
  c.sweep_pushed_cycles = double(o.sweep_pushed);
  c.sweep_face_cycles = double(o.sweep_face);
  for (int m = 0; m < 3; ++m) {
    c.merge_counts[m] = merge_count(m);
    c.merge_cycles[m] = double(o.merge[m]);
    c.merged_dx[m] = norm(o.merged[m].dx);
    // the merge on the host, of the same proposals (the device's last call: every one nudged by nothing)
    const NodeContact<T> host = merge_proposals<T>(merge_count(m), [&](int j) { return in.proposals[j]; });
    c.merged_apart = std::max(c.merged_apart, double(norm(o.merged[m].dx - host.dx)));
  }
  c.touching = o.touching[0] != 0 && o.touching[1] != 0;
  // a step's stage in contact runs its three chains one after the other
  c.chain_per_step_us = (c.test_cycles + c.sweep_pushed_cycles + c.merge_cycles[kNodeMerge]) / c.clock_mhz;
  // the sweeps' corrections against core's sweep of the same triangles on the host (one thread, in order)
  const std::uint8_t block[3] = {0, 0, 0};
  for (int s = 0; s < 2; ++s) {
    const ChainTriangle<T>& tri = s == 0 ? in.small : in.large;
    CornerContact<T> host[3];
    sweep_triangle(in.tools, kChainStep, tri.x, block, host);
    const CornerContact<T>* dev = s == 0 ? o.pushed : o.face;
    double largest = 0, apart = 0;
    for (int i = 0; i < 3; ++i) {
      largest = std::max(largest, double(norm(host[i].dx)));
      apart = std::max(apart, double(norm(dev[i].dx - host[i].dx)));
    }
    (s == 0 ? c.pushed_dx : c.face_dx) = largest;
    (s == 0 ? c.pushed_apart : c.face_apart) = apart;
  }
  return c;
}

}  // namespace
}  // namespace gpu

CudaContactChains cuda_contact_chains(Precision precision, int iters) {
  std::string why;
  if (!cuda_available(&why)) throw std::runtime_error("cuda_contact_chains: " + why);
  if (iters <= 0) throw std::invalid_argument("cuda_contact_chains: iters must be positive");
  return precision == Precision::Float ? gpu::measure<float>(iters) : gpu::measure<double>(iters);
}

}  // namespace tissue
