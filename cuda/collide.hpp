// The tool-segment query on the device (DESIGN.md section 3): one thread per
// surface triangle writes its hit distance (or +inf) using core
// segment_triangle in the backend's precision, a CUB ArgMin picks the
// nearest (ties: lowest triangle index), and one thread fills the Hit that
// comes back as the only copy. The distance written is the fraction t of
// |AB| (|AP| = t |AB|, the same order), exactly the key the cpu backend
// minimises, so both pick the same triangle without a rounding step between.
#pragma once

#include <cuda_runtime.h>

#include <cstdint>

#include "core/backend.hpp"
#include "cuda/device_array.hpp"
#include "cuda/views.hpp"

namespace tissue::gpu {

template <class T>
class Collider {
 public:
  /// Allocates the per-triangle keys, the CUB scratch and the result.
  void allocate(index_t n_tris);

  /// Segment a -> b (m) against the surface deformed by u (n_nodes). A
  /// zero-length segment hits nothing; a non-finite one throws
  /// std::invalid_argument.
  Hit query(const ModelView<T>& m, const Packed3<T>* u, Vec3<double> a, Vec3<double> b, Transfers& log,
            cudaStream_t stream);

 private:
  DeviceArray<T> key_;             ///< t = |AP| / |AB| per triangle, +inf for a miss (n_tris)
  DeviceArray<T> min_key_;         ///< (1)
  DeviceArray<std::int64_t> min_index_;  ///< (1)
  DeviceArray<Hit> hit_;           ///< (1)
  DeviceArray<unsigned char> cub_temp_;
  PinnedArray<Hit> hit_host_;
};

}  // namespace tissue::gpu
