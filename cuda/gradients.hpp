// Where the cuda backend's element passes get the element gradients
// (docs/cuda.md, "Element gradients"): the switch and Auto's two bounds,
// CUDA-free, for the public header (cuda/cuda_backend.hpp) and the kernels'
// views (cuda/views.hpp) alike.
#pragma once

#include "core/hd.hpp"

namespace tissue {

/// Where the cuda backend's element passes (1 and 3, and the reductions'
/// energies) get each element's shape gradients and volume (docs/cuda.md,
/// "Element gradients"):
///   Stored      loaded: 13 scalars per element and pass;
///   Recomputed  from its corners' reference positions, kept on the device
///               in double (double: core tet_shape_gradients_from) or as
///               points of a fixed-point grid (float: core
///               tet_shape_gradients_on_grid, half the bytes), at every
///               pass: a quarter fewer bytes per step at 1M tets;
///   Auto        both kept on a mesh of kRecomputeMinElements or more when
///               every element's recomputation at the backend's precision
///               stays within kGradientTolerance of the model's double
///               gradients (core worst_gradient_deviation):
///               regions of at least 50,000 elements (bandwidth-bound)
///               recompute, smaller ones (latency-bound: the haptic tick's)
///               load; Stored alone otherwise (a mesh with slivers).
enum class CudaGradients { Auto, Stored, Recomputed };

/// Auto's bound on the relative deviation of recomputed gradients: a
/// well-shaped tet's float recomputation deviates by a few 1e-7.
inline constexpr double kGradientTolerance = 1e-5;

/// Auto's smallest region whose element passes recompute the gradients.
/// Measured on an H100: the 8.6k-element kidney's steps gain nothing in
/// float and lose 19 % in double, its 4-step tick loses 4 %; 100k elements
/// gain 5-6 %, 1M 7-11 %.
inline constexpr index_t kRecomputeMinElements = 50'000;

}  // namespace tissue
