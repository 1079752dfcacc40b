// The per-tick reductions over the region (core Reductions): reaction on the
// tool-driven nodes, internal force and residual parts over inner nodes,
// kinetic energy and max displacement over region nodes, the bad-element
// flag (read and cleared). Accumulated in double in two deterministic
// stages (fixed-order block partials, then one block), one struct back.
#pragma once

#include <cuda_runtime.h>

#include "core/backend.hpp"
#include "cuda/device_array.hpp"
#include "cuda/views.hpp"

namespace tissue::gpu {

/// One block's (or thread's) partial sums, all in double.
struct ReducePartial {
  double reaction[3];
  double internal[3];
  double free2, held2, kinetic, max_disp;
  int nonfinite;  ///< region nodes with a non-finite u or f
};

template <class T>
class Reducer {
 public:
  void allocate();
  /// Reduces over region r with the current buffers b; clears the bad flag.
  Reductions run(const ModelView<T>& m, const StateView<T>& s, const RegionView& r, StepBuffers<T> b,
                 Transfers& log, cudaStream_t stream);

 private:
  DeviceArray<ReducePartial> partial_;  ///< one per stage-1 block
  DeviceArray<Reductions> result_;      ///< (1)
  PinnedArray<Reductions> result_host_;
};

}  // namespace tissue::gpu
