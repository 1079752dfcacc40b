// Device discovery and the measured copy bandwidth (the roofline reference).
#include <fmt/format.h>

#include <algorithm>
#include <stdexcept>
#include <vector>

#include "cuda/cuda_backend.hpp"
#include "cuda/device_array.hpp"

namespace tissue {

bool cuda_available(std::string* why) {
  std::string msg;
  int count = 0;
  const cudaError_t err = cudaGetDeviceCount(&count);
  bool ok = false;
  if (err != cudaSuccess) {
    cudaGetLastError();
    msg = fmt::format("no usable CUDA driver or device ({}: {})", cudaGetErrorName(err), cudaGetErrorString(err));
  } else if (count == 0) {
    msg = "no CUDA device found";
  } else {
    int dev = 0;
    cudaDeviceProp p;
    if (cudaGetDevice(&dev) != cudaSuccess || cudaGetDeviceProperties(&p, dev) != cudaSuccess) {
      cudaGetLastError();
      msg = "the CUDA device could not be queried";
    } else if (p.major < 9) {
      msg = fmt::format("{} has compute capability {}.{}; this build targets sm_90 (Hopper) and newer "
                        "(reconfigure with another CMAKE_CUDA_ARCHITECTURES)",
                        p.name, p.major, p.minor);
    } else {
      msg = p.name;
      ok = true;
    }
  }
  if (why) *why = msg;
  return ok;
}

double cuda_copy_bandwidth() {
  std::string why;
  if (!cuda_available(&why)) throw std::runtime_error("cuda_copy_bandwidth: " + why);
  constexpr size_t kBytes = size_t(512) << 20;
  gpu::DeviceArray<unsigned char> src(kBytes), dst(kBytes);
  gpu::Stream stream;
  gpu::Event start, stop;
  src.fill_bytes(1, stream.get());
  dst.fill_bytes(0, stream.get());
  std::vector<float> ms;
  for (int rep = 0; rep < 12; ++rep) {
    start.record(stream.get());
    CUDA_CHECK(cudaMemcpyAsync(dst.data(), src.data(), kBytes, cudaMemcpyDeviceToDevice, stream.get()));
    stop.record(stream.get());
    stop.sync();
    if (rep >= 2) ms.push_back(stop.since(start));  // the first copies warm up
  }
  std::sort(ms.begin(), ms.end());
  const double seconds = ms[ms.size() / 2] * 1e-3;
  return 2.0 * kBytes / seconds;
}

}  // namespace tissue
