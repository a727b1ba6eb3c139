#include "palpa/device_falcon/firmware_loader.h"

#include <algorithm>
#include <array>
#include <cstdio>
#include <fstream>
#include <iterator>

#include "palpa/device_falcon/ftdi.h"

namespace palpa::device_falcon {
namespace {

constexpr std::uint16_t kBootKey = 0x08AA;
constexpr std::size_t kHeaderBytes = 2 + 8 * 2 + 4;  // key, 8 reserved words, entry point
constexpr std::size_t kMaxFirmwareBytes = 1 << 20;
constexpr std::uint8_t kAutobaud = 0x41;                                           // 'A'
constexpr std::array<std::uint8_t, 3> kHandshakeRequest = {0x0A, 0x43, 0x0D};      // "\nC\r"
constexpr std::array<std::uint8_t, 4> kHandshakeReply = {0x0A, 0x44, 0x2C, 0x0D};  // "\nD,\r"

std::string Hex(unsigned v, int digits) {
  char buf[16];
  std::snprintf(buf, sizeof buf, "0x%0*X", digits, v);
  return buf;
}

std::uint16_t Word(std::span<const std::uint8_t> b, std::size_t at) {
  return static_cast<std::uint16_t>(b[at] | (b[at + 1] << 8));
}

std::string UsbFailure(const char* step, UsbStatus s) { return std::string(step) + ": USB " + UsbStatusName(s); }

// One upload attempt; returns an empty string on success, else the reason.
std::string TryUpload(FalconTransport& t, const FirmwareImage& image, const LoaderConfig& cfg, bool& lost) {
  UsbStatus s = ftdi::SetFirmwareMode(t);
  if (s != UsbStatus::kOk) {
    lost = s == UsbStatus::kNoDevice;
    return UsbFailure("boot-ROM mode set-up", s);
  }

  // Handshake: "\nC\r" until the boot ROM answers "\nD,\r" (libnifalcon also accepts a leading 0).
  bool greeted = false;
  for (int i = 0; i < cfg.handshake_tries && !greeted; ++i) {
    std::size_t written = 0;
    s = t.BulkOut(kHandshakeRequest, written, 1'000'000);
    if (s == UsbStatus::kNoDevice || s == UsbStatus::kIoError) {
      lost = s == UsbStatus::kNoDevice;
      return UsbFailure("handshake write", s);
    }
    std::array<std::uint8_t, 8> reply{};
    const std::size_t n = ReadPayload(t, reply, cfg.handshake_timeout_us, s);
    if (s == UsbStatus::kNoDevice) {
      lost = true;
      return UsbFailure("handshake read", s);
    }
    const std::span<const std::uint8_t> got(reply.data(), n);
    greeted = std::search(got.begin(), got.end(), kHandshakeReply.begin(), kHandshakeReply.end()) != got.end();
  }
  if (!greeted)
    return "handshake: no \"\\nD,\\r\" reply to " + std::to_string(cfg.handshake_tries) + " \"\\nC\\r\" requests";

  // Autobaud at 140 kBd: the boot ROM echoes 'A'.
  s = t.ControlOut(ftdi::kReqModemCtrl, ftdi::kDtrLow, ftdi::kControlTimeoutMs);
  if (s == UsbStatus::kOk) s = t.ControlOut(ftdi::kReqSetBaudRate, ftdi::kBaud140k, ftdi::kControlTimeoutMs);
  if (s != UsbStatus::kOk) {
    lost = s == UsbStatus::kNoDevice;
    return UsbFailure("switch to 140 kBd", s);
  }
  {
    std::size_t written = 0;
    const std::array<std::uint8_t, 1> a = {kAutobaud};
    s = t.BulkOut(a, written, 1'000'000);
    if (s != UsbStatus::kOk || written != 1) {
      lost = s == UsbStatus::kNoDevice;
      return UsbFailure("autobaud write", s == UsbStatus::kOk ? UsbStatus::kTimeout : s);
    }
    std::array<std::uint8_t, 1> echo{};
    const std::size_t n = ReadPayload(t, echo, cfg.echo_timeout_us, s);
    if (s == UsbStatus::kNoDevice) {
      lost = true;
      return UsbFailure("autobaud echo", s);
    }
    if (n != 1) return "autobaud: no echo of 'A' (0x41)";
    if (echo[0] != kAutobaud) return "autobaud: echo " + Hex(echo[0], 2) + " instead of 0x41";
  }

  // The boot stream, chunk by chunk, every byte's echo checked.
  const std::span<const std::uint8_t> bytes(image.bytes);
  for (std::size_t at = 0; at < bytes.size(); at += kFirmwareChunkBytes) {
    const auto chunk = bytes.subspan(at, std::min(kFirmwareChunkBytes, bytes.size() - at));
    std::size_t written = 0;
    s = t.BulkOut(chunk, written, 1'000'000);
    if (s != UsbStatus::kOk || written != chunk.size()) {
      lost = s == UsbStatus::kNoDevice;
      return "upload: write of bytes " + std::to_string(at) + ".." + std::to_string(at + chunk.size() - 1) +
             " failed: USB " + UsbStatusName(s == UsbStatus::kOk ? UsbStatus::kTimeout : s);
    }
    std::array<std::uint8_t, kFirmwareChunkBytes> echo{};
    const std::size_t n = ReadPayload(t, std::span(echo).first(chunk.size()), cfg.echo_timeout_us, s);
    if (s == UsbStatus::kNoDevice) {
      lost = true;
      return UsbFailure("upload echo", s);
    }
    for (std::size_t i = 0; i < n; ++i) {
      if (echo[i] != chunk[i])
        return "echo mismatch at byte " + std::to_string(at + i) + " of " + image.path + " (sent " + Hex(chunk[i], 2) +
               ", got " + Hex(echo[i], 2) + ")";
    }
    if (n != chunk.size())
      return "echo timeout at byte " + std::to_string(at + n) + " of " + image.path + " (" + std::to_string(n) +
             " of " + std::to_string(chunk.size()) + " bytes echoed)";
  }

  s = ftdi::SetNormalMode(t);
  if (s != UsbStatus::kOk) {
    lost = s == UsbStatus::kNoDevice;
    return UsbFailure("normal mode after upload", s);
  }
  falcon::DeviceStatus status;
  switch (ProbeFirmware(t, status)) {
    case ProbeResult::kAnswering:
      return {};
    case ProbeResult::kNoDevice:
      lost = true;
      return UsbFailure("first packet after upload", UsbStatus::kNoDevice);
    case ProbeResult::kIoError:
      return UsbFailure("first packet after upload", UsbStatus::kIoError);
    case ProbeResult::kSilent:
      break;
  }
  return "uploaded and echoed, but the firmware does not answer 16-byte packets";
}

}  // namespace

const char* UsbStatusName(UsbStatus s) {
  switch (s) {
    case UsbStatus::kOk:
      return "ok";
    case UsbStatus::kTimeout:
      return "timeout";
    case UsbStatus::kNoDevice:
      return "no device (unplugged)";
    case UsbStatus::kIoError:
      return "I/O error";
  }
  return "?";
}

std::expected<void, std::string> ValidateFirmwareImage(std::span<const std::uint8_t> bytes, const std::string& name) {
  auto fail = [&](std::size_t at, const std::string& what) {
    return std::unexpected(name + ": byte " + std::to_string(at) + ": " + what);
  };
  if (bytes.size() < kHeaderBytes + 2)
    return fail(bytes.size(), "file ends after " + std::to_string(bytes.size()) +
                                  " bytes; a Falcon firmware boot stream has a 22-byte header and an end block");
  if (Word(bytes, 0) != kBootKey)
    return fail(0, "key " + Hex(Word(bytes, 0), 4) + ", a Falcon firmware file (TI boot stream) starts with 0x08AA");
  std::size_t at = kHeaderBytes;
  for (;;) {
    if (at + 2 > bytes.size()) return fail(at, "file ends inside the block list (no size-0 end block)");
    const std::size_t words = Word(bytes, at);
    if (words == 0) {
      at += 2;
      break;
    }
    const std::size_t block_bytes = 2 * (3 + words);
    if (block_bytes > bytes.size() - at)
      return fail(at, "block of " + std::to_string(words) + " words runs past the end of the file (" +
                          std::to_string(bytes.size()) + " bytes)");
    at += block_bytes;
  }
  if (at != bytes.size()) return fail(at, std::to_string(bytes.size() - at) + " bytes after the end block");
  return {};
}

std::expected<FirmwareImage, std::string> ReadFirmwareFile(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) return std::unexpected(path + ": cannot open the firmware file");
  FirmwareImage image;
  image.path = path;
  image.bytes.assign(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
  if (f.bad()) return std::unexpected(path + ": read error");
  if (image.bytes.size() > kMaxFirmwareBytes)
    return std::unexpected(path + ": " + std::to_string(image.bytes.size()) +
                           " bytes is too large for Falcon firmware (at most 1 MiB)");
  if (auto ok = ValidateFirmwareImage(image.bytes, path); !ok) return std::unexpected(ok.error());
  return image;
}

std::size_t ReadPayload(FalconTransport& t, std::span<std::uint8_t> out, std::int64_t timeout_us, UsbStatus& status) {
  const std::int64_t deadline = t.NowNs() + timeout_us * 1000;
  std::size_t n = 0;
  status = UsbStatus::kOk;
  for (int transfers = 0; n < out.size() && transfers < 100'000; ++transfers) {
    const std::int64_t left_us = (deadline - t.NowNs()) / 1000;
    if (left_us <= 0) {
      status = UsbStatus::kTimeout;
      break;
    }
    std::array<std::uint8_t, kBulkInBytes> raw{};
    std::size_t got = 0;
    status = t.BulkIn(raw, got, left_us);
    if (status == UsbStatus::kNoDevice || status == UsbStatus::kIoError) break;
    std::uint8_t modem = 0;
    n += falcon::StripFtdiStatus(std::span<const std::uint8_t>(raw.data(), got), out.subspan(n), modem);
  }
  if (n == out.size()) status = UsbStatus::kOk;
  return n;
}

ProbeResult ProbeFirmware(FalconTransport& t, falcon::DeviceStatus& status, int tries, std::int64_t reply_timeout_us) {
  const falcon::Packet idle = falcon::EncodeCommand({});
  for (int i = 0; i < tries; ++i) {
    std::size_t written = 0;
    UsbStatus s = t.BulkOut(idle, written, 1'000'000);
    if (s == UsbStatus::kNoDevice) return ProbeResult::kNoDevice;
    if (s == UsbStatus::kIoError) return ProbeResult::kIoError;
    falcon::FrameReader reader;
    const std::int64_t deadline = t.NowNs() + reply_timeout_us * 1000;
    for (int transfers = 0; transfers < 10'000; ++transfers) {
      const std::int64_t left_us = (deadline - t.NowNs()) / 1000;
      if (left_us <= 0) break;
      std::array<std::uint8_t, kBulkInBytes> raw{};
      std::size_t got = 0;
      s = t.BulkIn(raw, got, left_us);
      if (s == UsbStatus::kNoDevice) return ProbeResult::kNoDevice;
      if (s == UsbStatus::kIoError) return ProbeResult::kIoError;
      reader.PushUsbTransfer(std::span<const std::uint8_t>(raw.data(), got));
      falcon::Packet p{};
      if (reader.Next(p)) {
        if (auto st = falcon::DecodeStatus(p)) {
          status = *st;
          return ProbeResult::kAnswering;
        }
      }
    }
  }
  return ProbeResult::kSilent;
}

LoadReport LoadFirmware(FalconTransport& t, const FirmwareImage& image, const LoaderConfig& config) {
  LoadReport report;
  for (int attempt = 1; attempt <= config.attempts; ++attempt) {
    report.attempts = attempt;
    bool lost = false;
    std::string failure = TryUpload(t, image, config, lost);
    if (failure.empty()) {
      report.ok = true;
      return report;
    }
    report.failures.push_back(std::move(failure));
    if (lost) break;  // unplugged: further tries cannot succeed
  }
  return report;
}

std::string LoadReport::Message(int max_attempts) const {
  std::string m;
  if (ok) {
    m = "firmware loaded (attempt " + std::to_string(attempts) + " of " + std::to_string(max_attempts) + ")";
  } else {
    m = "firmware upload failed after " + std::to_string(attempts) + " attempt" + (attempts == 1 ? "" : "s");
  }
  for (std::size_t i = 0; i < failures.size(); ++i) m += "\n  attempt " + std::to_string(i + 1) + ": " + failures[i];
  return m;
}

}  // namespace palpa::device_falcon
