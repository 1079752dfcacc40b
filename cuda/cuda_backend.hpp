// The cuda backend. This header has no CUDA includes: the registry and the
// apps see only the Backend interface.
#pragma once

#include <memory>
#include <string>

#include "core/backend.hpp"

namespace tissue {

std::unique_ptr<Backend> make_cuda_backend(Precision precision);

/// True when a CUDA device can be used; otherwise *why says why not.
/// On success *why holds the device name.
bool cuda_available(std::string* why);

}  // namespace tissue
