// Message building for .cu files: nvcc's front end cannot compile fmt's
// compile-time format checks, so CUDA sources join message parts with
// str(...) (operator<< of each part) instead of fmt::format.
#pragma once

#include <sstream>
#include <string>

namespace tissue::gpu {

/// The parts streamed one after another into one string.
template <class... Parts>
std::string str(const Parts&... parts) {
  std::ostringstream out;
  (out << ... << parts);
  return out.str();
}

}  // namespace tissue::gpu
