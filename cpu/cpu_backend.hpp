// The cpu backend: a persistent thread team over fixed slices of the region
// (cpu/thread_team.hpp; TBB for the one-off whole-mesh passes), Embree for
// the tool-segment query against the deformed surface.
#pragma once

#include <memory>
#include <string>

#include "core/backend.hpp"

namespace tissue {

std::unique_ptr<Backend> make_cpu_backend(Precision precision);

/// The processor's name and thread count, for reports.
std::string cpu_device_name();

}  // namespace tissue
