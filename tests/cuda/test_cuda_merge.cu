// The merge of a node's proposals on the device (core merge_proposals_unrolled,
// which the cuda merge kernel runs): its later passes run only when
// pass_would_change says they would change something, and the result must be
// that of every pass written out in full -- the same bits -- in a kernel of
// its own, where nvcc inlines both again (the check and the pass evaluate the
// same expressions, and must round them alike). The lists and the passes
// written out are the host test's (tests/merge_lists.hpp; tests/test_contact.cpp,
// MergeCorner.PassesEndOnceOneChangesNothingWithTheSameBits).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <random>
#include <vector>

#include "cuda/check.hpp"
#include "cuda/contact.cuh"
#include "cuda/device_array.hpp"
#include "tests/cuda/cuda_test_support.hpp"
#include "tests/merge_lists.hpp"

namespace tissue::cuda_test {
namespace {

constexpr int kLists = 1 << 16;
constexpr int kMax = gpu::kHeldProposals;

template <class T>
__global__ void merge_both_kernel(const CornerContact<T>* lists, const int* counts, int n, int* differ, int* early) {
  const int i = int(blockIdx.x * blockDim.x + threadIdx.x);
  if (i >= n) return;
  const CornerContact<T>* v = lists + i * kMax;
  CornerContact<T> held[kMax];
  for (int j = 0; j < kMax; ++j) held[j] = v[j];
  const NodeContact<T> a = merge_proposals_unrolled<kMax, T>(counts[i], [&](int j) { return held[j]; });
  const NodeContact<T> b = test::merge_every_pass<T>(counts[i], [&](int j) { return v[j]; });
  if (!same_bits(a, b)) atomicAdd(differ, 1);
  NodeContact<T> one;  // the first pass: the check ends most pushed nodes' passes there
  for (int j = 0; j < counts[i]; ++j) merge_corner(one, v[j]);
  if (one.kind == kPushed && !pass_would_change<kMax, T>(one, counts[i], [&](int j) { return held[j]; }))
    atomicAdd(early, 1);
}

template <class T>
void check_merge_bits() {
  std::mt19937 rng(20261128);
  std::vector<CornerContact<T>> lists(std::size_t(kLists) * kMax);
  std::vector<int> counts(kLists);
  for (int i = 0; i < kLists; ++i) {
    counts[i] = 1 + i % kMax;
    const std::vector<CornerContact<T>> v = test::random_proposal_list<T>(rng, kMax, i % 3 == 0);
    std::copy(v.begin(), v.end(), lists.begin() + std::ptrdiff_t(i) * kMax);
  }
  gpu::DeviceArray<CornerContact<T>> dl(lists.size());
  gpu::DeviceArray<int> dc(kLists), flags(2);
  CUDA_CHECK(cudaMemcpy(dl.data(), lists.data(), lists.size() * sizeof(lists[0]), cudaMemcpyHostToDevice));
  CUDA_CHECK(cudaMemcpy(dc.data(), counts.data(), kLists * sizeof(int), cudaMemcpyHostToDevice));
  CUDA_CHECK(cudaMemset(flags.data(), 0, 2 * sizeof(int)));
  merge_both_kernel<T><<<kLists / 128, 128>>>(dl.data(), dc.data(), kLists, flags.data(), flags.data() + 1);
  CUDA_CHECK(cudaGetLastError());
  int out[2];
  CUDA_CHECK(cudaMemcpy(out, flags.data(), sizeof(out), cudaMemcpyDeviceToHost));
  std::printf("[measured] %s: %d of %d merges differ from every pass written out; %d pushed nodes end after one pass\n",
              sizeof(T) == 4 ? "float" : "double", out[0], kLists, out[1]);
  EXPECT_EQ(out[0], 0);
  EXPECT_GT(out[1], kLists / 2) << "most lists push their node and end after one pass";
}

TEST(Merge, LaterPassesCheckedSideBySideGiveEveryPassesBits) {
  SKIP_WITHOUT_GPU();
  check_merge_bits<float>();
  check_merge_bits<double>();
}

}  // namespace
}  // namespace tissue::cuda_test
