#include "apps/viewer/phantom_device.hpp"

#include <fmt/format.h>

#include <stdexcept>

#if defined(TISSUE_HAVE_OPENHAPTICS)
#include <HD/hd.h>

#include <mutex>
#endif

namespace tissue::viewer {

#if defined(TISSUE_HAVE_OPENHAPTICS)

namespace {

std::string hd_error_text(const HDErrorInfo& e, const char* what) {
  return fmt::format("OpenHaptics: {} failed: {} (HD error {:#x}, internal {})", what, hdGetErrorString(e.errorCode),
                     static_cast<unsigned>(e.errorCode), e.internalErrorCode);
}

void check(const char* what) {
  const HDErrorInfo e = hdGetError();
  if (HD_DEVICE_ERROR(e)) throw std::runtime_error(hd_error_text(e, what));
}

/// The HD device and its servo callback.
class PhantomDevice : public Device {
 public:
  explicit PhantomDevice(const WorkspaceMap& map) : map_(map) {
    hhd_ = hdInitDevice(HD_DEFAULT_DEVICE);
    check("hdInitDevice(HD_DEFAULT_DEVICE)");
    hdMakeCurrentDevice(hhd_);
    hdGetDoublev(HD_NOMINAL_MAX_FORCE, &max_force_);
    hdEnable(HD_FORCE_OUTPUT);
    check("hdEnable(HD_FORCE_OUTPUT)");
    callback_ = hdScheduleAsynchronous(&PhantomDevice::servo, this, HD_DEFAULT_SCHEDULER_PRIORITY);
    hdStartScheduler();
    try {
      check("hdStartScheduler");
    } catch (...) {
      hdUnschedule(callback_);
      hdDisableDevice(hhd_);
      throw;
    }
  }

  ~PhantomDevice() override {
    hdStopScheduler();
    hdUnschedule(callback_);
    hdDisableDevice(hhd_);
  }

  double max_force() const { return max_force_; }

  /// The stylus tip, its axis (the gimbal's z axis, tip to handle) and the
  /// first stylus button as the grasp button.
  ToolInput read(double) override {
    std::lock_guard lk(mutex_);
    if (!error_.empty()) throw std::runtime_error(error_);
    return {map_.origin + (map_.scale * 1e-3) * position_mm_, axis_, grasp_};
  }

  void send_force(const Vec3<double>& force) override {
    std::lock_guard lk(mutex_);
    force_ = force;
  }

 private:
  /// The servo thread's callback (1 kHz): read the stylus, write the force.
  static HDCallbackCode HDCALLBACK servo(void* self_ptr) {
    auto* self = static_cast<PhantomDevice*>(self_ptr);
    HDdouble p[3], f[3], m[16];
    HDint buttons = 0;
    hdBeginFrame(self->hhd_);
    hdGetDoublev(HD_CURRENT_POSITION, p);
    hdGetDoublev(HD_CURRENT_TRANSFORM, m);  // column-major; column 2 is the stylus axis
    hdGetIntegerv(HD_CURRENT_BUTTONS, &buttons);
    {
      std::lock_guard lk(self->mutex_);
      self->position_mm_ = {p[0], p[1], p[2]};
      self->axis_ = unit_or(Vec3<double>{m[8], m[9], m[10]}, Vec3<double>{0, 0, 0});
      self->grasp_ = (buttons & HD_DEVICE_BUTTON_1) != 0;
      f[0] = self->force_.x;
      f[1] = self->force_.y;
      f[2] = self->force_.z;
    }
    hdSetDoublev(HD_CURRENT_FORCE, f);
    hdEndFrame(self->hhd_);
    const HDErrorInfo e = hdGetError();
    if (HD_DEVICE_ERROR(e)) {  // e.g. the device faulted or overheated: stop servoing, fail the next tick
      std::lock_guard lk(self->mutex_);
      self->error_ = hd_error_text(e, "the servo loop");
      return HD_CALLBACK_DONE;
    }
    return HD_CALLBACK_CONTINUE;
  }

  WorkspaceMap map_;
  HHD hhd_ = HD_INVALID_HANDLE;
  HDSchedulerHandle callback_ = 0;
  HDdouble max_force_ = 0;
  std::mutex mutex_;
  Vec3<double> position_mm_ = {0, 0, 0};
  Vec3<double> axis_ = {0, 0, 0};
  bool grasp_ = false;
  Vec3<double> force_ = {0, 0, 0};
  std::string error_;  ///< set by the servo callback when the device fails
};

}  // namespace

bool phantom_built() { return true; }

std::unique_ptr<Device> make_phantom_device(const WorkspaceMap& map, double* max_force) {
  auto dev = std::make_unique<PhantomDevice>(map);
  if (max_force) *max_force = dev->max_force();
  return dev;
}

#else

bool phantom_built() { return false; }

std::unique_ptr<Device> make_phantom_device(const WorkspaceMap&, double*) {
  throw std::runtime_error(
      "the phantom device needs OpenHaptics, which this build did not find: install the OpenHaptics SDK (HD/hd.h, "
      "libHD) and re-run cmake (-DOPENHAPTICS_ROOT=<dir> if it is not in a system path); see docs/viewer.md");
}

#endif

}  // namespace tissue::viewer
