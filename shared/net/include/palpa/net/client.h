// The host side of the upload protocol (docs/upload.md): send a field blob to a running palpad,
// and fetch its status. Each call opens one TCP connection, runs one authenticated exchange
// (server challenge nonce + client nonce, HMAC-SHA-512/256 with the shared key) and closes it.
//
// Thread rules: every function is re-entrant and keeps no state between calls; call them from any
// non-RT thread (e.g. `palpa view --connect` polls FetchStatus ~60 times a second). Non-RT:
// allocates, blocks on the network (bounded by `timeout`). No exceptions: errors are NetError.
#pragma once

#include <array>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <expected>
#include <span>
#include <string>
#include <string_view>

#include "palpa/net/protocol.h"

namespace palpa::net {

/// What went wrong on the client side, or why the controller refused.
enum class NetErrorCode {
  kBadEndpoint,  ///< "HOST:PORT" could not be parsed or resolved
  kKeyFile,      ///< the key file is missing, not 32 bytes, or readable by group/other
  kConnect,      ///< TCP connect failed (refused, unreachable) or timed out
  kTimeout,      ///< the controller did not answer within `timeout`
  kProtocol,     ///< the controller's bytes are not this protocol (or an unknown version)
  kBadReply,     ///< the reply's MAC does not verify with our key (wrong key, or altered in transit)
  kRefused,      ///< the controller refused the request: see `refusal` and `message`
  kIo,           ///< a socket error other than the above
};

/// A failed call. `message` is one sentence naming the endpoint; for kRefused, `refusal` is the
/// controller's reason code and `message` its text (e.g. the verifier's field and byte).
struct NetError {
  NetErrorCode code = NetErrorCode::kIo;
  Refusal refusal = Refusal::kNone;
  std::string message;
  bool reply_authenticated = false;  ///< kRefused: the refusal carried a valid MAC under our key
};

/// Where palpad listens. Parse with ParseEndpoint.
struct Endpoint {
  std::string host;  ///< name or numeric address (IPv4 or IPv6)
  std::uint16_t port = 0;
};
/// "HOST:PORT" or "[V6ADDR]:PORT"; port 1..65535. Errors: kBadEndpoint.
[[nodiscard]] std::expected<Endpoint, NetError> ParseEndpoint(std::string_view text);

/// The field the controller renders, and its loop's counters and latest telemetry sample.
/// Device frame; metres, newtons, seconds. Filled from palpad's STATUS reply (docs/upload.md).
struct ControllerStatus {
  // The field in use.
  std::uint32_t field_crc32c = 0;       ///< the blob's CRC-32C (blob header), identifies the field
  std::array<std::uint32_t, 3> dims{};  ///< grid nodes nx, ny, nz
  double voxel_m = 0;                   ///< node spacing, m
  std::uint64_t field_bytes = 0;        ///< blob size, bytes
  std::uint64_t swaps = 0;              ///< fields swapped in since start (the loop's epoch)
  bool swap_ramp = false;               ///< the force is ramping in after the last swap
  // Loop counters (since start).
  std::uint64_t ticks = 0;          ///< completed servo ticks
  std::uint64_t overruns = 0;       ///< paced ticks that ended after the next deadline
  std::int64_t max_tick_ns = 0;     ///< longest tick compute time, ns
  std::uint64_t force_clamps = 0;   ///< ticks whose |f| hit the force clamp
  std::uint64_t estops = 0;         ///< e-stop assertions
  std::uint64_t contact_ticks = 0;  ///< ticks in contact
  std::uint64_t dropped = 0;        ///< telemetry samples dropped (ring full)
  // Uploads since start.
  std::uint64_t uploads_accepted = 0;
  std::uint64_t uploads_refused = 0;
  // The latest telemetry sample.
  std::uint64_t last_tick = 0;      ///< its tick index
  double t_s = 0;                   ///< its device time, s
  std::array<double, 3> hip_m{};    ///< HIP as read, m
  std::array<double, 3> proxy_m{};  ///< proxy after the tick, m
  std::array<double, 3> force_n{};  ///< force written, N
  bool contact = false;             ///< proxy held apart from the HIP by the surface
  // The run.
  double rate_hz = 0;    ///< servo rate, Hz
  bool running = false;  ///< the loop is ticking (false once it ended)
};

/// One-line JSON object, keys as the field names above (arrays for the 3-vectors), e.g.
/// {"field_crc32c": "0x1a2b3c4d", "dims": [40, 40, 40], "voxel_m": 0.0002, ..., "contact": true}.
/// The checksum is a hex string; everything else numbers or booleans.
std::string ToJson(const ControllerStatus& s);

/// A 32-byte shared key (crypto_auth_hmacsha512256_KEYBYTES).
struct Key {
  std::array<unsigned char, kKeyBytes> bytes{};
};
/// Reads a key file written by `palpa keygen`: exactly 32 bytes, a regular file with no group or
/// other permission bits (mode 0600 or stricter). Errors (kKeyFile) name the file and the fault.
[[nodiscard]] std::expected<Key, NetError> ReadKeyFile(const std::string& path);
/// Writes 32 random bytes (libsodium randombytes_buf) to `path` with mode 0600, atomically
/// (io::AtomicFile: temporary file, fsync, rename). Refuses an existing path unless `force`, and a
/// device, FIFO or directory always. Errors: kKeyFile.
[[nodiscard]] std::expected<void, NetError> WriteNewKeyFile(const std::string& path, bool force);

/// Fetches the controller's status. Bounded by `timeout` overall (connect + exchange).
/// Errors: kConnect, kTimeout, kProtocol, kBadReply (wrong key), kRefused (e.g. replayed), kIo.
[[nodiscard]] std::expected<ControllerStatus, NetError> FetchStatus(const Endpoint& to, const Key& key,
                                                                    std::chrono::milliseconds timeout);

/// What the controller answered to an accepted upload.
struct UploadAccepted {
  std::uint32_t field_crc32c = 0;       ///< CRC-32C of the field now in use
  std::array<std::uint32_t, 3> dims{};  ///< its grid nodes
  double voxel_m = 0;                   ///< its voxel, m
  std::uint64_t swaps = 0;              ///< the loop's epoch after this swap
};

/// Sends `blob` (verify it locally first) and waits for the controller's answer: accepted once
/// the loop picked the field up at a tick boundary, or refused with a reason. `timeout` bounds
/// every wait for the controller (connect, each send, the answer), not the whole transfer.
/// Errors: as FetchStatus; kRefused with refusal kOversize, kBlobInvalid, kBusy, ....
[[nodiscard]] std::expected<UploadAccepted, NetError> Upload(const Endpoint& to, const Key& key,
                                                             std::span<const std::byte> blob,
                                                             std::chrono::milliseconds timeout);

}  // namespace palpa::net
