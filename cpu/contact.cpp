#include "cpu/contact.hpp"

#include <algorithm>

#include "core/node_rules.hpp"

namespace tissue::cpu {
namespace {

template <class T>
Vec3<T> at(const std::vector<T>& v, index_t n, index_t a) {
  return {v[a], v[n + a], v[2 * size_t(n) + a]};
}

template <class T>
void put(std::vector<T>& v, index_t n, index_t a, Vec3<T> x) {
  v[a] = x.x;
  v[n + a] = x.y;
  v[2 * size_t(n) + a] = x.z;
}

/// The box of the sub-check capsules (j = 1..substeps of every tool), padded by pad radii.
template <class T, class Capsules>
Box sweep_box(const ContactTools<T>& tools, const Capsules& capsule, double pad) {
  Box box;
  for (int t = 0; t < tools.n_tools; ++t)
    for (int j = 1; j <= tools.tool[t].substeps; ++j) {
      const Capsule<T> cap = capsule(t, j);
      const double a[3] = {cap.a.x, cap.a.y, cap.a.z}, b[3] = {cap.b.x, cap.b.y, cap.b.z};
      box.add(a, pad * double(cap.r));
      box.add(b, pad * double(cap.r));
    }
  return box;
}

}  // namespace

template <class T>
ContactStage<T>::ContactStage(const TissueModel<T>& m) : m_(m), bvh_(m, std::max(median_surface_edge(m), 1e-9)) {
  bvh_.set_skin(0.5 * bvh_.margin());
}

template <class T>
void ContactStage<T>::CapsuleTable::fill(const ContactTools<T>& tools, int k) {
  caps_.clear();
  for (int t = 0; t < tools.n_tools; ++t) {
    first_[t] = caps_.size();
    for (int j = 0; j <= tools.tool[t].substeps; ++j) caps_.push_back(tool_capsule(tools.tool[t], tools.steps, k, j));
  }
}

template <class T>
Vec3<T> ContactStage<T>::corner_position(const TissueState<T>& s, const ContactTools<T>& tools, int k, const T* u,
                                         index_t a) const {
  const index_t n = m_.n_nodes;
  if (s.contact[a] == kGrasped) {
    const ToolStep<T>& tool = tools.tool[s.contact_tool[a]];
    Vec3<T> tip, axis;
    interpolate_pose(tool.tip0, tool.axis0, tool.tip1, tool.axis1, T(k + 1) / T(tools.steps), tip, axis);
    return grasped_position(tip, axis, tool.grasp_axis, at(s.grasp_offset, n, a));
  }
  return Vec3<T>{m_.X[a], m_.X[n + a], m_.X[2 * size_t(n) + a]} + Vec3<T>{u[a], u[n + a], u[2 * size_t(n) + a]};
}

template <class T>
void ContactStage<T>::check_region(const TissueState<T>& s, std::span<const index_t> nodes, int part) {
  left_[std::size_t(part)].left = bvh_.left_margin(s.u_next.data(), nodes);
}

template <class T>
bool ContactStage<T>::begin_step(TissueState<T>& s, const ContactTools<T>& tools, int k, int parts) {
  const index_t n = m_.n_nodes;
  // forget last step's contacts (grasps stay)
  for (index_t a : touched_)
    if (s.contact[a] != kGrasped) {
      s.contact[a] = kNoContact;
      s.contact_tool[a] = -1;
    }
  touched_.clear();
  if (tools.n_tools == 0) return false;
  // grasped nodes follow their tool
  for (int t = 0; t < tools.n_tools; ++t) {
    if (!tools.tool[t].grasping) continue;
    for (index_t a : grasped_[t]) {
      const Vec3<T> X = {m_.X[a], m_.X[n + a], m_.X[2 * size_t(n) + a]};
      put(s.u_next, n, a, corner_position(s, tools, k, s.u_next.data(), a) - X);
      put(s.u_carry, n, a, Vec3<T>{0, 0, 0});  // a position set by contact carries no rounding (as on cuda)
      touched_.push_back(a);
    }
  }
  // the triangles near the tools; only the region's nodes and the grasped ones have moved
  const long builds = bvh_.builds();
  for (int t = 0; t < tools.n_tools; ++t)
    if (tools.tool[t].grasping) bvh_.update(s.u_next.data(), grasped_[t]);
  // the region's nodes, as the members' check_region found them against the build before the grasped
  // nodes' update (a build since is at this u, which every region node is within)
  bool left = false;
  for (int p = 0; p < parts; ++p) left = left || left_[std::size_t(p)].left;
  bvh_.update_checked(s.u_next.data(), left && bvh_.builds() == builds);
  capsules_.fill(tools, k);
  tris_now_ = &bvh_.query_within_skin(sweep_box(tools, capsules_, 1.0));
  // at least kMinSweepShare triangles per part: a share smaller than that costs less than the barrier
  n_parts_ = std::clamp<std::size_t>(tris_now_->size() / kMinSweepShare, 1, std::size_t(std::max(parts, 1)));
  if (parts_.size() < n_parts_) parts_.resize(n_parts_);
  for (std::size_t p = 0; p < n_parts_; ++p) parts_[p].entries.clear();
  if (n_parts_ > 1) return true;
  sweep(s, tools, k, 0);  // one part: here, and the step is complete
  finish_step(s, tools, k);
  return false;
}

template <class T>
void ContactStage<T>::sweep(const TissueState<T>& s, const ContactTools<T>& tools, int k, int part) {
  const index_t nt = m_.n_tris;
  if (std::size_t(part) >= n_parts_) return;  // a member beyond the parts begin_step chose
  const std::vector<index_t>& tris = *tris_now_;
  // this part's share of the triangles (the same cut for every part count that begin_step was given)
  const std::size_t first = tris.size() * part / n_parts_, last = tris.size() * (part + 1) / n_parts_;
  std::vector<Entry>& entries = parts_[part].entries;
  for (std::size_t q = first; q < last; ++q) {
    const index_t t = tris[q];
    Vec3<T> x[3];
    index_t c[3];
    for (int i = 0; i < 3; ++i) {
      c[i] = m_.tris[i * nt + t];
      x[i] = corner_position(s, tools, k, s.u_next.data(), c[i]);
    }
    // sweep_triangle's test first: most triangles the query returns are out of reach
    if (!triangle_may_touch(tools, capsules_, x)) continue;
    std::uint8_t block[3];
    for (int i = 0; i < 3; ++i) {
      const index_t a = c[i];
      block[i] = corner_block(s.region.role[a] == kInner, s.held[a] == kAllAxes, s.contact[a] == kGrasped);
    }
    CornerContact<T> out[3];
    sweep_touching_triangle(tools, capsules_, x, block, out);
    for (int i = 0; i < 3; ++i)
      if (proposes(out[i])) entries.push_back({c[i], 3 * t + i, out[i]});
  }
}

template <class T>
void ContactStage<T>::finish_step(TissueState<T>& s, const ContactTools<T>& tools, int k) {
  const index_t n = m_.n_nodes;
  entries_.clear();
  for (std::size_t p = 0; p < n_parts_; ++p)
    entries_.insert(entries_.end(), parts_[p].entries.begin(), parts_[p].entries.end());
  // each node takes its triangles' largest proposal (ascending triangle order)
  std::sort(entries_.begin(), entries_.end(),
            [](const Entry& a, const Entry& b) { return a.node != b.node ? a.node < b.node : a.slot < b.slot; });
  for (std::size_t i = 0; i < entries_.size();) {
    const index_t a = entries_[i].node;
    std::size_t j = i;
    while (j < entries_.size() && entries_[j].node == a) ++j;
    const NodeContact<T> acc =
        merge_proposals<T>(int(j - i), [&](int k) -> const CornerContact<T>& { return entries_[i + k].c; });
    i = j;
    if (s.contact[a] == kGrasped || acc.kind == kNoContact) continue;
    if (acc.kind == kPushed) {
      const Vec3<T> dx = free_part(s.held[a], acc.dx);  // a roller's held component does not move
      const Vec3<T> normal = unit_or(dx, Vec3<T>{0, 0, 0}), u_now = at(s.u, n, a);
      const ToolStep<T>& tool = tools.tool[acc.tool];
      const Vec3<T> X = {m_.X[a], m_.X[n + a], m_.X[2 * size_t(n) + a]};
      Vec3<T> u1 = at(s.u_next, n, a) + dx;
      const Vec3<T> w = tool_motion_at(tool, tools.steps, k, X + u1);
      u1 = coulomb_slip(s.held[a], u_now, u1, normal, w, dx, tool.friction);
      put(s.u_next, n, a, u1);
      put(s.u_carry, n, a, Vec3<T>{0, 0, 0});
      put(s.contact_normal, n, a, normal);
      put(s.u, n, a, contact_previous(s.held[a], u_now, u1, normal, w));
    }
    s.contact[a] = acc.kind;
    s.contact_tool[a] = acc.tool;
    touched_.push_back(a);
  }
  std::sort(touched_.begin(), touched_.end());
}

template <class T>
void ContactStage<T>::begin_grasp(TissueState<T>& s, int tool, Vec3<double> tip) {
  const index_t n = m_.n_nodes;
  std::vector<index_t>& g = grasped_[tool];
  g.clear();
  for (index_t a : touched_) {
    if (s.contact[a] != kPushed || s.contact_tool[a] != tool) continue;
    s.contact[a] = kGrasped;
    const Vec3<T> x = Vec3<T>{m_.X[a], m_.X[n + a], m_.X[2 * size_t(n) + a]} + at(s.u, n, a);
    put(s.grasp_offset, n, a, x - Vec3<T>{T(tip.x), T(tip.y), T(tip.z)});
    g.push_back(a);
  }
}

template <class T>
void ContactStage<T>::end_grasp(TissueState<T>& s, int tool) {
  for (index_t a : grasped_[tool]) {
    s.contact[a] = kNoContact;
    s.contact_tool[a] = -1;
  }
  grasped_[tool].clear();
}

template <class T>
void ContactStage<T>::reset(TissueState<T>& s) {
  for (index_t a : touched_) {
    s.contact[a] = kNoContact;
    s.contact_tool[a] = -1;
  }
  touched_.clear();
  for (auto& g : grasped_) {
    for (index_t a : g) {
      s.contact[a] = kNoContact;
      s.contact_tool[a] = -1;
    }
    g.clear();
  }
}

template <class T>
std::vector<index_t> ContactStage<T>::candidates(const TissueState<T>& s, const ContactTools<T>& sweep) {
  const index_t nt = m_.n_tris;
  std::vector<index_t> out;
  bvh_.update(s.u.data(), s.region.nodes);
  bvh_.query(sweep_box(sweep, StepCapsules<T>{sweep, 0}, double(kCandidateReach<T>)), tris_);
  for (index_t t : tris_) {
    Vec3<T> x[3];
    index_t c[3];
    bool all_inner = true;
    for (int i = 0; i < 3; ++i) {
      c[i] = m_.tris[i * nt + t];
      x[i] = corner_position(s, sweep, 0, s.u.data(), c[i]);
      all_inner = all_inner && s.region.role[c[i]] == kInner;
    }
    if (all_inner) continue;
    if (!triangle_near_tools(sweep, x)) continue;
    for (int i = 0; i < 3; ++i)
      if (s.region.role[c[i]] != kInner) out.push_back(c[i]);
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

template <class T>
void reduce_contacts(const TissueModel<T>& m, const TissueState<T>& s, const std::vector<index_t>& touched,
                     const T friction[kMaxTools], ToolReduction out[kMaxTools]) {
  const index_t n = m.n_nodes;
  for (int t = 0; t < kMaxTools; ++t) out[t] = ToolReduction{};
  for (index_t a : touched) {
    const int t = s.contact_tool[a];
    if (t < 0 || t >= kMaxTools) continue;
    ToolReduction& r = out[t];
    const std::uint8_t kind = s.contact[a];
    const Vec3<T> f = at(s.f, n, a);
    const Vec3<T> react =
        contact_reaction(kind, f, at(s.contact_normal, n, a), fixed_axes(m.node_flags[a]), friction[t]);
    r.reaction = r.reaction + Vec3<double>{double(react.x), double(react.y), double(react.z)};
    r.contact += (kind == kPushed || kind == kGrasped) ? 1 : 0;
    r.grasped += kind == kGrasped ? 1 : 0;
    if (kind == kRigidContact) {
      if (r.rigid == 0 || a < r.rigid_first) r.rigid_first = a;
      ++r.rigid;
    }
    r.outside += kind == kOutsideRegion ? 1 : 0;
  }
}

template class ContactStage<float>;
template class ContactStage<double>;
template void reduce_contacts(const TissueModel<float>&, const TissueState<float>&, const std::vector<index_t>&,
                              const float[kMaxTools], ToolReduction[kMaxTools]);
template void reduce_contacts(const TissueModel<double>&, const TissueState<double>&, const std::vector<index_t>&,
                              const double[kMaxTools], ToolReduction[kMaxTools]);

}  // namespace tissue::cpu
