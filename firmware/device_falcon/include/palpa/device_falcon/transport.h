// The byte pipe to a Novint Falcon: an FTDI USB-serial bridge seen as vendor control requests
// plus two bulk endpoints (OUT 0x02, IN 0x81). Backends: libusb-1.0 (libusb_transport.h) and the
// virtual Falcon (firmware/device_virtual_falcon/), which consumes and produces the same bytes.
// The codec, firmware loader and FalconDevice run unchanged on either.
//
// NVI (house style §7): the public methods check their arguments and call the private Do*.
// Every call is bounded by its timeout; none blocks longer. Thread rules: one thread at a time
// (the start-up thread, then the servo thread). RT contract of a backend: no allocation, lock or
// exception of its own in BulkOut/BulkIn/NowNs beyond the USB transfer itself (docs/falcon.md
// "Real-time notes" says what libusb does inside).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

namespace palpa::device_falcon {

/// Result of one transport call.
enum class UsbStatus {
  kOk,        ///< done (a bulk IN may still carry only the 2 FTDI status bytes)
  kTimeout,   ///< nothing (more) within the timeout; partial data, if any, is reported
  kNoDevice,  ///< the device is gone (unplugged); every later call fails the same way
  kIoError,   ///< any other transfer failure (pipe stall, overflow, protocol error)
};

/// One-word description for messages: "ok", "timeout", "no device", "I/O error".
const char* UsbStatusName(UsbStatus s);

/// Bulk endpoints of the Falcon's FTDI bridge (docs/falcon.md §1.2).
inline constexpr std::uint8_t kEndpointOut = 0x02;
inline constexpr std::uint8_t kEndpointIn = 0x81;
/// Bytes asked for per bulk IN: one full-speed packet (libnifalcon: "over 64 fries libusb-1.0").
inline constexpr std::size_t kBulkInBytes = 64;

class FalconTransport {
 public:
  FalconTransport() = default;
  FalconTransport(const FalconTransport&) = delete;
  FalconTransport& operator=(const FalconTransport&) = delete;
  virtual ~FalconTransport() = default;

  /// FTDI vendor request, host→device, no data stage: bmRequestType 0x40, bRequest `request`,
  /// wValue `value`, wIndex 0 (ftdi.h names them).
  UsbStatus ControlOut(std::uint8_t request, std::uint16_t value, int timeout_ms) {
    return DoControlOut(request, value, timeout_ms < 1 ? 1 : timeout_ms);
  }

  /// Bulk OUT on EP 0x02. `written` gets the bytes the device took.
  UsbStatus BulkOut(std::span<const std::uint8_t> bytes, std::size_t& written, std::int64_t timeout_us) {
    written = 0;
    if (bytes.empty()) return UsbStatus::kOk;
    return DoBulkOut(bytes, written, timeout_us < 1 ? 1 : timeout_us);
  }

  /// One bulk IN transfer on EP 0x81 into `buf` (at most kBulkInBytes used): raw bytes, FTDI
  /// status bytes included (the codec strips them). `got` = bytes received (0 on timeout).
  UsbStatus BulkIn(std::span<std::uint8_t> buf, std::size_t& got, std::int64_t timeout_us) {
    got = 0;
    if (buf.size() > kBulkInBytes) buf = buf.first(kBulkInBytes);
    if (buf.size() < 2) return UsbStatus::kIoError;
    return DoBulkIn(buf, got, timeout_us < 1 ? 1 : timeout_us);
  }

  /// The transport's clock, ns, monotonic: CLOCK_MONOTONIC for USB, simulated time for the
  /// virtual Falcon (so that its timeouts are deterministic). FalconDevice measures reply
  /// deadlines with it.
  std::int64_t NowNs() { return DoNowNs(); }

 private:
  virtual UsbStatus DoControlOut(std::uint8_t request, std::uint16_t value, int timeout_ms) = 0;
  virtual UsbStatus DoBulkOut(std::span<const std::uint8_t> bytes, std::size_t& written, std::int64_t timeout_us) = 0;
  virtual UsbStatus DoBulkIn(std::span<std::uint8_t> buf, std::size_t& got, std::int64_t timeout_us) = 0;
  virtual std::int64_t DoNowNs() = 0;
};

}  // namespace palpa::device_falcon
