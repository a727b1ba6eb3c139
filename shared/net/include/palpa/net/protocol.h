// The upload protocol's wire format (docs/upload.md is the specification): one fixed 96-byte
// header, a body of `body_size` bytes, then a 32-byte body tag. Little-endian, no implicit padding.
//
//   byte 0      4     6     8            16                40                64                 96
//   +-----------+-----+-----+------------+-----------------+-----------------+------------------+
//   | "PLPU"    | ver | type| body_size  | server_nonce    | client_nonce    | header_tag       |
//   +-----------+-----+-----+------------+-----------------+-----------------+------------------+
//   then body[body_size], then body_tag[32]
//
// header_tag = HMAC-SHA-512/256(key, header bytes [0, 64)); body_tag = HMAC-SHA-512/256(key,
// header bytes [0, 96) ‖ body) (libsodium crypto_auth_hmacsha512256). The HELLO that opens every
// connection carries a fresh random server nonce and zero tags. A request must echo that nonce
// and bring its own client nonce; the reply echoes both. So a recorded request, replayed on a new
// connection, names a nonce this connection never issued and is refused as replayed (no state to
// persist across restarts), and a recorded reply cannot be passed off as the answer to a new one.
//
// Non-RT. No exceptions.
#pragma once

#include <array>
#include <bit>
#include <cstddef>
#include <cstdint>
#include <span>
#include <type_traits>

