// Shared helpers of the cuda backend tests: the GPU skip, small box models,
// random (non-zero) displacement fields and field comparisons.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "core/box_mesh.hpp"
#include "core/model.hpp"
#include "cpu/cpu_backend.hpp"
#include "cuda/cuda_backend.hpp"

namespace tissue::cuda_test {

/// Skips the calling test when no usable GPU is present (CI), naming why.
#define SKIP_WITHOUT_GPU()                                          \
  do {                                                              \
    std::string why_;                                               \
    if (!::tissue::cuda_available(&why_)) GTEST_SKIP() << why_;     \
  } while (0)

/// Brain-like tissue (E = 3000 Pa, nu = 0.45, rho = 1000 kg/m^3) on an
/// lx x ly x lz box of nx x ny x nz cells (6 tets each), bottom face fixed.
inline TissueModel<double> box_model(int nx, int ny, int nz, double lx, double ly, double lz, bool ianp = true) {
  ModelInput in;
  box_mesh(in, nx, ny, nz, lx, ly, lz);
  const double E = 3000, nu = 0.45;
  in.materials = {{E / (2 * (1 + nu)), E / (3 * (1 - 2 * nu)), 1000}};
  in.fixed.assign(in.nodes.size() / 3, 0);
  for (size_t i = 0; i < in.fixed.size(); ++i) in.fixed[i] = in.nodes[3 * i + 2] == 0.0;
  in.ianp = ianp;
  in.source = "test box";
  return build_model(in);
}

/// Uniform random displacements in [-amplitude, amplitude] m (3 x n_nodes),
/// fixed nodes included (the passes must not care).
inline std::vector<double> random_field(index_t n_nodes, double amplitude, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> d(-amplitude, amplitude);
  std::vector<double> u(3 * size_t(n_nodes));
  for (auto& v : u) v = d(rng);
  return u;
}

/// max |a_i - b_i| / max(max |b_i|, floor): the relative difference of two
/// fields measured against the reference field's magnitude.
inline double rel_diff(const std::vector<double>& a, const std::vector<double>& b, double floor = 1e-300) {
  EXPECT_EQ(a.size(), b.size());
  double d = 0, m = 0;
  for (size_t i = 0; i < std::min(a.size(), b.size()); ++i) {
    d = std::max(d, std::fabs(a[i] - b[i]));
    m = std::max(m, std::fabs(b[i]));
  }
  return d / std::max(m, floor);
}

/// Precision names for parameterised test names.
inline std::string name_of(Precision p) { return to_string(p); }

}  // namespace tissue::cuda_test
