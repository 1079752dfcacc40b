// Contact between bodies on the cuda backend (core/body_contact.hpp's rule):
// the host-built candidate lists in device memory behind one device-resident
// view (BodyView: a rebuild replaces the arrays and rewrites the view, so the
// captured graphs, which hold only the view's address, stay valid), and per
// TLED step four kernels over the rows: each row's hit, each node's count of
// contacts, each hit's scale, then each row's move (a node's own hit and its
// shares as a corner of others', in list order: the same sums as the cpu's). After an advance's steps a third kernel flags, in
// mapped host memory, a listed node that has left a quarter of the skin; the
// backend rebuilds the lists before its next steps.
#pragma once

#include <cuda_runtime.h>

#include <vector>

#include "core/backend.hpp"
#include "core/body_contact.hpp"
#include "core/model.hpp"
#include "cuda/device_array.hpp"
#include "cuda/views.hpp"

namespace tissue::gpu {

/// The lists as the kernels read them (one copy in device memory).
template <class T>
struct BodyView {
  index_t rows = 0;
  T reach = 0;                          ///< m: the lists' skin
  T stale2 = 0;                         ///< m^2: (skin / 4)^2, the rebuild's trigger
  const index_t* node = nullptr;        ///< (rows)
  const index_t* cand_start = nullptr;  ///< (rows + 1)
  const index_t* cand_tri = nullptr;
  const T* cand_mu = nullptr;
  const index_t* cand_rows = nullptr;   ///< 3 per candidate
  const index_t* corner_start = nullptr;  ///< (rows + 1)
  const index_t* corner_cand = nullptr;
  const index_t* corner_row = nullptr;
  const std::uint8_t* corner_slot = nullptr;
  const Packed3<T>* x_built = nullptr;  ///< (rows)
  BodyHit<T>* hits = nullptr;           ///< (rows): the current step's
  BodyAnchor<T>* anchors = nullptr;     ///< (rows): the stick anchors, carried across steps and rebuilds
  T* counts = nullptr;                  ///< (rows): the current step's weighted contacts per node
  int* stale = nullptr;                 ///< mapped host memory: 1 = rebuild before the next steps
};

/// What the stepper needs to queue the kernels: the view's address and the rows (the grid).
template <class T>
struct BodySteps {
  const BodyView<T>* view = nullptr;
  index_t rows = 0;
};

/// The step's four kernels (after pass 4, before the tools' contact stage).
template <class T>
void enqueue_body_step(const ModelView<T>& m, const StateView<T>& s, BodySteps<T> body, StepBuffers<T> b,
                       cudaStream_t stream);
/// The staleness check at u (after an advance's steps).
template <class T>
void enqueue_body_check(const ModelView<T>& m, const StateView<T>& s, BodySteps<T> body, const Packed3<T>* u,
                        cudaStream_t stream);

template <class T>
class DeviceBodyContact {
 public:
  /// Lists for spec over the mesh (its surface: X, tris, surf_nodes) at positions x (3 per node).
  void set(const TissueModel<double>& mesh, const BodyContactSpec& spec, const std::vector<double>& x, Transfers& log,
           cudaStream_t stream);
  bool active() const { return rows_ > 0 || !spec_.empty(); }
  void clear();
  /// Whether the last steps flagged a rebuild (read after the stream is done).
  bool stale() const { return stale_.size() > 0 && stale_host()[0] != 0; }
  /// Forgets every stick anchor (a new initial state).
  void clear_anchors(cudaStream_t stream) { anchors_.fill_bytes(0xff, stream); }  // tri -1
  /// Rebuilds at positions x and clears the flag.
  void rebuild(const TissueModel<double>& mesh, const std::vector<double>& x, Transfers& log, cudaStream_t stream);
  BodySteps<T> steps() const { return {view_.data(), rows_}; }
  /// The rows inside another body at the last step (downloads the hits).
  std::vector<BodyContactNode> contacts(Transfers& log, cudaStream_t stream);
  long builds() const { return builds_; }

 private:
  int* stale_host() const { return const_cast<PinnedArray<int>&>(stale_).data(); }
  BodyContactSpec spec_;
  BodyLists lists_;
  index_t rows_ = 0;
  long builds_ = 0;
  DeviceArray<index_t> node_, cand_start_, cand_tri_, cand_rows_, corner_start_, corner_cand_, corner_row_;
  DeviceArray<T> counts_;
  DeviceArray<T> cand_mu_;
  DeviceArray<std::uint8_t> corner_slot_;
  DeviceArray<Packed3<T>> x_built_;
  DeviceArray<BodyHit<T>> hits_;
  DeviceArray<BodyAnchor<T>> anchors_;
  DeviceArray<BodyView<T>> view_;
  PinnedArray<int> stale_;
};

}  // namespace tissue::gpu