namespace palpa::net {

static_assert(std::endian::native == std::endian::little, "the wire format is little-endian");

inline constexpr std::array<char, 4> kMagic = {'P', 'L', 'P', 'U'};
inline constexpr std::uint16_t kVersion = 1;
inline constexpr std::size_t kKeyBytes = 32;    ///< crypto_auth_hmacsha512256_KEYBYTES
inline constexpr std::size_t kNonceBytes = 24;  ///< per side, from randombytes_buf
inline constexpr std::size_t kTagBytes = 32;    ///< crypto_auth_hmacsha512256_BYTES
inline constexpr std::size_t kHeaderSize = 96;
inline constexpr std::size_t kHeaderTagOffset = 64;
/// Cap of every body except an upload's: HELLO, STATUS request and the replies are fixed records.
inline constexpr std::uint64_t kMaxControlBody = 4096;
/// Largest --max-blob palpad accepts (the upload body cap it announces is at most this), bytes.
inline constexpr std::uint64_t kMaxBlobCap = std::uint64_t{1} << 30;
/// Default --max-blob, bytes (64 MiB).
inline constexpr std::uint64_t kDefaultMaxBlob = std::uint64_t{64} << 20;

enum class MessageType : std::uint16_t {
  kHello = 1,           ///< palpad → client, on accept: HelloBody, zero tags
  kUpload = 2,          ///< client → palpad: the blob
  kStatusRequest = 3,   ///< client → palpad: empty body
  kUploadAccepted = 4,  ///< palpad → client: AcceptedBody
  kStatusReply = 5,     ///< palpad → client: StatusBody
  kRefused = 6,         ///< palpad → client: RefusedBody
  kContinue = 7,        ///< palpad → client: an UPLOAD header passed every check; send the body
};

/// Why palpad refused a request (RefusedBody::refusal). docs/upload.md lists the exact texts.
enum class Refusal : std::uint32_t {
  kNone = 0,
  kGarbage = 1,       ///< the first bytes are not a header of this protocol (magic)
  kBadVersion = 2,    ///< protocol version not 1
  kType = 3,          ///< not a request type (UPLOAD or STATUS), or a STATUS with a body
  kOversize = 4,      ///< body_size above the announced cap; refused before the body is read
  kReplayed = 5,      ///< the header echoes a server nonce this connection did not issue
  kWrongKey = 6,      ///< header_tag does not verify with palpad's key
  kTimeout = 7,       ///< the message did not arrive within the read deadline (slow client)
  kHalfSent = 8,      ///< the connection closed before the whole message arrived
  kBodyTag = 9,       ///< body_tag does not verify: the body was altered in transit
  kBlobInvalid = 10,  ///< the blob fails blob::Verify (the text names the field and byte)
  kBusy = 11,         ///< the loop has not picked up the previous field, or is not running
  kSetup = 12,        ///< the blob verifies but cannot be rendered (e.g. k·h out of range for its voxel)
};
/// A short lower-case name, e.g. "wrong key".
const char* RefusalName(Refusal r);

/// The 96-byte header exactly as sent. Comments: size (offset).
struct Header {
  std::array<char, 4> magic{};                            // 4B (0)  "PLPU"
  std::uint16_t version = 0;                              // 2B (4)  1
  std::uint16_t type = 0;                                 // 2B (6)  MessageType
  std::uint64_t body_size = 0;                            // 8B (8)  bytes after the header, before body_tag
  std::array<unsigned char, kNonceBytes> server_nonce{};  // 24B (16)
  std::array<unsigned char, kNonceBytes> client_nonce{};  // 24B (40) zero in HELLO
  std::array<unsigned char, kTagBytes> header_tag{};      // 32B (64) zero in HELLO
};
static_assert(sizeof(Header) == kHeaderSize && std::is_trivially_copyable_v<Header>);
static_assert(offsetof(Header, body_size) == 8 && offsetof(Header, server_nonce) == 16);
static_assert(offsetof(Header, client_nonce) == 40 && offsetof(Header, header_tag) == kHeaderTagOffset);

/// HELLO body (16 B).
struct HelloBody {
  std::uint64_t max_body = 0;         // 8B (0) the upload body cap (palpad --max-blob), bytes
  std::uint32_t read_timeout_ms = 0;  // 4B (8) palpad's read deadline for a whole request
  std::uint32_t reserved = 0;         // 4B (12) 0
};
static_assert(sizeof(HelloBody) == 16);

/// UPLOAD_ACCEPTED body (40 B): the field now in use.
struct AcceptedBody {
  std::uint32_t crc32c = 0;             // 4B (0)
  std::array<std::uint32_t, 3> dims{};  // 12B (4)
  double voxel_m = 0;                   // 8B (16)
  std::uint64_t swaps = 0;              // 8B (24) the loop's field epoch after this swap
  std::uint64_t field_bytes = 0;        // 8B (32)
};
static_assert(sizeof(AcceptedBody) == 40 && offsetof(AcceptedBody, voxel_m) == 16);

/// REFUSED body (256 B).
struct RefusedBody {
  std::uint32_t refusal = 0;     // 4B (0) Refusal
  std::uint32_t reserved = 0;    // 4B (4) 0
  std::array<char, 248> text{};  // 248B (8) NUL-terminated sentence
};
static_assert(sizeof(RefusedBody) == 256);

/// STATUS_REPLY body (272 B): ControllerStatus on the wire (client.h documents each field).
struct StatusBody {
  std::uint32_t field_crc32c = 0;            // 4B (0)
  std::array<std::uint32_t, 3> dims{};       // 12B (4)
  double voxel_m = 0;                        // 8B (16)
  std::uint64_t field_bytes = 0;             // 8B (24)
  std::uint64_t swaps = 0;                   // 8B (32)
  std::uint64_t ticks = 0;                   // 8B (40)
  std::uint64_t overruns = 0;                // 8B (48)
  std::int64_t max_tick_ns = 0;              // 8B (56)
  std::uint64_t force_clamps = 0;            // 8B (64)
  std::uint64_t estops = 0;                  // 8B (72)
  std::uint64_t contact_ticks = 0;           // 8B (80)
  std::uint64_t dropped = 0;                 // 8B (88)
  std::uint64_t uploads_accepted = 0;        // 8B (96)
  std::uint64_t uploads_refused = 0;         // 8B (104)
  std::uint64_t last_tick = 0;               // 8B (112)
  double t_s = 0;                            // 8B (120)
  std::array<double, 3> hip_m{};             // 24B (128)
  std::array<double, 3> proxy_m{};           // 24B (152)
  std::array<double, 3> force_n{};           // 24B (176)
  double rate_hz = 0;                        // 8B (200)
  std::uint32_t flags = 0;                   // 4B (208) bit 0 contact, 1 running, 2 swap ramp
  std::uint32_t reserved0 = 0;               // 4B (212) 0
  std::array<std::uint64_t, 7> reserved1{};  // 56B (216) 0
};
static_assert(sizeof(StatusBody) == 272 && offsetof(StatusBody, t_s) == 120 && offsetof(StatusBody, flags) == 208);
inline constexpr std::uint32_t kStatusContact = 1u << 0;
inline constexpr std::uint32_t kStatusRunning = 1u << 1;
inline constexpr std::uint32_t kStatusSwapRamp = 1u << 2;

/// HMAC-SHA-512/256 of `data` (crypto_auth_hmacsha512256): RFC 4231's HMAC-SHA-512, first 32 bytes.
std::array<unsigned char, kTagBytes> Mac(const std::array<unsigned char, kKeyBytes>& key,
                                         std::span<const std::byte> data);

/// HMAC-SHA-512/256 over header bytes [0, 64), as header_tag.
std::array<unsigned char, kTagBytes> HeaderTag(const std::array<unsigned char, kKeyBytes>& key, const Header& h);

/// body_tag computed incrementally: Start with the header (its tag filled), Update with the body
/// in pieces, Final. Wraps crypto_auth_hmacsha512256_state (no allocation).
class BodyMac {
 public:
  BodyMac(const std::array<unsigned char, kKeyBytes>& key, const Header& h);
  void Update(std::span<const std::byte> piece);
  std::array<unsigned char, kTagBytes> Final();

 private:
  alignas(16) std::array<unsigned char, 512> state_{};  // crypto_auth_hmacsha512256_state (416 B)
};

/// Fills h.header_tag and returns the body_tag of `body` (sent in one piece).
std::array<unsigned char, kTagBytes> Seal(const std::array<unsigned char, kKeyBytes>& key, Header& h,
                                          std::span<const std::byte> body);

/// Constant-time tag comparison (sodium_memcmp).
bool TagsEqual(const std::array<unsigned char, kTagBytes>& a, const std::array<unsigned char, kTagBytes>& b);
/// A fresh random nonce (randombytes_buf).
std::array<unsigned char, kNonceBytes> NewNonce();
/// sodium_init once; false if libsodium cannot initialise (no entropy source).
bool InitCrypto();

/// The header checks every receiver runs before reading a body, in this order: magic (kGarbage),
/// version (kVersion). Type and size checks depend on the receiver.
Refusal CheckMagicAndVersion(const Header& h);

}  // namespace palpa::net
