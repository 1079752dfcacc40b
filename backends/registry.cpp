#include "backends/registry.hpp"

#include <algorithm>
#include <stdexcept>

#include "cpu/cpu_backend.hpp"
#include "cpu/element_lanes.hpp"
#ifdef TISSUE_HAVE_CUDA
#include "cuda/cuda_backend.hpp"
#endif

namespace tissue {

#ifdef TISSUE_HAVE_CUDA
namespace {
/// BackendInfo::float_math of this build's cuda float kernels.
std::string cuda_float_math() { return cuda_fast_float_math() ? "approximate" : "ieee"; }
}  // namespace
#endif

std::vector<BackendInfo> list_backends() {
  std::vector<BackendInfo> out;
  out.push_back({"cpu", true, true, cpu_device_name(), "ieee", cpu::to_string(cpu::lanes_tuning())});
#ifdef TISSUE_HAVE_CUDA
  std::string why;
  const bool gpu = cuda_available(&why);
  out.push_back({"cuda", true, gpu, why, cuda_float_math()});
#else
  out.push_back({"cuda", false, false, "not built: configure with -DTISSUE_WITH_CUDA=ON on a machine with the CUDA toolkit"});
#endif
  return out;
}

std::unique_ptr<Backend> create_backend(const std::string& name, Precision precision) {
  if (name == "cpu") return make_cpu_backend(precision);
  if (name == "cuda") {
#ifdef TISSUE_HAVE_CUDA
    std::string why;
    if (!cuda_available(&why)) throw std::runtime_error("backend 'cuda' cannot run here: " + why);
    return make_cuda_backend(precision);
#else
    throw std::runtime_error(
        "backend 'cuda' was not built: configure with -DTISSUE_WITH_CUDA=ON on a machine with the CUDA toolkit");
#endif
  }
  throw std::runtime_error("unknown backend '" + name + "' (known: cpu, cuda)");
}

double measure_device_bandwidth(const std::string& name) {
#ifdef TISSUE_HAVE_CUDA
  if (name == "cuda") return cuda_copy_bandwidth();
#endif
  (void)name;
  return 0;
}

std::string element_gradients(Backend& backend) {
#ifdef TISSUE_HAVE_CUDA
  if (backend.name() == "cuda") return to_string(cuda_gradients(backend));
#endif
  (void)backend;
  return "stored";
}

std::vector<std::pair<std::string, double>> contact_chain_times(const std::string& backend, Precision precision) {
  std::vector<std::pair<std::string, double>> out;
#ifdef TISSUE_HAVE_CUDA
  if (backend == "cuda") {
    const CudaContactChains c = cuda_contact_chains(precision);
    const auto both = [&](const std::string& name, double cycles) {
      out.emplace_back(name + "_us", cycles / c.clock_mhz);
      out.emplace_back(name + "_cycles", cycles);
    };
    out.emplace_back("clock_mhz", c.clock_mhz);
    both("test", c.test_cycles);
    both("sweep_corners_inside", c.sweep_pushed_cycles);
    both("sweep_face_only", c.sweep_face_cycles);
    for (int m = 0; m < 3; ++m) both("merge_" + std::to_string(c.merge_counts[m]), c.merge_cycles[m]);
    // what no arrangement of the stage's kernels goes below
    out.emplace_back("chain_per_step_us", c.chain_per_step_us);
  }
#endif
  (void)backend;
  (void)precision;
  return out;
}

std::shared_ptr<BackendGroup> make_backend_group(const std::string& name, Precision precision, int scenes,
                                                std::size_t scene_bytes) {
#ifdef TISSUE_HAVE_CUDA
  if (name == "cuda" && scenes >= 2) return make_cuda_scene_group(precision, std::min(scenes, kMaxCudaGroupScenes), scene_bytes);
#endif
  (void)name;
  (void)precision;
  (void)scenes;
  (void)scene_bytes;
  return nullptr;
}

int max_group_scenes(const std::string& name) {
#ifdef TISSUE_HAVE_CUDA
  if (name == "cuda") return kMaxCudaGroupScenes;
#endif
  (void)name;
  return 0;
}

void join_backend_group(Backend& backend, const std::shared_ptr<BackendGroup>& group, int slot) {
#ifdef TISSUE_HAVE_CUDA
  if (backend.name() == "cuda") return join_cuda_scene_group(backend, group, slot);
#endif
  (void)group;
  (void)slot;
  throw std::invalid_argument("backend '" + backend.name() + "' steps no scene groups");
}

std::string backend_tuning(const Backend& backend) {
  return backend.name() == "cpu" ? cpu::to_string(cpu::lanes_tuning()) : "";
}

std::vector<std::string> step_modes(const Backend& backend) {
#ifdef TISSUE_HAVE_CUDA
  if (backend.name() == "cuda") return {"auto", "launch", "graph", "grid", "cluster"};
#endif
  (void)backend;
  return {"auto"};
}

void set_step_mode(Backend& backend, const std::string& mode) {
#ifdef TISSUE_HAVE_CUDA
  if (backend.name() == "cuda") {
    for (CudaStepMode m :
         {CudaStepMode::Auto, CudaStepMode::Launch, CudaStepMode::Graph, CudaStepMode::Grid, CudaStepMode::Cluster})
      if (mode == to_string(m)) return set_cuda_step_mode(backend, m);
  }
#endif
  if (mode == "auto") return;
  throw std::invalid_argument("step mode '" + mode + "': the " + backend.name() + " backend has none of that name");
}

std::string step_mode(Backend& backend) {
#ifdef TISSUE_HAVE_CUDA
  if (backend.name() == "cuda") return to_string(cuda_step_mode(backend));
#endif
  (void)backend;
  return "auto";
}

void set_element_gradients(Backend& backend, const std::string& where) {
#ifdef TISSUE_HAVE_CUDA
  if (backend.name() == "cuda") {
    for (CudaGradients g : {CudaGradients::Auto, CudaGradients::Stored, CudaGradients::Recomputed})
      if (where == to_string(g)) return set_cuda_gradients(backend, g);
  }
#endif
  if (where == "auto" || where == "stored") return;
  throw std::invalid_argument("element gradients '" + where + "': the " + backend.name() +
                              " backend takes auto or stored" + (backend.name() == "cuda" ? " or recomputed" : ""));
}

DeviceField device_field(Backend& backend, NodeField field) {
#ifdef TISSUE_HAVE_CUDA
  if (backend.name() == "cuda") {
    const CudaNodeField f = cuda_node_field(backend, field == NodeField::Displacement ? 0 : 1);
    return {f.data, f.nodes, f.node_stride, f.scalar_bytes, f.device};
  }
#endif
  (void)backend;
  (void)field;
  return {};
}

void copy_from_device(const void* src, void* dst, std::size_t bytes) {
#ifdef TISSUE_HAVE_CUDA
  return cuda_copy_to_host(src, dst, bytes);
#else
  (void)src;
  (void)dst;
  (void)bytes;
  throw std::invalid_argument("a device array: this build has no cuda backend (configure with -DTISSUE_WITH_CUDA=ON)");
#endif
}

std::string float_math(const Backend& backend) {
#ifdef TISSUE_HAVE_CUDA
  if (backend.name() == "cuda" && backend.precision() == Precision::Float) return cuda_float_math();
#endif
  (void)backend;
  return "ieee";
}

}  // namespace tissue
