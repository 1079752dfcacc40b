// The cpu backend's contact stage (core/contact.hpp's rule; docs/contact.md):
// per TLED step, the surface BVH (cpu/surface_bvh.hpp) gives the triangles
// near the tools' sub-check capsules, each is swept (core sweep_triangle),
// and each touched node takes its triangles' largest proposal (core
// merge_corner, in ascending triangle order as the cuda backend's gather
// does). Only the candidates are visited: no loop over every node.
// Grasped nodes follow their tool (core grasped_position). Host functions of
// (const model&, state&) plus the stage's own scratch; allocation-free
// after the first steps (the scratch vectors keep their capacity).
#pragma once

#include <array>
#include <vector>

#include "core/backend.hpp"
#include "core/state.hpp"
#include "cpu/surface_bvh.hpp"

namespace tissue::cpu {

template <class T>
class ContactStage {
 public:
  /// Over m's surface (m must outlive this); the BVH margin is the median
  /// surface edge length.
  explicit ContactStage(const TissueModel<T>& m);

  /// The contact stage of step k of an advance (after pass 4 wrote
  /// s.u_next, before the buffers rotate): moves grasped nodes to their
  /// tools and pushed nodes out of them in s.u_next, and records every
  /// surface node's contact (s.contact, contact_tool, contact_normal).
  void step(TissueState<T>& s, const ContactTools<T>& tools, int k);

  /// Tool `tool` at pose (tip, axis) grasps its pushed nodes.
  void begin_grasp(TissueState<T>& s, int tool, Vec3<double> tip);
  /// Releases tool `tool`'s grasped nodes (they become free, not in contact).
  void end_grasp(TissueState<T>& s, int tool);
  /// Forgets every contact and grasp (new tools).
  void reset(TissueState<T>& s);

  /// Surface nodes that are not inner region nodes within 1.5 radii of the
  /// sweep's sub-check capsules (current u), ascending.
  std::vector<index_t> candidates(const TissueState<T>& s, const ContactTools<T>& sweep);

  /// Nodes whose contact kind is not kNoContact, ascending (reductions, contacts()).
  const std::vector<index_t>& touched() const { return touched_; }

  /// The next contact step or candidates() checks the whole surface against
  /// the BVH's margin, not only the region's nodes: call after any change of
  /// u beyond the region's nodes (new displacements, a new region, driven nodes).
  void surface_moved() { bvh_.invalidate(); }

  /// The surface BVH (tests: builds only when the surface left the margin).
  const SurfaceBvh<T>& bvh() const { return bvh_; }

 private:
  /// Boxes of the capsules that step k of `tools` checks, padded by pad radii.
  Box sweep_box(const ContactTools<T>& tools, int k, double pad) const;
  /// A corner's position: grasped nodes at their tool's pose for step k.
  Vec3<T> corner_position(const TissueState<T>& s, const ContactTools<T>& tools, int k, const T* u, index_t a) const;

  const TissueModel<T>& m_;
  SurfaceBvh<T> bvh_;
  std::vector<index_t> tris_;                 ///< candidate triangles of the current query
  struct Entry {
    index_t node, slot;
    CornerContact<T> c;
  };
  std::vector<Entry> entries_;                ///< the candidates' corner proposals
  std::vector<index_t> touched_;              ///< nodes with a contact kind (pushed, rigid, outside, grasped)
  std::array<std::vector<index_t>, kMaxTools> grasped_;  ///< per tool, ascending
};

/// Per-tool contact reductions (core ToolReduction) over the touched nodes:
/// reaction = sum of core contact_reaction with the internal force s.f.
template <class T>
void reduce_contacts(const TissueModel<T>& m, const TissueState<T>& s, const std::vector<index_t>& touched,
                     ToolReduction out[kMaxTools]);

}  // namespace tissue::cpu
