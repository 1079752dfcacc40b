#include "cuda/contact.hpp"

#include <cub/device/device_select.cuh>

#include <algorithm>

#include "cuda/block_sum.cuh"
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

/// Flags the non-inner corners of triangles within 1.5 radii of a sub-check capsule.
template <class T>
__global__ void flag_candidates_kernel(ModelView<T> m, StateView<T> s, const Packed3<T>* u, ContactTools<T> sweep,
                                       std::uint8_t* flag) {
  const index_t t = thread_index();
  if (t >= m.n_tris) return;
  index_t c[3];
  Vec3<T> x[3];
  bool all_inner = true;
  for (int i = 0; i < 3; ++i) {
    c[i] = m.tris[i * m.n_tris + t];
    x[i] = sweep_position(m, s, sweep, 0, u, c[i]);
    all_inner = all_inner && s.role[c[i]] == kInner;
  }
  if (all_inner) return;
  if (!triangle_near_tools(sweep, x)) return;
  for (int i = 0; i < 3; ++i)
    if (s.role[c[i]] != kInner) flag[c[i]] = 1;
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

/// Threads of a contact-reduction block (a multiple of 32, at most 32 warps).
constexpr int kContactBlock = 256;
constexpr int kContactWarps = kContactBlock / 32;

__device__ void combine(ContactPartial& a, const ContactPartial& b) {
  for (int t = 0; t < kMaxTools; ++t) {
    for (int c = 0; c < 3; ++c) a.reaction[t][c] += b.reaction[t][c];
    a.contact[t] += b.contact[t];
    a.grasped[t] += b.grasped[t];
    a.rigid[t] += b.rigid[t];
    a.outside[t] += b.outside[t];
    if (b.rigid_first[t] >= 0 && (a.rigid_first[t] < 0 || b.rigid_first[t] < a.rigid_first[t]))
      a.rigid_first[t] = b.rigid_first[t];
  }
}

/// Surface nodes one block of contact_partials_kernel reduces: a fixed
/// split, so the partials and their order depend only on the mesh.
constexpr index_t kContactChunk = 2048;

__device__ void empty_partial(ContactPartial& p) {
  for (int t = 0; t < kMaxTools; ++t) {
    p.reaction[t][0] = p.reaction[t][1] = p.reaction[t][2] = 0;
    p.contact[t] = p.grasped[t] = p.rigid[t] = p.outside[t] = 0;
    p.rigid_first[t] = -1;
  }
}

/// The block's combined partial, in thread 0 (cuda/block_sum.cuh; before: a
/// shared-memory tree over 128 threads with a __syncthreads per level, 20 us
/// on the kidney's 1.8k surface nodes).
__device__ ContactPartial block_combine(ContactPartial* sh, const ContactPartial& p) {
  ContactPartial empty;
  empty_partial(empty);
  return block_sum<kContactBlock>(p, empty, sh, [](ContactPartial& a, const ContactPartial& b) { combine(a, b); });
}

/// The tools' reductions of the combined partial q into out->tools.
__device__ void write_tools(const ContactPartial& q, Reductions* out) {
  for (int t = 0; t < kMaxTools; ++t) {
    ToolReduction r;
    r.reaction = {q.reaction[t][0], q.reaction[t][1], q.reaction[t][2]};
    r.contact = q.contact[t];
    r.grasped = q.grasped[t];
    r.rigid = q.rigid[t];
    r.rigid_first = q.rigid_first[t];
    r.outside = q.outside[t];
    out->tools[t] = r;
    out->finite = out->finite && isfinite(r.reaction.x + r.reaction.y + r.reaction.z);
  }
}

/// Stage 1: block b reduces surface nodes [b kContactChunk, (b + 1) kContactChunk) into partials[b];
/// a surface of one chunk (the kidney's) is finished here, into out, with no second launch.
/// (Before: one block walked the whole surface, 50k nodes on a 100k-triangle slab, latency-bound.)
template <class T>
__global__ void __launch_bounds__(kContactBlock) contact_partials_kernel(ModelView<T> m, StateView<T> s,
                                                                         ContactPartial* partials, Reductions* out) {
  __shared__ ContactPartial sh[kContactWarps];
  ContactPartial p;
  empty_partial(p);
  const index_t first = index_t(blockIdx.x) * kContactChunk;
  const index_t last = first + kContactChunk < m.n_surf ? first + kContactChunk : m.n_surf;
  for (index_t i = first + index_t(threadIdx.x); i < last; i += kContactBlock) {
    const index_t a = m.surf_nodes[i];
    const int t = s.contact_tool[a];
    const std::uint8_t kind = s.contact[a];
    if (t < 0 || t >= kMaxTools || kind == kNoContact) continue;
    const Vec3<T> r = contact_reaction(kind, s.f[a].vec(), s.contact_normal[a].vec(), fixed_axes(m.node_flags[a]));
    p.reaction[t][0] += double(r.x);
    p.reaction[t][1] += double(r.y);
    p.reaction[t][2] += double(r.z);
    p.contact[t] += (kind == kPushed || kind == kGrasped) ? 1 : 0;
    p.grasped[t] += kind == kGrasped ? 1 : 0;
    if (kind == kRigidContact) {
      if (p.rigid_first[t] < 0 || a < p.rigid_first[t]) p.rigid_first[t] = a;
      ++p.rigid[t];
    }
    p.outside[t] += kind == kOutsideRegion ? 1 : 0;
  }
  p = block_combine(sh, p);
  if (threadIdx.x != 0) return;
  if (gridDim.x == 1)
    write_tools(p, out);
  else
    partials[blockIdx.x] = p;
}

/// Stage 2: one block combines the n partials (fixed order) into out->tools.
__global__ void __launch_bounds__(kContactBlock) contact_finish_kernel(const ContactPartial* partials, int n,
                                                                       Reductions* out) {
  __shared__ ContactPartial sh[kContactWarps];
  ContactPartial p;
  empty_partial(p);
  for (int i = int(threadIdx.x); i < n; i += kContactBlock) combine(p, partials[i]);
  p = block_combine(sh, p);
  if (threadIdx.x == 0) write_tools(p, out);
}

int contact_blocks(index_t n_surf) { return int((std::max<index_t>(n_surf, 1) + kContactChunk - 1) / kContactChunk); }

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
  partials_.allocate(contact_blocks(n_surf));
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

template <class T>
void DeviceContact<T>::reduce(const ModelView<T>& m, const StateView<T>& s, Reductions* out, cudaStream_t stream) {
  const int blocks = contact_blocks(m.n_surf);
  launch_blocks(blocks, kContactBlock, stream, contact_partials_kernel<T>, m, s, partials_.data(), out);
  if (blocks > 1)
    launch_blocks(1, kContactBlock, stream, contact_finish_kernel, static_cast<const ContactPartial*>(partials_.data()),
                  blocks, out);
}

template class DeviceContact<float>;
template class DeviceContact<double>;

}  // namespace tissue::gpu
