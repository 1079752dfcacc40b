#include "cuda/contact.hpp"

#include <cub/device/device_select.cuh>

#include <algorithm>

#include "cuda/contact.cuh"
#include "cuda/launch.cuh"

namespace tissue::gpu {
namespace {

template <class T>
__global__ void begin_grasp_kernel(ModelView<T> m, StateView<T> s, const Packed3<T>* u, int tool, Vec3<T> tip) {
  const index_t i = thread_index();
  if (i >= m.n_surf) return;
  const index_t a = m.surf_nodes[i];
  if (s.contact[a] != kPushed || s.contact_tool[a] != tool) return;
  s.contact[a] = kGrasped;
  s.grasp_offset[a] = Packed3<T>::of(m.X[a].vec() + u[a].vec() - tip);
}

template <class T>
__global__ void end_grasp_kernel(ModelView<T> m, StateView<T> s, int tool) {
  const index_t i = thread_index();
  if (i >= m.n_surf) return;
  const index_t a = m.surf_nodes[i];
  if (s.contact[a] != kGrasped || s.contact_tool[a] != tool) return;
  s.contact[a] = kNoContact;
  s.contact_tool[a] = -1;
}

template <class T>
__global__ void reset_contacts_kernel(ModelView<T> m, StateView<T> s) {
  const index_t i = thread_index();
  if (i >= m.n_surf) return;
  const index_t a = m.surf_nodes[i];
  s.contact[a] = kNoContact;
  s.contact_tool[a] = -1;
}

/// Whether a surface triangle (its model part tm, its corners' state cs at
/// the current u) has a corner that is not an inner region node and comes
/// within 1.5 radii of a sub-check capsule of the sweep.
template <class T>
__device__ bool reaches_outside(const StateView<T>& s, const ContactTools<T>& sweep, const TriangleModel<T>& tm,
                                const CornerState<T>& cs) {
  if (cs.role[0] == kInner && cs.role[1] == kInner && cs.role[2] == kInner) return false;
  Vec3<T> x[3];
#pragma unroll
  for (int i = 0; i < 3; ++i) x[i] = sweep_position(sweep, 0, s, tm, cs, i);
  return triangle_near_tools(sweep, x);
}

/// Flags the non-inner corners of triangles within 1.5 radii of a sub-check capsule.
template <class T>
__global__ void flag_candidates_kernel(ModelView<T> m, StateView<T> s, const Packed3<T>* u, ContactTools<T> sweep,
                                       std::uint8_t* flag) {
  const index_t t = thread_index();
  if (t >= m.n_tris) return;
  const TriangleModel<T> tm = load_triangle(m, t);
  const CornerState<T> cs = load_corner_state(s, tm, u);
  if (!reaches_outside(s, sweep, tm, cs)) return;
  for (int i = 0; i < 3; ++i)
    if (cs.role[i] != kInner) flag[tm.c[i]] = 1;
}

/// Sets *reach when any triangle has a candidate (flag_candidates_kernel's
/// test) for the sweep of the advance's tools, tools as one step with their
/// sweep_substeps: the same sweep as Backend::contact_candidates'.
template <class T>
__global__ void reach_outside_kernel(ModelView<T> m, StateView<T> s, const Packed3<T>* u, const ContactTools<T>* tools,
                                     int* reach, int* host_reach) {
  // the steps' first pass may load its model meanwhile (it waits for this kernel), or run beside it
  // (element_forces_beside_check_kernel: stores nothing before this kernel has finished)
  let_next_pass_launch();
  __shared__ alignas(ContactTools<T>) unsigned char raw[sizeof(ContactTools<T>)];
  ContactTools<T>& sweep = *reinterpret_cast<ContactTools<T>*>(raw);
  // the triangle's corners and their state, loaded while the block copies the tools
  const index_t t = thread_index();
  const bool active = t < m.n_tris;
  TriangleModel<T> tm;
  CornerState<T> cs;
  if (active) {
    tm = load_triangle(m, t);
    cs = load_corner_state(s, tm, u);
  }
  static_assert(kBlock >= kMaxTools, "a thread per tool sets its substeps below");  // (launched in blocks of kBlock)
  copy_tools(tools, sweep);  // by every thread (one thread's copy was a chain of loads)
  __syncthreads();
  // then the check's own: one step, each tool's sweep_substeps
  if (threadIdx.x == 0) sweep.steps = 1;
  if (int(threadIdx.x) < sweep.n_tools) sweep.tool[threadIdx.x].substeps = __ldg(tools->sweep_substeps + threadIdx.x);
  __syncthreads();
  // the first triangle in reach also tells the host (one write over the bus)
  if (active && reaches_outside(s, sweep, tm, cs) && atomicExch(reach, 1) == 0 && host_reach) *host_reach = 1;
}

template <class T>
__global__ void gather_flags_kernel(ModelView<T> m, const std::uint8_t* flag, std::uint8_t* flag_surf) {
  const index_t i = thread_index();
  if (i < m.n_surf) flag_surf[i] = flag[m.surf_nodes[i]];
}

template <class T>
__global__ void records_kernel(ModelView<T> m, StateView<T> s, ContactRecord* out) {
  const index_t i = thread_index();
  if (i >= m.n_surf) return;
  const index_t a = m.surf_nodes[i];
  const Packed3<T> n = s.contact_normal[a];
  out[i] = {a, s.contact_tool[a], s.contact[a], {float(n.x), float(n.y), float(n.z)}};
}

}  // namespace

template <class T>
void DeviceContact<T>::allocate(index_t n_nodes, index_t n_surf) {
  if (tools_pending_) tools_copied_.sync();
  tools_pending_ = false;
  tools_.allocate(1);
  tools_host_.allocate(1);
  flag_.allocate(n_nodes);
  flag_surf_.allocate(std::max<index_t>(n_surf, 1));
  selected_.allocate(std::max<index_t>(n_surf, 1));
  n_selected_.allocate(1);
  n_selected_host_.allocate(1);
  records_.allocate(std::max<index_t>(n_surf, 1));
  reach_.allocate(1);
  reach_host_.allocate(1);
  // the kernel writes the fields, not the padding between them: zero it once so that the copy to the
  // host reads no uninitialised byte (compute-sanitizer initcheck)
  CUDA_CHECK(cudaMemset(records_.data(), 0, records_.bytes()));
  size_t bytes = 0;
  CUDA_CHECK(cub::DeviceSelect::Flagged(nullptr, bytes, selected_.data(), flag_surf_.data(), selected_.data(),
                                        n_selected_.data(), std::max<index_t>(n_surf, 1)));
  cub_temp_.allocate(std::max<size_t>(bytes, 1));
}

template <class T>
std::size_t DeviceContact<T>::stage(const ContactTools<T>& tools) {
  if (tools_pending_) tools_copied_.sync();  // the staging is free again
  tools_host_[0] = tools;
  // only the tools in use cross (the struct's head and n_tools entries)
  return offsetof(ContactTools<T>, tool) + sizeof(ToolStep<T>) * size_t(tools.n_tools);
}

template <class T>
void DeviceContact<T>::enqueue_copy(std::size_t bytes, cudaStream_t stream) {
  CUDA_CHECK(cudaMemcpyAsync(tools_.data(), tools_host_.data(), bytes, cudaMemcpyHostToDevice, stream));
}

template <class T>
const ContactTools<T>* DeviceContact<T>::upload(const ContactTools<T>& tools, Transfers& log, cudaStream_t stream) {
  const std::size_t bytes = stage(tools);
  log.to_device(tools_.data(), tools_host_.data(), bytes, stream);
  tools_copied_.record(stream);
  tools_pending_ = true;
  return tools_.data();
}

template <class T>
void DeviceContact<T>::begin_grasp(const ModelView<T>& m, const StateView<T>& s, const Packed3<T>* u, int tool,
                                   Vec3<double> tip, cudaStream_t stream) {
  launch(m.n_surf, stream, begin_grasp_kernel<T>, m, s, u, tool, Vec3<T>{T(tip.x), T(tip.y), T(tip.z)});
}

template <class T>
void DeviceContact<T>::end_grasp(const ModelView<T>& m, const StateView<T>& s, int tool, cudaStream_t stream) {
  launch(m.n_surf, stream, end_grasp_kernel<T>, m, s, tool);
}

template <class T>
void DeviceContact<T>::reset(const ModelView<T>& m, const StateView<T>& s, cudaStream_t stream) {
  launch(m.n_surf, stream, reset_contacts_kernel<T>, m, s);
}

template <class T>
std::vector<index_t> DeviceContact<T>::candidates(const ModelView<T>& m, const StateView<T>& s, const Packed3<T>* u,
                                                  const ContactTools<T>& sweep, Transfers& log, cudaStream_t stream) {
  if (m.n_surf == 0) return {};
  flag_.fill_bytes(0, stream);
  launch(m.n_tris, stream, flag_candidates_kernel<T>, m, s, u, sweep, flag_.data());
  launch(m.n_surf, stream, gather_flags_kernel<T>, m, static_cast<const std::uint8_t*>(flag_.data()),
         flag_surf_.data());
  size_t bytes = cub_temp_.bytes();
  CUDA_CHECK(cub::DeviceSelect::Flagged(cub_temp_.data(), bytes, m.surf_nodes, flag_surf_.data(), selected_.data(),
                                        n_selected_.data(), m.n_surf, stream));
  log.to_host(n_selected_host_.data(), n_selected_.data(), sizeof(int), stream);
  const int count = n_selected_host_[0];
  std::vector<index_t> out(count);
  if (count > 0) log.to_host(out.data(), selected_.data(), sizeof(index_t) * size_t(count), stream);
  return out;  // surf_nodes is ascending and Flagged keeps the order
}

template <class T>
void DeviceContact<T>::enqueue_reach_check(const ModelView<T>& m, const StateView<T>& s, const Packed3<T>* u,
                                           cudaStream_t stream) {
  CUDA_CHECK(cudaMemsetAsync(reach_.data(), 0, sizeof(int), stream));
  // a plain launch, not a chained one: the first pass 3 of a checked tick reads u and the pressures
  // before it waits for this kernel (element_forces_beside_check_kernel), which is safe only while
  // everything queued before the check has finished when the check starts
  launch(m.n_tris, stream, reach_outside_kernel<T>, m, s, u, static_cast<const ContactTools<T>*>(tools_.data()),
         reach_.data(), reach_host_.device());
}

template <class T>
std::vector<ContactNode> DeviceContact<T>::contacts(const ModelView<T>& m, const StateView<T>& s, Transfers& log,
                                                    cudaStream_t stream) {
  if (m.n_surf == 0) return {};
  launch(m.n_surf, stream, records_kernel<T>, m, s, records_.data());
  std::vector<ContactRecord> all(m.n_surf);
  log.to_host(all.data(), records_.data(), sizeof(ContactRecord) * all.size(), stream);
  std::vector<ContactNode> out;
  for (const ContactRecord& r : all)
    if (r.kind != kNoContact)
      out.push_back({r.node, r.tool, r.kind,
                     r.kind == kPushed ? Vec3<double>{r.normal[0], r.normal[1], r.normal[2]} : Vec3<double>{}});
  return out;
}

template class DeviceContact<float>;
template class DeviceContact<double>;

}  // namespace tissue::gpu
