// The cpu backend's contact stage (core/contact.hpp's rule; docs/contact.md):
// per TLED step, the surface BVH (cpu/surface_bvh.hpp) gives the triangles
// near the tools' sub-check capsules (a query padded by a skin serves the
// next steps while the tools stay inside it), each is swept (core
// sweep_triangle, over the step's capsules computed once; the team's
// members sweep shares of the triangles), and each touched node takes its
// triangles' largest proposal (core merge_proposals, in ascending triangle
// order as the cuda backend's gather does). Only the candidates are
// visited: no loop over every node.
// Grasped nodes follow their tool (core grasped_position). Host functions of
// (const model&, state&) plus the stage's own scratch; allocation-free
// after the first steps (the scratch vectors keep their capacity).
#pragma once

#include <array>
#include <cstddef>
#include <span>
#include <vector>

#include "core/backend.hpp"
#include "core/state.hpp"
#include "cpu/surface_bvh.hpp"

namespace tissue::cpu {

/// The fewest triangles a team member sweeps in a step (ContactStage::sweep):
/// fewer are swept by one member, without the barrier a shared sweep needs.
inline constexpr std::size_t kMinSweepShare = 32;

/// The most parts (team members) of a contact step (ThreadTeam::kMaxSize).
inline constexpr int kMaxParts = 255;

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
  /// In three parts, for a team of `parts` members (the cpu backend's
  /// advance): begin_step on one member; if it returns true, sweep(part) on
  /// every member part < parts at once (each sweeps its share of the
  /// triangles near the tools into its own list; members beyond the shares
  /// begin_step chose, at least kMinSweepShare triangles each, return at
  /// once), then finish_step on one member once all have swept (it merges
  /// the proposals). false: the step is already complete (no tools, or too
  /// few triangles near them to share: begin_step swept them). The results
  /// do not depend on parts (proposals merge in (node, triangle) order).
  ///
  /// Before begin_step, every member part < parts calls check_region with
  /// its slice of the region's nodes (after its pass 4, while their u_next
  /// is in its core's cache): the members share the check of the region's
  /// nodes against the surface BVH's margin, and begin_step rebuilds the
  /// BVH if any found one beyond it (one member checking every region node
  /// was ~18 us of each 16-thread step on the kidney).
  void check_region(const TissueState<T>& s, std::span<const index_t> nodes, int part);
  bool begin_step(TissueState<T>& s, const ContactTools<T>& tools, int k, int parts);
  void sweep(const TissueState<T>& s, const ContactTools<T>& tools, int k, int part);
  void finish_step(TissueState<T>& s, const ContactTools<T>& tools, int k);

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
  /// Makes the surface BVH valid for the current u now (a build, the first time).
  void warm_up(const TissueState<T>& s) { bvh_.update(s.u.data()); }

  /// The surface BVH (tests: builds only when the surface left the margin).
  const SurfaceBvh<T>& bvh() const { return bvh_; }

  /// How far (m) beyond the tools' box each step's BVH query reaches, so
  /// that the next steps can reuse its triangles (SurfaceBvh::query_within_skin);
  /// 0: a query per step. Default: half the BVH margin. The results do not
  /// depend on it (the extra triangles are out of the tools' reach).
  void set_query_skin(double skin) { bvh_.set_skin(skin); }

 private:
  /// A corner's position: grasped nodes at their tool's pose for step k.
  Vec3<T> corner_position(const TissueState<T>& s, const ContactTools<T>& tools, int k, const T* u, index_t a) const;

  /// The sub-check capsules of one step, computed once per step: the values
  /// of core StepCapsules, read by the sweep of every triangle.
  class CapsuleTable {
   public:
    void fill(const ContactTools<T>& tools, int k);
    Capsule<T> operator()(int t, int j) const { return caps_[first_[t] + std::size_t(j)]; }

   private:
    std::vector<Capsule<T>> caps_;
    std::size_t first_[kMaxTools] = {};
  };

  const TissueModel<T>& m_;
  SurfaceBvh<T> bvh_;
  CapsuleTable capsules_;                     ///< the current step's
  std::vector<index_t> tris_;                 ///< the triangles of candidates()' query
  struct Entry {
    index_t node, slot;
    CornerContact<T> c;
  };
  struct alignas(64) Part {                   ///< one sweep() member's proposals (own cache lines)
    std::vector<Entry> entries;
  };
  const std::vector<index_t>* tris_now_ = nullptr;  ///< the current step's triangles (the BVH's kept query)
  std::vector<Part> parts_;                   ///< the current step's sweeps (the first n_parts_)
  std::size_t n_parts_ = 1;
  std::vector<Entry> entries_;                ///< the candidates' corner proposals, all parts
  std::vector<index_t> touched_;              ///< nodes with a contact kind (pushed, rigid, outside, grasped)
  std::array<std::vector<index_t>, kMaxTools> grasped_;  ///< per tool, ascending
  struct alignas(64) Left {                  ///< one check_region member's result (own cache line)
    bool left = false;
  };
  std::array<Left, kMaxParts> left_{};       ///< check_region's results, by part
};

/// Per-tool contact reductions (core ToolReduction) over the touched nodes:
/// reaction = sum of core contact_reaction with the internal force s.f and
/// each tool's friction coefficient (the last advance's).
template <class T>
void reduce_contacts(const TissueModel<T>& m, const TissueState<T>& s, const std::vector<index_t>& touched,
                     const T friction[kMaxTools], ToolReduction out[kMaxTools]);

}  // namespace tissue::cpu
