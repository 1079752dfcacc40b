// The per-tick reductions over the region (core Reductions), in one kernel
// after passes 1-2 (the strain energy's): reaction on the
// tool-driven components, internal force and residual parts over inner
// nodes (per held / free component), kinetic energy and max displacement
// over region nodes, the front ring's displacement, the strain energy of the
// computed elements at the current u, the Prony terms' viscous power and
// stored energy, the per-tool contact results over the surface, and the
// bad-element flag (read and cleared). Accumulated in double in two
// deterministic stages: each block's partials in a fixed order, then the
// block that finishes last combines all blocks' partials in block order
// (the partials and their order depend only on the region, not on which
// block is last). One struct comes back.
#pragma once

#include <cuda_runtime.h>

#include <vector>

#include "core/backend.hpp"
#include "cuda/device_array.hpp"
#include "cuda/views.hpp"

namespace tissue::gpu {

/// One block's (or thread's) partial sums, all in double.
struct ReducePartial {
  double reaction[3];
  double internal[3];
  double free2, held2, kinetic, max_disp, front_disp, energy;
  double visco_power, visco_stored;  ///< the Prony terms' (core/energy.hpp element_prony_energy)
  int nonfinite;  ///< region nodes with a non-finite u, f or velocity
};

/// One tool's partial sums of the contact reduction (double): the fields of
/// core's ToolReduction without its default member initialisers, which a
/// __shared__ array (the block sums) cannot have.
struct ToolPartial {
  double reaction[3];
  int contact, grasped, rigid, rigid_first, outside;
  int pad;  ///< (a whole number of 8-byte words)
};

/// Per-tool partial sums of the contact reduction: one per thread, then one
/// per block.
struct ContactPartial {
  ToolPartial tool[kMaxTools];
};

/// The front ring of the region: nodes whose flood-fill ring equals depth
/// (ring == nullptr: no front, the whole mesh).
struct FrontView {
  const int* ring = nullptr;  ///< (n_nodes)
  int depth = 0;
};

template <class T>
class Reducer {
 public:
  /// Partials and result.
  void allocate(cudaStream_t stream);
  /// The model's law terms: the fibre term's energy (LawView::fibre; null:
  /// none) and the Prony terms' power and stored energy (null visco_slot: none).
  void set_law(const LawView<T>& law) { law_ = law; }

  /// Whether the reduction runs passes 1-2 (IANP, a region with elements).
  static bool runs_passes(const ModelView<T>& m, const RegionView& r) { return m.ianp && r.n_elems > 0; }

  /// Reduces over region r with the current buffers b, and the tools'
  /// contact over the surface (`tools`: the last advance's, whose friction
  /// coefficients the reactions use; null: no tools); clears the bad flag;
  /// one download.
  /// For IANP the energy needs the nodal pressures at the current u: passes
  /// 1 and 2 run again over the region into `scratch` (the state view s
  /// with the scratch set of pass arrays: DeviceStore::pressure_scratch;
  /// the state's own stay as the last step wrote them). Its entries outside
  /// the region must already be the state's (the caller's copy), so that
  /// the next steps can take the set as theirs.
  Reductions run(const ModelView<T>& m, const StateView<T>& s, const StateView<T>& scratch, const RegionView& r,
                 FrontView front, StepBuffers<T> b, const ContactTools<T>* tools, Transfers& log,
                 cudaStream_t stream);

  /// run()'s kernels without the download: the result stays in device
  /// memory (result()) and, with to_host, the kernel also writes it into
  /// result_host() (mapped): no copy, readable once the stream has finished.
  void enqueue(const ModelView<T>& m, const StateView<T>& s, const StateView<T>& scratch, const RegionView& r,
               FrontView front, StepBuffers<T> b, const ContactTools<T>* tools, cudaStream_t stream,
               bool to_host = false);
  const Reductions* result() const { return result_.data(); }
  /// The device arrays its kernel writes (a scene group checks that they lie in the scene's slot).
  std::vector<const void*> device_arrays() const {
    return {partial_.data(), contact_partial_.data(), touched_.data(), done_.data(), result_.data()};
  }
  /// Pinned, mapped host memory for the result's download.
  Reductions* result_host() { return result_host_.data(); }

 private:
  DeviceArray<int> partial_;            ///< one ReducePartial per block, as columns (reduce.cu store_columns)
  DeviceArray<int> contact_partial_;    ///< one ContactPartial per block, likewise (only blocks that met a contact)
  DeviceArray<unsigned> touched_;       ///< per block: a bit per tool it met (0: it stored no contact partial)
  DeviceArray<unsigned> done_;          ///< blocks finished (the last one resets it to 0)
  DeviceArray<Reductions> result_;      ///< (1)
  PinnedArray<Reductions> result_host_;
  LawView<T> law_;
};

}  // namespace tissue::gpu
