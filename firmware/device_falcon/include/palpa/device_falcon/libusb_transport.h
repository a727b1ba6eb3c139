// FalconTransport over libusb-1.0: the real Novint Falcon (USB 0403:cb48, FTDI bridge,
// interface 0, bulk EP 0x02 out / 0x81 in; docs/falcon.md §1). Synchronous transfers, each with
// a timeout (libusb counts in whole milliseconds: sub-millisecond timeouts round up to 1 ms).
// No kernel driver binds 0403:cb48 by default; if one does (ftdi_sio given the PID), it is detached.
//
// Non-RT: Open. Transfers: as FalconTransport; libusb-1.0 itself allocates one URB array per
// submitted transfer and takes its internal event lock (docs/falcon.md "Real-time notes").
#pragma once

#include <cstdint>
#include <expected>
#include <memory>
#include <string>

#include "palpa/device_falcon/transport.h"

struct libusb_context;
struct libusb_device_handle;

namespace palpa::device_falcon {

inline constexpr std::uint16_t kFalconVendorId = 0x0403;   ///< FTDI
inline constexpr std::uint16_t kFalconProductId = 0xCB48;  ///< Novint Falcon

/// Why Open failed.
enum class OpenError {
  kNotFound,    ///< no (or not enough) 0403:cb48 devices; message: "no Novint Falcon (USB 0403:cb48) found"
  kNoAccess,    ///< found but not openable by this user (udev rules)
  kBusy,        ///< interface 0 claimed by another program
  kUsbFailure,  ///< libusb could not start or another libusb error
};

struct OpenFailure {
  OpenError error = OpenError::kUsbFailure;
  std::string message;  ///< one or two sentences for people
};

class LibusbTransport final : public FalconTransport {
 public:
  /// Opens the `index`-th (0-based, in libusb's enumeration order) device with VID:PID
  /// 0403:cb48 and claims interface 0. Non-RT.
  static std::expected<std::unique_ptr<LibusbTransport>, OpenFailure> Open(int index);

  /// Number of attached 0403:cb48 devices (0 if libusb cannot start). Non-RT.
  static int CountDevices();

  ~LibusbTransport() override;

 private:
  LibusbTransport(libusb_context* ctx, libusb_device_handle* handle) : ctx_(ctx), handle_(handle) {}

  UsbStatus DoControlOut(std::uint8_t request, std::uint16_t value, int timeout_ms) override;
  UsbStatus DoBulkOut(std::span<const std::uint8_t> bytes, std::size_t& written, std::int64_t timeout_us) override;
  UsbStatus DoBulkIn(std::span<std::uint8_t> buf, std::size_t& got, std::int64_t timeout_us) override;
  std::int64_t DoNowNs() override;

  libusb_context* ctx_;
  libusb_device_handle* handle_;
  bool gone_ = false;  // LIBUSB_ERROR_NO_DEVICE seen: every later call fails fast
};

}  // namespace palpa::device_falcon
