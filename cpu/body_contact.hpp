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
  /// The step's contact: moves the touching nodes in s.u_next.
  void step(TissueState<T>& s);
  /// The rows inside another body at the last step (ascending node).
  std::vector<BodyContactNode> contacts() const;
  long builds() const { return builds_; }

 private:
  void build(const TissueState<T>& s);
  const TissueModel<T>& m_;
  BodyContactSpec spec_;
  BodyLists lists_;
  std::vector<T> cand_mu_;
  std::vector<BodyHit<T>> hits_;
  std::vector<Vec3<T>> moves_;
  std::vector<int> counts_;
  long builds_ = 0;
};

}  // namespace tissue::cpu
