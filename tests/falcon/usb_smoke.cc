// The real libusb path against an emulated Falcon (run under umockdev-run, see CMakeLists.txt):
// LibusbTransport::Open finds 0403:cb48 and claims interface 0, the FTDI normal-mode set-up goes
// out as six vendor control transfers, ProbeFirmware sends the idle packet and decodes the
// recorded reply, then one homing packet (red LED) gets its recorded reply. Every OUT transfer
// must match the recording byte for byte (umockdev fails the transfer otherwise).
// `--expect-none`: with no device attached, Open must say "no Novint Falcon (USB 0403:cb48) found".

#include <cstdio>
#include <cstring>

#include "palpa/device_falcon/firmware_loader.h"
#include "palpa/device_falcon/ftdi.h"
#include "palpa/device_falcon/libusb_transport.h"
#include "palpa/falcon/codec.h"

namespace {

using palpa::device_falcon::UsbStatus;

int Fail(const char* what) {
  std::printf("falcon_usb_smoke: FAILED: %s\n", what);
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace palpa;
  if (argc > 1 && std::strcmp(argv[1], "--expect-none") == 0) {
    auto t = device_falcon::LibusbTransport::Open(0);
    if (t) return Fail("opened a Falcon where none is attached");
    std::printf("falcon_usb_smoke: %s\n", t.error().message.c_str());
    return t.error().error == device_falcon::OpenError::kNotFound ? 0 : 1;
  }
  auto opened = device_falcon::LibusbTransport::Open(0);
  if (!opened) return Fail(opened.error().message.c_str());
  device_falcon::FalconTransport& t = **opened;
  if (device_falcon::ftdi::SetNormalMode(t) != UsbStatus::kOk) return Fail("FTDI normal-mode control transfers");

  falcon::DeviceStatus st;
  if (device_falcon::ProbeFirmware(t, st, 1, 200'000) != device_falcon::ProbeResult::kAnswering)
    return Fail("firmware probe got no status packet");
  if (st.encoders != std::array<std::int16_t, 3>{-1447, 0, 1447} || st.homed != 0)
    return Fail("probe reply decoded wrong");

  // One homing exchange: homing bit + red LED; the recorded reply has all three homed flags.
  const falcon::Packet cmd = falcon::EncodeCommand({{0, 0, 0}, falcon::kControlHoming | falcon::kLedRed});
  std::size_t written = 0;
  if (t.BulkOut(cmd, written, 200'000) != UsbStatus::kOk || written != cmd.size()) return Fail("homing packet write");
  falcon::FrameReader reader;
  falcon::Packet reply{};
  for (int i = 0; i < 10 && !reader.Next(reply); ++i) {
    std::array<std::uint8_t, 64> raw{};
    std::size_t got = 0;
    const UsbStatus s = t.BulkIn(raw, got, 200'000);
    if (s != UsbStatus::kOk && s != UsbStatus::kTimeout) return Fail("homing reply read");
    reader.PushUsbTransfer(std::span<const std::uint8_t>(raw.data(), got));
  }
  const auto homed = falcon::DecodeStatus(reply);
  if (!homed || !homed->AllHomed() || homed->encoders != std::array<std::int16_t, 3>{100, -200, 300})
    return Fail("homing reply decoded wrong");
  std::printf("falcon_usb_smoke: ok (encoders %d %d %d, homed 0x%x)\n", homed->encoders[0], homed->encoders[1],
              homed->encoders[2], homed->homed);
  return 0;
}
