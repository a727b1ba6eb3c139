#include "palpa/device_falcon/libusb_transport.h"

#include <libusb.h>

#include <climits>
#include <ctime>

namespace palpa::device_falcon {
namespace {

constexpr int kInterface = 0;
constexpr auto kVendorOut =
    static_cast<std::uint8_t>(static_cast<int>(LIBUSB_REQUEST_TYPE_VENDOR) | static_cast<int>(LIBUSB_RECIPIENT_DEVICE) |
                              static_cast<int>(LIBUSB_ENDPOINT_OUT));  // 0x40

UsbStatus Map(int rc) {
  switch (rc) {
    case LIBUSB_SUCCESS:
      return UsbStatus::kOk;
    case LIBUSB_ERROR_TIMEOUT:
      return UsbStatus::kTimeout;
    case LIBUSB_ERROR_NO_DEVICE:
      return UsbStatus::kNoDevice;
    default:
      return UsbStatus::kIoError;
  }
}

unsigned TimeoutMs(std::int64_t timeout_us) {
  const std::int64_t ms = (timeout_us + 999) / 1000;  // libusb: whole ms, 0 would mean "forever"
  return static_cast<unsigned>(ms < 1 ? 1 : (ms > INT_MAX ? INT_MAX : ms));
}

std::string NotFound(int found, int index) {
  if (found == 0) return "no Novint Falcon (USB 0403:cb48) found";
  return "no Novint Falcon (USB 0403:cb48) found at --usb-index " + std::to_string(index) + " (" +
         std::to_string(found) + " attached, indices 0.." + std::to_string(found - 1) + ")";
}

// Walks the device list; returns the matching devices' count and refs the index-th one.
int FindFalcons(libusb_context* ctx, int index, libusb_device** chosen) {
  libusb_device** list = nullptr;
  const ssize_t n = libusb_get_device_list(ctx, &list);
  if (n < 0) return 0;
  int found = 0;
  for (ssize_t i = 0; i < n; ++i) {
    libusb_device_descriptor desc{};
    if (libusb_get_device_descriptor(list[i], &desc) != LIBUSB_SUCCESS) continue;
    if (desc.idVendor != kFalconVendorId || desc.idProduct != kFalconProductId) continue;
    if (found == index && chosen != nullptr) *chosen = libusb_ref_device(list[i]);
    ++found;
  }
  libusb_free_device_list(list, 1);
  return found;
}

}  // namespace

int LibusbTransport::CountDevices() {
  libusb_context* ctx = nullptr;
  if (libusb_init(&ctx) != LIBUSB_SUCCESS) return 0;
  const int n = FindFalcons(ctx, -1, nullptr);
  libusb_exit(ctx);
  return n;
}

std::expected<std::unique_ptr<LibusbTransport>, OpenFailure> LibusbTransport::Open(int index) {
  libusb_context* ctx = nullptr;
  const int rc_init = libusb_init(&ctx);
  if (rc_init != LIBUSB_SUCCESS) {
    // No usbfs at all (e.g. a container or a kernel without USB): there is no Falcon to find.
    return std::unexpected(OpenFailure{OpenError::kNotFound, "no Novint Falcon (USB 0403:cb48) found (libusb: " +
                                                                 std::string(libusb_error_name(rc_init)) + ")"});
  }
  libusb_device* dev = nullptr;
  const int found = FindFalcons(ctx, index, &dev);
  if (dev == nullptr) {
    libusb_exit(ctx);
    return std::unexpected(OpenFailure{OpenError::kNotFound, NotFound(found, index)});
  }
  libusb_device_handle* h = nullptr;
  const int rc_open = libusb_open(dev, &h);
  const std::string where = "Novint Falcon on USB bus " + std::to_string(libusb_get_bus_number(dev)) + " device " +
                            std::to_string(libusb_get_device_address(dev));
  libusb_unref_device(dev);
  if (rc_open != LIBUSB_SUCCESS) {
    libusb_exit(ctx);
    if (rc_open == LIBUSB_ERROR_ACCESS)
      return std::unexpected(
          OpenFailure{OpenError::kNoAccess, where + ": permission denied; install packaging/99-palpa-falcon.rules in "
                                                    "/etc/udev/rules.d, add yourself to group plugdev, re-plug"});
    return std::unexpected(
        OpenFailure{OpenError::kUsbFailure, where + ": cannot open (libusb " + libusb_error_name(rc_open) + ")"});
  }
  // No kernel driver binds 0403:cb48 by default; detach one only if present (ftdi_sio given the
  // PID by hand). Auto-detach would use USBDEVFS_DISCONNECT_CLAIM, which emulators lack.
  if (libusb_kernel_driver_active(h, kInterface) == 1) (void)libusb_detach_kernel_driver(h, kInterface);
  const int rc_claim = libusb_claim_interface(h, kInterface);
  if (rc_claim != LIBUSB_SUCCESS) {
    libusb_close(h);
    libusb_exit(ctx);
    if (rc_claim == LIBUSB_ERROR_BUSY)
      return std::unexpected(OpenFailure{OpenError::kBusy, where + ": interface 0 is in use by another program"});
    return std::unexpected(OpenFailure{
        OpenError::kUsbFailure, where + ": cannot claim interface 0 (libusb " + libusb_error_name(rc_claim) + ")"});
  }
  return std::unique_ptr<LibusbTransport>(new LibusbTransport(ctx, h));
}

LibusbTransport::~LibusbTransport() {
  if (!gone_) (void)libusb_release_interface(handle_, kInterface);
  libusb_close(handle_);
  libusb_exit(ctx_);
}

UsbStatus LibusbTransport::DoControlOut(std::uint8_t request, std::uint16_t value, int timeout_ms) {
  if (gone_) return UsbStatus::kNoDevice;
  const int rc =
      libusb_control_transfer(handle_, kVendorOut, request, value, 0, nullptr, 0, static_cast<unsigned>(timeout_ms));
  const UsbStatus s = rc >= 0 ? UsbStatus::kOk : Map(rc);
  gone_ = s == UsbStatus::kNoDevice;
  return s;
}

UsbStatus LibusbTransport::DoBulkOut(std::span<const std::uint8_t> bytes, std::size_t& written,
                                     std::int64_t timeout_us) {
  if (gone_) return UsbStatus::kNoDevice;
  int n = 0;
  // libusb's buffer parameter is non-const although OUT transfers only read it.
  const int rc = libusb_bulk_transfer(handle_, kEndpointOut, const_cast<unsigned char*>(bytes.data()),
                                      static_cast<int>(bytes.size()), &n, TimeoutMs(timeout_us));
  written = n > 0 ? static_cast<std::size_t>(n) : 0;
  const UsbStatus s = Map(rc);
  gone_ = s == UsbStatus::kNoDevice;
  return s;
}

UsbStatus LibusbTransport::DoBulkIn(std::span<std::uint8_t> buf, std::size_t& got, std::int64_t timeout_us) {
  if (gone_) return UsbStatus::kNoDevice;
  int n = 0;
  const int rc =
      libusb_bulk_transfer(handle_, kEndpointIn, buf.data(), static_cast<int>(buf.size()), &n, TimeoutMs(timeout_us));
  got = n > 0 ? static_cast<std::size_t>(n) : 0;
  const UsbStatus s = Map(rc);
  gone_ = s == UsbStatus::kNoDevice;
  return s;
}

std::int64_t LibusbTransport::DoNowNs() {
  timespec ts{};
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return std::int64_t{ts.tv_sec} * 1'000'000'000 + ts.tv_nsec;
}

}  // namespace palpa::device_falcon
