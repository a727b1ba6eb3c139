// palpad's Falcon devices (--device falcon | virtual-falcon): open the transport (libusb or the
// virtual Falcon), bring the firmware up, home, hand the FalconDevice to the servo loop, and
// report afterwards. Non-RT; the servo loop only sees the HapticDevice.
#pragma once

#include <atomic>
#include <cstddef>
#include <expected>
#include <memory>
#include <string>
#include <vector>

#include "palpa/device_falcon/falcon_device.h"
#include "palpa/device_falcon/transport.h"
#include "palpa/device_virtual_falcon/virtual_falcon.h"
#include "palpa/palpad/options.h"
#include "palpa/servo/servo_loop.h"
#include "palpa/trace/trace.h"

namespace palpa::palpad {

/// A failure before the run: exit code (kExitBadInput, kExitNoDevice, kExitRunFailed) and message.
struct SessionFailure {
  int exit_code = kExitRunFailed;
  std::string message;
};

class FalconSession {
 public:
  /// Opens the device and configures it (firmware probe/upload). `trace` (virtual-falcon only)
  /// drives the virtual hand; `tick_limit` ends the run after that many ticks (0: until a signal).
  static std::expected<std::unique_ptr<FalconSession>, SessionFailure> Open(const Options& o,
                                                                            std::vector<trace::TraceSample> trace,
                                                                            std::size_t tick_limit);

  device::HapticDevice& device() { return *device_; }

  /// Homing (prompt on stderr), then Activate. Honours `stop`.
  std::expected<void, SessionFailure> Home(const std::atomic<bool>& stop, double timeout_s);

  /// After the run: zero torque and LEDs off, the fault message (if any) and the counters on
  /// stderr. Returns kExitRunFailed if the device faulted, else kExitOk.
  int Finish();

  /// palpad's fatal-signal hook (signals.h): a zero-torque packet, and for the virtual Falcon
  /// whether its motors now hold zero torque, one line each on fd 2. `self` is the session.
  static void EmergencyZero(void* self);

  ~FalconSession();

 private:
  FalconSession() = default;

  std::unique_ptr<device_falcon::FalconTransport> transport_;
  device_virtual_falcon::VirtualFalcon* virtual_ = nullptr;  // = transport_ for virtual-falcon
  std::unique_ptr<device_falcon::FalconDevice> device_;
};

}  // namespace palpa::palpad
