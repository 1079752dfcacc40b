// core flood_fill (core/region.hpp) on a hand-checked mesh: the 4 x 1 x 1 box
// of box_mesh (20 nodes, 24 tets). Node (i, j, k) has id i + 5 (j + 2 k);
// cell i holds elements 6i .. 6i+5, one per axis path from its corner
// (i,0,0) to (i+1,1,1) in the order xyz, xzy, yxz, yzx, zxy, zyx. Inside a
// cell, (i,0,0) and (i+1,1,1) are in every tet; a corner one step from
// (i,0,0) along axis a is only in the two tets whose path starts with a; a
// corner two steps away only in the two tets whose path passes through it.
// The expected sets below were derived by hand from those rules.
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <stdexcept>
#include <vector>

#include "core/box_mesh.hpp"
#include "core/model.hpp"
#include "core/region.hpp"

namespace tissue {
namespace {

using Ids = std::vector<index_t>;

TissueModel<double> strip_model() {
  ModelInput in;
  box_mesh(in, 4, 1, 1, 4.0, 1.0, 1.0);
  in.materials = {{1.0, 10.0, 1.0}};
  in.source = "strip";
  return build_model(in);
}

Ids with_role(const Region& r, NodeRole role) {
  Ids out;
  for (index_t a = 0; a < index_t(r.role.size()); ++a)
    if (r.role[a] == role) out.push_back(a);
  return out;
}

/// Checks the region against expected inner nodes, halo nodes and elements
/// (all ascending), and its internal consistency.
void expect_region(const Region& r, const Ids& inner, const Ids& halo, const Ids& elems) {
  EXPECT_EQ(with_role(r, kInner), inner);
  EXPECT_EQ(with_role(r, kHalo), halo);
  EXPECT_EQ(r.elems, elems);
  Ids nodes = inner;
  nodes.insert(nodes.end(), halo.begin(), halo.end());
  std::sort(nodes.begin(), nodes.end());
  EXPECT_EQ(r.nodes, nodes);
  EXPECT_EQ(r.n_inner, index_t(inner.size()));
  EXPECT_EQ(r.n_halo, index_t(halo.size()));
  const RegionSizes s = r.sizes();
  EXPECT_EQ(s.nodes(), index_t(nodes.size()));
  EXPECT_EQ(s.n_elems, index_t(elems.size()));
}

Ids range(index_t lo, index_t hi) {  // [lo, hi)
  Ids v;
  for (index_t i = lo; i < hi; ++i) v.push_back(i);
  return v;
}

TEST(Region, StripIsTheMeshTheCommentDescribes) {
  const auto m = strip_model();
  ASSERT_EQ(m.n_nodes, 20);
  ASSERT_EQ(m.n_elems, 24);
  EXPECT_EQ(m.reoriented, 0);
  // element 2 of cell 0 is the path y, x, z: (0,0,0) (0,1,0) (1,1,0) (1,1,1)
  Ids e2;
  for (int a = 0; a < 4; ++a) e2.push_back(m.elem_nodes[a * m.n_elems + 2]);
  std::sort(e2.begin(), e2.end());
  EXPECT_EQ(e2, (Ids{0, 5, 6, 16}));
}

TEST(Region, CornerSeedDepth0) {
  const auto m = strip_model();
  const index_t seed[] = {0};  // (0,0,0): in every tet of cell 0 only
  expect_region(flood_fill(m, std::span<const index_t>(seed), 0), {0}, {1, 5, 6, 10, 11, 15, 16}, range(0, 6));
}

TEST(Region, CornerSeedDepth1) {
  const auto m = strip_model();
  const index_t seed[] = {0};
  expect_region(flood_fill(m, std::span<const index_t>(seed), 1), {0, 1, 5, 6, 10, 11, 15, 16}, {2, 7, 12, 17},
                range(0, 12));
}

TEST(Region, CornerSeedDepth2) {
  const auto m = strip_model();
  const index_t seed[] = {0};
  expect_region(flood_fill(m, std::span<const index_t>(seed), 2), {0, 1, 2, 5, 6, 7, 10, 11, 12, 15, 16, 17},
                {3, 8, 13, 18}, range(0, 18));
}

TEST(Region, EdgeSeedDepth0) {
  const auto m = strip_model();
  const index_t seed[] = {5};  // (0,1,0): one step along y, so only in tets 2 (yxz) and 3 (yzx)
  expect_region(flood_fill(m, std::span<const index_t>(seed), 0), {5}, {0, 6, 15, 16}, {2, 3});
}

TEST(Region, EdgeSeedDepth1) {
  const auto m = strip_model();
  const index_t seed[] = {5};
  // ring 1 = {0, 6, 15, 16}; node 6 = (1,1,0) is cell 1's y-step corner (tets 8, 9),
  // node 16 = (1,1,1) its yz corner (tets 9, 11); nodes 0 and 16 cover cell 0.
  expect_region(flood_fill(m, std::span<const index_t>(seed), 1), {0, 5, 6, 15, 16}, {1, 7, 10, 11, 17},
                {0, 1, 2, 3, 4, 5, 8, 9, 11});
}

TEST(Region, EdgeSeedDepth2) {
  const auto m = strip_model();
  const index_t seed[] = {5};
  // ring 2 adds 1, 10, 11 (cell 0) and 7, 17 (cell 1); node 1 covers cell 1;
  // in cell 2, node 7 = (2,1,0) is in tets 14, 15 and node 17 = (2,1,1) in 15, 17.
  expect_region(flood_fill(m, std::span<const index_t>(seed), 2), {0, 1, 5, 6, 7, 10, 11, 15, 16, 17}, {2, 8, 12, 18},
                {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 14, 15, 17});
}

TEST(Region, TwoSeedsAtBothEndsAndDuplicates) {
  const auto m = strip_model();
  const index_t seeds[] = {19, 0, 0};  // (4,1,1) is in every tet of cell 3 only
  const Region r = flood_fill(m, std::span<const index_t>(seeds), 0);
  expect_region(r, {0, 19}, {1, 3, 4, 5, 6, 8, 9, 10, 11, 13, 14, 15, 16, 18},
                {0, 1, 2, 3, 4, 5, 18, 19, 20, 21, 22, 23});
  EXPECT_EQ(r.seeds, (Ids{19, 0, 0}));
  EXPECT_FALSE(r.whole());
}

TEST(Region, DeepFillReachesEverythingWithoutHalo) {
  const auto m = strip_model();
  const index_t seed[] = {0};
  const Region r = flood_fill(m, std::span<const index_t>(seed), 10);
  expect_region(r, range(0, 20), {}, range(0, 24));
  EXPECT_FALSE(r.whole());
}

TEST(Region, AllIsTheWholeMeshAndIgnoresSeeds) {
  const auto m = strip_model();
  const index_t seed[] = {7};
  const Region r = flood_fill(m, std::span<const index_t>(seed), kDepthAll);
  expect_region(r, range(0, 20), {}, range(0, 24));
  EXPECT_TRUE(r.whole());
  EXPECT_TRUE(r.sizes().whole());
}

TEST(Region, NoSeedsAtFiniteDepthIsEmpty) {
  const auto m = strip_model();
  const Region r = flood_fill(m, std::span<const index_t>{}, 3);
  expect_region(r, {}, {}, {});
}

TEST(Region, BadSeedIsRejectedWithItsId) {
  const auto m = strip_model();
  for (index_t bad : {index_t(-1), index_t(20)}) {
    const index_t seed[] = {0, bad};
    try {
      flood_fill(m, std::span<const index_t>(seed), 1);
      FAIL() << "seed " << bad << " accepted";
    } catch (const std::out_of_range& e) {
      EXPECT_NE(std::string(e.what()).find(fmt::format("seed node {}", bad)), std::string::npos) << e.what();
    }
  }
}

TEST(Region, BadDepthIsRejected) {
  const auto m = strip_model();
  const index_t seed[] = {0};
  try {
    flood_fill(m, std::span<const index_t>(seed), -2);
    FAIL() << "depth -2 accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("depth -2"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace tissue
