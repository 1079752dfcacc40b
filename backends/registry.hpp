// Names and creates backends ("cpu", "cuda") and reports which this build and
// this machine can run.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "core/backend.hpp"

namespace tissue {

struct BackendInfo {
  std::string name;
  bool built = false;      ///< compiled into this binary
  bool available = false;  ///< built and usable on this machine (a GPU is present, ...)
  std::string detail;      ///< device name, or why it is unavailable
  /// How its float kernels divide and take square roots: "ieee" (IEEE
  /// round-to-nearest) or "approximate" (the cuda build's
  /// TISSUE_CUDA_FAST_FLOAT_MATH; docs/cuda.md). Double is IEEE on both.
  std::string float_math = "ieee";
  /// The tuning of its host kernels: the cpu's lane kernels, "xeon" or
  /// "generic" (TISSUE_CPU_TUNING overrides); "" where there is none.
  std::string tuning;
};

/// Every known backend, built or not.
std::vector<BackendInfo> list_backends();

/// Creates a backend; throws std::runtime_error naming the CMake option to
/// turn on when it was not built, or why it cannot run here.
std::unique_ptr<Backend> create_backend(const std::string& name, Precision precision);

/// Measured device-memory copy bandwidth of a device backend (bytes/s,
/// read + write counted); 0 for host backends (measure the host instead).
double measure_device_bandwidth(const std::string& name);

/// Where the backend's element passes get the element gradients and
/// volumes of its uploaded model: "stored" (loaded), or "recomputed" from
/// the reference positions (the cuda backend's CudaGradients).
std::string element_gradients(Backend& backend);

/// The contact stage's parts timed alone on a device backend (the cuda
/// backend's cuda_contact_chains, in `precision`), as named microseconds at
/// the device's peak clock and their cycles; empty for a backend that has no
/// such measurement (the cpu: its stage is timed in whole steps).
std::vector<std::pair<std::string, double>> contact_chain_times(const std::string& backend, Precision precision);

/// BackendInfo::tuning of a backend.
/// A group in which the named backend steps `scenes` scenes of one model as
/// one (BackendGroup), each taking at most `scene_bytes` of device memory;
/// null where the backend has no groups (the cpu) or for fewer than two
/// scenes. max_group_scenes: the most one group holds (0: none).
std::shared_ptr<BackendGroup> make_backend_group(const std::string& name, Precision precision, int scenes,
                                                std::size_t scene_bytes);
int max_group_scenes(const std::string& name);
/// Makes `backend`, before its upload, scene `slot` of `group`.
void join_backend_group(Backend& backend, const std::shared_ptr<BackendGroup>& group, int slot);

std::string backend_tuning(const Backend& backend);

/// The ways a backend can run advance() (all give the same results): the
/// cuda backend's step modes "auto", "launch", "graph", "grid", "cluster"
/// (docs/cuda.md); {"auto"} for a backend with one way.
std::vector<std::string> step_modes(const Backend& backend);
/// Selects one of step_modes(); std::invalid_argument naming the mode when
/// the backend or its device does not have it.
void set_step_mode(Backend& backend, const std::string& mode);
/// The mode advance() uses for the current region ("auto" resolved).
std::string step_mode(Backend& backend);
/// Where the next upload() puts the element gradients: "auto", "stored" or
/// "recomputed" (the cuda backend's CudaGradients); a host backend stores
/// them and takes "auto" and "stored" only. std::invalid_argument otherwise.
void set_element_gradients(Backend& backend, const std::string& where);

/// BackendInfo::float_math of the backend at its precision: "approximate"
/// for the cuda backend in float where the build chose it, else "ieee".
std::string float_math(const Backend& backend);

/// A per-node field as it lies in a device backend's memory: 3 scalars a
/// node (scalar_bytes each), nodes node_stride bytes apart (padding after
/// the three), on CUDA device `device`. Valid until the backend's next
/// step, reset, upload or region build (the displacement buffers rotate
/// with every step). Null data where the backend keeps its fields on the
/// host.
struct DeviceField {
  const void* data = nullptr;
  std::int64_t nodes = 0, node_stride = 0;
  int scalar_bytes = 0;
  int device = -1;
};
enum class NodeField { Displacement, InternalForce };
DeviceField device_field(Backend& backend, NodeField field);

/// Copies `bytes` from device memory at `src` (a CUDA device pointer) to
/// the host; refuses a pointer that is not device memory.
void copy_from_device(const void* src, void* dst, std::size_t bytes);

}  // namespace tissue
