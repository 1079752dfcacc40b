// The merge's reference and test lists, for its host test
// (tests/test_contact.cpp, MergeCorner) and its device test
// (tests/cuda/test_cuda_merge.cu): core merge_corner over every pass written
// out in full, and random proposal lists -- near-parallel ones, scattered
// ones with obtuse pairs, zero and blocked ones among them.
#pragma once

#include <cmath>
#include <random>
#include <vector>

#include "core/node_rules.hpp"

namespace tissue::test {

/// kMergePasses passes of merge_corner over `count` proposals (get(j) the
/// j-th), none ended early: what merge_proposals and
/// merge_proposals_unrolled must give, bit for bit.
template <class T, class Get>
TISSUE_HD NodeContact<T> merge_every_pass(int count, Get get) {
  NodeContact<T> acc;
  for (int pass = 0; pass < kMergePasses; ++pass) {
    for (int j = 0; j < count; ++j) merge_corner(acc, get(j));
    if (acc.kind != kPushed) break;
  }
  return acc;
}

/// `count` random proposals for one node: 15 % none or blocked (rigid,
/// outside the region), the others 0.1-1.1 mm long, within a few tens of
/// degrees of (1, 1, 1) or, `scattered`, in any direction; tools 0-2.
template <class T>
std::vector<CornerContact<T>> random_proposal_list(std::mt19937& rng, int count, bool scattered) {
  std::normal_distribution<double> g(0, 1);
  std::uniform_real_distribution<double> u01(0, 1);
  const double n = 1 / std::sqrt(3.0);
  std::vector<CornerContact<T>> v;
  for (int j = 0; j < count; ++j) {
    const auto tool = static_cast<signed char>(j % 3);
    const double kind = u01(rng);
    if (kind < 0.15) {  // no proposal, or a blocked one
      const auto blocked = std::uint8_t(kind < 0.05 ? 0 : (kind < 0.1 ? kRigidContact : kOutsideRegion));
      v.push_back({{T(0), T(0), T(0)}, tool, blocked});
      continue;
    }
    double d[3] = {g(rng), g(rng), g(rng)};
    if (!scattered)
      for (double& x : d) x = n + 0.2 * x;
    const double s = 1e-4 + 1e-3 * u01(rng);
    v.push_back({{T(s * d[0]), T(s * d[1]), T(s * d[2])}, tool, 0});
  }
  return v;
}

}  // namespace tissue::test
