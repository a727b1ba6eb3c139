// Novint Falcon firmware: reading the user's file, checking whether firmware already runs, and
// uploading it to the DSP's boot ROM (docs/falcon.md §1.5-1.7; source: libnifalcon
// src/comm/FalconCommLibUSB.cpp setFirmwareMode, src/core/FalconFirmware.cpp loadFirmware and
// isFirmwareLoaded). palpa never ships the firmware: it is Novint's, under a licence that forbids
// redistribution; the user passes its path (--firmware).
//
// Non-RT: allocates (file, messages) and does blocking transfers, each bounded by a timeout.
#pragma once

#include <cstddef>
#include <cstdint>
#include <expected>
#include <span>
#include <string>
#include <vector>

#include "palpa/device_falcon/transport.h"
#include "palpa/falcon/codec.h"

namespace palpa::device_falcon {

/// A firmware file that passed ValidateFirmwareImage.
struct FirmwareImage {
  std::string path;                 ///< as given, for messages
  std::vector<std::uint8_t> bytes;  ///< the whole boot stream, sent as is
};

/// Checks that `bytes` is a TI C2000 boot-ROM 8-bit stream, as Novint's files are (docs/falcon.md
/// §1.7): 16-bit little-endian words, key 0x08AA, 8 reserved words, a 32-bit entry point, then
/// blocks {size, dest_hi, dest_lo, size words} ending with a size-0 word and nothing after it.
/// Error: one sentence naming `name` and the byte offset, e.g. "fw.bin: byte 0: key 0x1234, a
/// Falcon firmware file starts with 0x08AA".
std::expected<void, std::string> ValidateFirmwareImage(std::span<const std::uint8_t> bytes, const std::string& name);

/// Reads and validates a firmware file (≤ 1 MiB). Errors name the path (and the byte).
std::expected<FirmwareImage, std::string> ReadFirmwareFile(const std::string& path);

/// Bytes per upload chunk; each chunk's echo is compared before the next (libnifalcon READ_SIZE).
inline constexpr std::size_t kFirmwareChunkBytes = 62;

/// Result of asking whether firmware runs.
enum class ProbeResult {
  kAnswering,  ///< a valid 16-byte status packet came back: firmware runs
  kSilent,     ///< no valid reply: the DSP is in its boot ROM (or not talking)
  kNoDevice,   ///< unplugged
  kIoError,    ///< USB failure
};

/// Sends up to `tries` idle command packets (zero torque, LEDs off), each followed by up to
/// `reply_timeout_us` of reading, and stops at the first valid status reply (stored in
/// `status`). Expects normal mode (ftdi::SetNormalMode). Bounded: tries × (timeout + transfer).
ProbeResult ProbeFirmware(FalconTransport& t, falcon::DeviceStatus& status, int tries = 20,
                          std::int64_t reply_timeout_us = 10'000);

struct LoaderConfig {
  int attempts = 10;                           ///< whole uploads (libnifalcon's clients use 10)
  int handshake_tries = 100;                   ///< "\nC\r" → "\nD,\r" tries per upload (libnifalcon: 100)
  std::int64_t handshake_timeout_us = 50'000;  ///< per handshake try
  std::int64_t echo_timeout_us = 1'000'000;    ///< per chunk echo (libnifalcon: 1000 ms)
};

/// What an upload did: `failures` has one sentence per failed attempt, in order.
struct LoadReport {
  bool ok = false;
  int attempts = 0;
  std::vector<std::string> failures;
  /// Multi-line summary: "firmware loaded (attempt 2 of 10)" or "firmware upload failed after N
  /// attempts", then "  attempt k: <reason>" lines.
  std::string Message(int max_attempts) const;
};

/// Uploads `image` with up to config.attempts tries. Each try: ftdi::SetFirmwareMode; the
/// handshake; DTR low and 140 kBd; 'A' and its echo (boot-ROM autobaud); the image in 62-byte
/// chunks, every byte's echo compared; ftdi::SetNormalMode; ProbeFirmware must then answer.
/// A failure names the step and, for an echo mismatch, the byte offset and both values. A lost
/// device ends all tries at once. Leaves the bridge in normal mode after a success.
LoadReport LoadFirmware(FalconTransport& t, const FirmwareImage& image, const LoaderConfig& config = {});

/// Reads serial payload bytes (FTDI status bytes stripped) into `out` until `out.size()` bytes
/// came or `timeout_us` passed on the transport's clock. Returns the count; `status` gets the last
/// transfer's status (kTimeout if the time ran out). Bounded also in transfers (≤ 100 000).
std::size_t ReadPayload(FalconTransport& t, std::span<std::uint8_t> out, std::int64_t timeout_us, UsbStatus& status);

}  // namespace palpa::device_falcon
