// The tool contact of the cuda backend outside the step loop (the per-step
// kernels are cuda/contact.cuh, run by the stepper): the tools' motion in
// device memory (one small upload per advance), grasp start and release,
// the region's contact candidates and the contact list (the per-tool
// reductions are part of cuda/reduce.cu's kernel). The rule is
// core/contact.hpp's (docs/contact.md).
#pragma once

#include <cuda_runtime.h>

#include <vector>

#include "core/backend.hpp"
#include "cuda/device_array.hpp"
#include "cuda/views.hpp"

namespace tissue::gpu {

/// One surface node's contact as DeviceContact::contacts downloads it.
struct ContactRecord {
  index_t node;
  signed char tool;
  std::uint8_t kind;
  float normal[3];
};

template <class T>
class DeviceContact {
 public:
  /// Scratch for a mesh of this size.
  void allocate(index_t n_nodes, index_t n_surf);

  /// Queues the upload of the tools' motion over the next steps (pinned
  /// staging, guarded by an event); returns the device copy the kernels read.
  const ContactTools<T>* upload(const ContactTools<T>& tools, Transfers& log, cudaStream_t stream);
  /// upload() in two parts, for a graph that the caller synchronises
  /// before the next stage(): stage() writes the pinned staging (once its
  /// last upload has been read) and returns the bytes to copy;
  /// enqueue_copy() queues that copy (in a graph: its memcpy node).
  std::size_t stage(const ContactTools<T>& tools);
  void enqueue_copy(std::size_t bytes, cudaStream_t stream);
  const ContactTools<T>* device_tools() const { return tools_.data(); }

  /// Queues the check whether the uploaded tools' candidate sweep (tools as
  /// one step, ContactTools::sweep_substeps) reaches a surface node that is
  /// not an inner region node, the test of candidates(), at u: reach() is
  /// then non-zero (device memory), and so is reach_host() (pinned, mapped:
  /// the kernel writes it too), which the caller zeroes before the check.
  void enqueue_reach_check(const ModelView<T>& m, const StateView<T>& s, const Packed3<T>* u, cudaStream_t stream);
  const int* reach() const { return reach_.data(); }
  int* reach_host() { return reach_host_.data(); }

  /// Tool `tool` at tip (m) grasps its pushed nodes (offsets from the tip).
  void begin_grasp(const ModelView<T>& m, const StateView<T>& s, const Packed3<T>* u, int tool, Vec3<double> tip,
                   cudaStream_t stream);
  /// Releases tool `tool`'s grasped nodes.
  void end_grasp(const ModelView<T>& m, const StateView<T>& s, int tool, cudaStream_t stream);
  /// Forgets every contact and grasp.
  void reset(const ModelView<T>& m, const StateView<T>& s, cudaStream_t stream);

  /// Surface nodes, not inner region nodes, within 1.5 radii of the sweep's
  /// sub-check capsules (current u), ascending: one count comes back, and
  /// the list when it is not empty.
  std::vector<index_t> candidates(const ModelView<T>& m, const StateView<T>& s, const Packed3<T>* u,
                                  const ContactTools<T>& sweep, Transfers& log, cudaStream_t stream);

  /// Every surface node in contact (downloads one record per surface node).
  std::vector<ContactNode> contacts(const ModelView<T>& m, const StateView<T>& s, Transfers& log,
                                    cudaStream_t stream);

 private:
  DeviceArray<ContactTools<T>> tools_;       ///< (1)
  PinnedArray<ContactTools<T>> tools_host_;  ///< its staging
  Event tools_copied_;                       ///< the staging has been read
  bool tools_pending_ = false;
  DeviceArray<std::uint8_t> flag_;           ///< candidates: per node (n_nodes), then per surface node (n_surf)
  DeviceArray<std::uint8_t> flag_surf_;
  DeviceArray<index_t> selected_;            ///< (n_surf)
  DeviceArray<int> n_selected_;              ///< (1)
  PinnedArray<int> n_selected_host_;
  DeviceArray<unsigned char> cub_temp_;
  DeviceArray<ContactRecord> records_;              ///< (n_surf)
  DeviceArray<int> reach_;                          ///< enqueue_reach_check's answer (1)
  PinnedArray<int> reach_host_;
};

}  // namespace tissue::gpu
