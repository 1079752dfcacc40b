// The cuda backend's device memory: held bytes are accounted and returned,
// and a model that does not fit is refused at upload with the bytes asked
// for, held and available (docs/reliability.md).
#include <stdexcept>
#include <string>

#include "cuda_test_support.hpp"

namespace tissue::cuda_test {
namespace {

TEST(CudaMemory, AModelThatDoesNotFitIsRefusedNamingTheBytes) {
  SKIP_WITHOUT_GPU();
  const TissueModel<double> m = box_model(8, 8, 8, 0.02, 0.02, 0.02);
  set_cuda_memory_limit(64 * 1024);  // far below the ~1 MB this model needs
  auto b = make_cuda_backend(Precision::Float);
  try {
    b->upload(m);
    set_cuda_memory_limit(0);
    FAIL() << "upload under a 64 KiB limit succeeded";
  } catch (const std::runtime_error& e) {
    set_cuda_memory_limit(0);
    const std::string what = e.what();
    for (const char* word : {"does not fit in GPU memory", "729 nodes", "3072 tets", "float", "MiB", "limit"})
      EXPECT_NE(what.find(word), std::string::npos) << "'" << word << "' missing from: " << what;
  }
  // the same backend uploads once the limit is lifted, and runs
  EXPECT_NO_THROW(b->upload(m));
  b->advance(10);
  EXPECT_TRUE(b->reduce().finite);
}

TEST(CudaMemory, HeldBytesAreReturnedWhenBackendsGo) {
  SKIP_WITHOUT_GPU();
  const TissueModel<double> m = box_model(8, 8, 8, 0.02, 0.02, 0.02);
  std::int64_t before = -1, with = -1;
  {
    auto probe = make_cuda_backend(Precision::Float);
    probe->upload(m);
    with = probe->device_memory().held;
    EXPECT_GT(probe->device_memory().total, 0);
    EXPECT_GE(probe->device_memory().free, 0);
  }
  {
    auto idle = make_cuda_backend(Precision::Double);
    before = idle->device_memory().held;  // nothing uploaded: what other backends hold (none here)
  }
  EXPECT_GT(with, before);
  for (int k = 0; k < 20; ++k) {  // upload, run and drop, again and again: nothing accumulates
    auto b = make_cuda_backend(k % 2 ? Precision::Double : Precision::Float);
    b->upload(m);
    b->upload(m);  // a re-upload frees the old arrays first
    b->advance(5);
  }
  auto after = make_cuda_backend(Precision::Float);
  EXPECT_EQ(after->device_memory().held, before);
}

}  // namespace
}  // namespace tissue::cuda_test
