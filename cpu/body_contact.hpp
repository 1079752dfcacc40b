// The cpu backend's contact between bodies (core/body_contact.hpp's rule):
// the host-built candidate lists, rebuilt when a listed node has left a
// quarter of their skin (checked before every advance), and per TLED step
// the rows' hits, their counts and scales, then their moves, on one thread (the team's last member
// after pass 4, before the tools' contact stage).
#pragma once

#include <vector>

#include "core/backend.hpp"
#include "core/body_contact.hpp"
#include "core/state.hpp"

namespace tissue::cpu {

template <class T>
class BodyStage {
 public:
  /// Over m (m must outlive this), for spec (checked), at the state's current u.
  BodyStage(const TissueModel<T>& m, const BodyContactSpec& spec, const TissueState<T>& s);

  /// Rebuilds the lists when a listed node at the current u has moved too far since they were built.
  void refresh(const TissueState<T>& s);
  /// The step's contact, in three phases after the free update (each
  /// phase reads what every part of the one before wrote: a barrier
  /// between them): the candidate triangles' geometry and the rows' hits,
  /// each split into `parts` (run part 0..parts-1, one per team member),
  /// then finish() on one thread moves the touching nodes in s.u_next.
  void geometry(const TissueState<T>& s, int part, int parts);
  void hits(const TissueState<T>& s, int part, int parts);
  void finish(TissueState<T>& s);
  /// The rows inside another body at the last step (ascending node).
  std::vector<BodyContactNode> contacts() const;
  /// Forgets every stick anchor (a new initial state).
  void clear_anchors() { anchors_.assign(anchors_.size(), BodyAnchor<T>{}); }
  /// A new motion (Backend::set_motion): the lists built again at its u, no anchor kept.
  void restart(const TissueState<T>& s) {
    build(s);
    clear_anchors();
  }
  long builds() const { return builds_; }

 private:
  void build(const TissueState<T>& s);
  T inverse_mass(const TissueState<T>& s, index_t a) const;  ///< 1/m, or 0 where the node cannot move
  const TissueModel<T>& m_;
  BodyContactSpec spec_;
  BodyLists lists_;
  std::vector<T> cand_mu_;
  std::vector<BodyHit<T>> hits_;
  std::vector<BodyAnchor<T>> anchors_;  ///< per row, carried across steps and rebuilds
  std::vector<Vec3<T>> moves_;
  std::vector<T> counts_;
  std::vector<index_t> tris_;        ///< the candidates' triangles, each once (ascending)
  std::vector<index_t> tri_slot_;    ///< per surface triangle its place in tris_ (-1: none)
  std::vector<BodyTri<T>> geom_;     ///< tris_'s geometry at the step's free update
  long builds_ = 0;
};

}  // namespace tissue::cpu
