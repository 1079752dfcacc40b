// The adapter point for real haptic hardware: a Phantom / Omni / Touch
// through the OpenHaptics HD API. Built only when CMake finds HD/hd.h and
// libHD (apps/viewer/CMakeLists.txt: find_path / find_library, or
// -DOPENHAPTICS_ROOT=...); otherwise make_phantom_device() throws and says
// how to enable it. docs/viewer.md describes the set-up.
//
// Threads: OpenHaptics runs its own 1 kHz servo thread (the HD scheduler).
// Its callback, scheduled with hdScheduleAsynchronous, reads the stylus
// position (hdGetDoublev(HD_CURRENT_POSITION), mm, device frame) and writes
// the latest force (hdSetDoublev(HD_CURRENT_FORCE), N) inside
// hdBeginFrame/hdEndFrame; the haptic loop exchanges position and force
// with it through a mutex-protected pair, so the force reaches the motors at
// the next servo tick (at most one period of added latency).
#pragma once

#include <memory>
#include <string>

#include "core/device.hpp"

namespace tissue::viewer {

/// Maps the device's workspace onto the scene: p_scene = origin + scale * p_device
/// (p_device in m; the device frame's axes are the scene's).
struct WorkspaceMap {
  Vec3<double> origin = {0, 0, 0};  ///< scene point of the device's workspace centre (m)
  double scale = 1.0;               ///< scene metres per device metre
};

/// True when this build has the OpenHaptics adapter.
bool phantom_built();

/// Opens the default OpenHaptics device, enables force output and starts
/// its servo loop. *max_force receives the device's nominal maximum force
/// (HD_NOMINAL_MAX_FORCE, N). Throws std::runtime_error with the HD error
/// text, or, when not built, naming what to install.
std::unique_ptr<Device> make_phantom_device(const WorkspaceMap& map, double* max_force);

}  // namespace tissue::viewer
