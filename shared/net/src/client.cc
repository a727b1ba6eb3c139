#include "palpa/net/client.h"

#include <fcntl.h>
#include <sodium.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <charconv>
#include <cinttypes>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <span>
#include <string_view>
#include <vector>

#include "palpa/io/atomic_file.h"
#include "palpa/io/escape.h"
#include "palpa/net/socket.h"

namespace palpa::net {
namespace {

NetError Err(NetErrorCode code, std::string message) {
  return NetError{code, Refusal::kNone, std::move(message), false};
}

std::string Where(const Endpoint& e) { return e.host + ":" + std::to_string(e.port); }

NetError IoErr(IoResult r, const Endpoint& to, const char* doing) {
  switch (r) {
    case IoResult::kTimeout:
      return Err(NetErrorCode::kTimeout, Where(to) + ": no answer while " + doing + " (timed out)");
    case IoResult::kEof:
      return Err(NetErrorCode::kProtocol, Where(to) + ": the controller closed the connection while " + doing);
    default:
      return Err(NetErrorCode::kIo, Where(to) + ": socket error while " + doing + ": " + std::strerror(errno));
  }
}

// One connection's exchange state: the server nonce from HELLO and our own nonce.
struct Session {
  Socket sock;
  Header hello;
  HelloBody hello_body;
  std::array<unsigned char, kNonceBytes> client_nonce{};
};

std::expected<Session, NetError> Open(const Endpoint& to, std::int64_t deadline_ns) {
  if (!InitCrypto()) return std::unexpected(Err(NetErrorCode::kIo, "libsodium could not initialise"));
  auto sock = ConnectTcp(to.host, to.port, deadline_ns);
  if (!sock) return std::unexpected(Err(NetErrorCode::kConnect, sock.error()));
  Session s;
  s.sock = std::move(*sock);
  std::size_t got = 0;
  if (const IoResult r = RecvAll(s.sock.fd(), WritableBytes(s.hello), deadline_ns, 0, got); r != IoResult::kOk)
    return std::unexpected(IoErr(r, to, "waiting for the controller's HELLO"));
  if (CheckMagicAndVersion(s.hello) != Refusal::kNone ||
      s.hello.type != static_cast<std::uint16_t>(MessageType::kHello) || s.hello.body_size != sizeof(HelloBody))
    return std::unexpected(Err(NetErrorCode::kProtocol, Where(to) + ": not a palpad upload listener (bad HELLO)"));
  std::array<std::byte, sizeof(HelloBody) + kTagBytes> rest{};
  if (const IoResult r = RecvAll(s.sock.fd(), rest, deadline_ns, 0, got); r != IoResult::kOk)
    return std::unexpected(IoErr(r, to, "reading the controller's HELLO"));
  std::memcpy(&s.hello_body, rest.data(), sizeof(HelloBody));
  s.client_nonce = NewNonce();
  return s;
}

Header RequestHeader(const Session& s, MessageType type, std::uint64_t body_size) {
  Header h;
  h.magic = kMagic;
  h.version = kVersion;
  h.type = static_cast<std::uint16_t>(type);
  h.body_size = body_size;
  h.server_nonce = s.hello.server_nonce;
  h.client_nonce = s.client_nonce;
  return h;
}

// A reply: header, body (≤ kMaxControlBody) and tag; authenticated against both nonces.
struct Reply {
  Header header;
  std::vector<std::byte> body;
  bool authenticated = false;
  bool mac_ok = false;        // its MACs verify under our key (it came from a palpad holding our key)
  bool nonces_match = false;  // it answers this request (both nonces echoed)
};

std::expected<Reply, NetError> ReadReply(const Session& s, const Key& key, const Endpoint& to,
                                         std::int64_t deadline_ns) {
  Reply r;
  std::size_t got = 0;
  if (const IoResult io = RecvAll(s.sock.fd(), WritableBytes(r.header), deadline_ns, 0, got); io != IoResult::kOk)
    return std::unexpected(IoErr(io, to, "waiting for the controller's answer"));
  if (CheckMagicAndVersion(r.header) != Refusal::kNone || r.header.body_size > kMaxControlBody)
    return std::unexpected(Err(NetErrorCode::kProtocol, Where(to) + ": the controller's answer is not this protocol"));
  r.body.resize(static_cast<std::size_t>(r.header.body_size));
  std::array<unsigned char, kTagBytes> tag{};
  if (const IoResult io = RecvAll(s.sock.fd(), r.body, deadline_ns, 0, got); io != IoResult::kOk)
    return std::unexpected(IoErr(io, to, "reading the controller's answer"));
  if (const IoResult io = RecvAll(s.sock.fd(), WritableBytes(tag), deadline_ns, 0, got); io != IoResult::kOk)
    return std::unexpected(IoErr(io, to, "reading the controller's answer"));
  BodyMac mac(key.bytes, r.header);
  mac.Update(r.body);
  r.nonces_match = r.header.server_nonce == s.hello.server_nonce && r.header.client_nonce == s.client_nonce;
  r.mac_ok = TagsEqual(HeaderTag(key.bytes, r.header), r.header.header_tag) && TagsEqual(mac.Final(), tag);
  r.authenticated = r.nonces_match && r.mac_ok;
  return r;
}

// A REFUSED reply as a NetError; anything else unauthenticated is kBadReply.
NetError RefusalOrBadReply(const Reply& r, const Endpoint& to) {
  if (r.header.type == static_cast<std::uint16_t>(MessageType::kRefused) && r.body.size() == sizeof(RefusedBody)) {
    RefusedBody b;
    std::memcpy(&b, r.body.data(), sizeof b);
    b.text.back() = '\0';
    NetError e{NetErrorCode::kRefused, static_cast<Refusal>(b.refusal), b.text.data(), r.authenticated};
    if (!r.authenticated) e.message += " (this answer is not authenticated under our key)";
    return e;
  }
  // A reply whose MACs verify but whose nonces belong to another exchange is a replay (or a stale
  // answer), not a key problem: say which, so nobody rotates a good key.
  if (!r.authenticated && r.mac_ok)
    return Err(NetErrorCode::kBadReply, Where(to) +
                                            ": the controller's answer is signed with this key but belongs to "
                                            "another exchange (its nonces are not this request's): a replayed or "
                                            "stale answer, ignored");
  if (!r.authenticated)
    return Err(NetErrorCode::kBadReply,
               Where(to) +
                   ": the controller's answer does not authenticate with this key (a different key, or "
                   "altered in transit)");
  return Err(NetErrorCode::kProtocol, Where(to) + ": unexpected answer type " + std::to_string(r.header.type));
}

void AppendNumber(std::string& out, const char* key, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "\"%s\": %.17g", key, v);
  out += buf;
}
void AppendU64(std::string& out, const char* key, std::uint64_t v) {
  char buf[96];
  std::snprintf(buf, sizeof buf, "\"%s\": %llu", key, static_cast<unsigned long long>(v));
  out += buf;
}
void AppendVec(std::string& out, const char* key, const std::array<double, 3>& v) {
  char buf[128];
  std::snprintf(buf, sizeof buf, "\"%s\": [%.17g, %.17g, %.17g]", key, v[0], v[1], v[2]);
  out += buf;
}

}  // namespace

std::expected<Endpoint, NetError> ParseEndpoint(std::string_view text) {
  const auto bad = [&](const char* why) {
    std::string m = "'";
    m.append(text).append("': ").append(why).append(" (HOST:PORT)");
    return std::unexpected(Err(NetErrorCode::kBadEndpoint, std::move(m)));
  };
  const auto colon = text.rfind(':');
  if (colon == std::string_view::npos || colon == 0) return bad("no host or port");
  std::string_view host = text.substr(0, colon);
  const std::string_view port = text.substr(colon + 1);
  if (host.front() == '[') {
    if (host.size() < 3 || host.back() != ']') return bad("unbalanced [ ]");
    host = host.substr(1, host.size() - 2);
  }
  unsigned value = 0;
  const auto [ptr, ec] = std::from_chars(port.data(), port.data() + port.size(), value);
  if (port.empty() || ec != std::errc() || ptr != port.data() + port.size() || value == 0 || value > 65535)
    return bad("the port must be a number in 1..65535");
  return Endpoint{std::string(host), static_cast<std::uint16_t>(value)};
}

std::string ToJson(const ControllerStatus& s) {
  std::string o = "{";
  char crc[32];
  std::snprintf(crc, sizeof crc, "\"field_crc32c\": \"0x%08" PRIx32 "\", ", s.field_crc32c);
  o += crc;
  char dims[96];
  std::snprintf(dims, sizeof dims, "\"dims\": [%u, %u, %u], ", s.dims[0], s.dims[1], s.dims[2]);
  o += dims;
  AppendNumber(o, "voxel_m", s.voxel_m), o += ", ";
  AppendU64(o, "field_bytes", s.field_bytes), o += ", ";
  AppendU64(o, "swaps", s.swaps), o += ", ";
  o += s.swap_ramp ? "\"swap_ramp\": true, " : "\"swap_ramp\": false, ";
  AppendU64(o, "ticks", s.ticks), o += ", ";
  AppendU64(o, "overruns", s.overruns), o += ", ";
  char tick[64];
  std::snprintf(tick, sizeof tick, "\"max_tick_ns\": %lld, ", static_cast<long long>(s.max_tick_ns));
  o += tick;
  AppendU64(o, "force_clamps", s.force_clamps), o += ", ";
  AppendU64(o, "estops", s.estops), o += ", ";
  AppendU64(o, "contact_ticks", s.contact_ticks), o += ", ";
  AppendU64(o, "dropped", s.dropped), o += ", ";
  AppendU64(o, "uploads_accepted", s.uploads_accepted), o += ", ";
  AppendU64(o, "uploads_refused", s.uploads_refused), o += ", ";
  AppendU64(o, "last_tick", s.last_tick), o += ", ";
  AppendNumber(o, "t_s", s.t_s), o += ", ";
  AppendVec(o, "hip_m", s.hip_m), o += ", ";
  AppendVec(o, "proxy_m", s.proxy_m), o += ", ";
  AppendVec(o, "force_n", s.force_n), o += ", ";
  o += s.contact ? "\"contact\": true, " : "\"contact\": false, ";
  AppendNumber(o, "rate_hz", s.rate_hz), o += ", ";
  o += s.running ? "\"running\": true}" : "\"running\": false}";
  return o;
}

std::expected<Key, NetError> ReadKeyFile(const std::string& path) {
  const auto fail = [&](const std::string& why) {
    return std::unexpected(Err(NetErrorCode::kKeyFile, path + ": " + why));
  };
  // A symbolic link is refused (a key is read only where it was made), naming what it points to;
  // O_NONBLOCK so that a FIFO is refused by fstat below instead of blocking the open for ever.
  struct stat link {};
  if (lstat(path.c_str(), &link) == 0 && S_ISLNK(link.st_mode)) {
    char* resolved = realpath(path.c_str(), nullptr);
    std::string target;
    if (resolved != nullptr) {
      target = io::Escape(resolved, 256);
    } else {
      char to[4096];
      const ssize_t n = readlink(path.c_str(), to, sizeof to);
      target =
          io::Escape(std::string_view(to, n > 0 ? static_cast<std::size_t>(n) : 0), 256) + " (which does not resolve)";
    }
    std::free(resolved);
    return fail("is a symbolic link to " + target +
                "; key files are not read through links (name the key file itself: --key-file " + target + ")");
  }
  const int fd = open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW | O_NONBLOCK);
  if (fd < 0) return fail(std::string("cannot open key file: ") + std::strerror(errno));
  Socket closer(fd);  // an owned fd, closed on return
  struct stat st {};
  if (fstat(fd, &st) != 0) return fail(std::string("cannot stat key file: ") + std::strerror(errno));
  if (!S_ISREG(st.st_mode)) return fail("not a regular file (a key file must be one, made by palpa keygen)");
  if ((st.st_mode & 077) != 0) {
    char mode[8];
    std::snprintf(mode, sizeof mode, "%04o", static_cast<unsigned>(st.st_mode & 07777));
    return fail(std::string("key file has mode ") + mode +
                ": group/other may read it; refusing to use it (chmod 600, or make a new key with palpa keygen)");
  }
  if (st.st_size != static_cast<off_t>(kKeyBytes))
    return fail("key file must hold exactly 32 bytes, it holds " + std::to_string(st.st_size) + " (palpa keygen)");
  Key k;
  std::size_t got = 0;
  while (got < k.bytes.size()) {
    const ssize_t n = read(fd, k.bytes.data() + got, k.bytes.size() - got);
    if (n <= 0) {
      if (n < 0 && errno == EINTR) continue;
      return fail("cannot read key file");
    }
    got += static_cast<std::size_t>(n);
  }
  return k;
}

std::expected<void, NetError> WriteNewKeyFile(const std::string& path, bool force) {
  const auto fail = [&](const std::string& why) {
    return std::unexpected(Err(NetErrorCode::kKeyFile, path + ": " + why));
  };
  if (!InitCrypto()) return fail("libsodium could not initialise");
  struct stat st {};
  if (!force && lstat(path.c_str(), &st) == 0) return fail("exists; refusing to overwrite a key (--force replaces it)");
  // Created 0600 (never readable by others, not even as the temporary) and unbuffered, so that
  // no stdio buffer keeps a copy of the key after it is zeroed.
  auto file = io::AtomicFile::Create(path, {.mode = 0600});
  if (!file) return std::unexpected(Err(NetErrorCode::kKeyFile, std::move(file.error())));
  std::setvbuf(file->file(), nullptr, _IONBF, 0);
  Key k;
  randombytes_buf(k.bytes.data(), k.bytes.size());
  auto written = file->Append(std::as_bytes(std::span(k.bytes)));
  sodium_memzero(k.bytes.data(), k.bytes.size());
  if (written) written = file->Commit();
  if (!written) return std::unexpected(Err(NetErrorCode::kKeyFile, std::move(written.error())));
  return {};
}

std::expected<ControllerStatus, NetError> FetchStatus(const Endpoint& to, const Key& key,
                                                      std::chrono::milliseconds timeout) {
  const std::int64_t deadline = NowNs() + static_cast<std::int64_t>(timeout.count()) * 1'000'000;
  auto session = Open(to, deadline);
  if (!session) return std::unexpected(std::move(session.error()));
  Header h = RequestHeader(*session, MessageType::kStatusRequest, 0);
  const auto tag = Seal(key.bytes, h, {});
  std::array<std::byte, kHeaderSize + kTagBytes> msg{};
  std::memcpy(msg.data(), &h, kHeaderSize);
  std::memcpy(msg.data() + kHeaderSize, tag.data(), kTagBytes);
  if (const IoResult r = SendAll(session->sock.fd(), msg, deadline); r != IoResult::kOk)
    return std::unexpected(IoErr(r, to, "sending the status request"));
  auto reply = ReadReply(*session, key, to, deadline);
  if (!reply) return std::unexpected(std::move(reply.error()));
  if (!reply->authenticated || reply->header.type != static_cast<std::uint16_t>(MessageType::kStatusReply) ||
      reply->body.size() != sizeof(StatusBody))
    return std::unexpected(RefusalOrBadReply(*reply, to));
  StatusBody b;
  std::memcpy(&b, reply->body.data(), sizeof b);
  ControllerStatus s;
  s.field_crc32c = b.field_crc32c;
  s.dims = b.dims;
  s.voxel_m = b.voxel_m;
  s.field_bytes = b.field_bytes;
  s.swaps = b.swaps;
  s.swap_ramp = (b.flags & kStatusSwapRamp) != 0;
  s.ticks = b.ticks;
  s.overruns = b.overruns;
  s.max_tick_ns = b.max_tick_ns;
  s.force_clamps = b.force_clamps;
  s.estops = b.estops;
  s.contact_ticks = b.contact_ticks;
  s.dropped = b.dropped;
  s.uploads_accepted = b.uploads_accepted;
  s.uploads_refused = b.uploads_refused;
  s.last_tick = b.last_tick;
  s.t_s = b.t_s;
  s.hip_m = b.hip_m;
  s.proxy_m = b.proxy_m;
  s.force_n = b.force_n;
  s.contact = (b.flags & kStatusContact) != 0;
  s.rate_hz = b.rate_hz;
  s.running = (b.flags & kStatusRunning) != 0;
  return s;
}

std::expected<UploadAccepted, NetError> Upload(const Endpoint& to, const Key& key, std::span<const std::byte> blob,
                                               std::chrono::milliseconds timeout) {
  const std::int64_t timeout_ns = static_cast<std::int64_t>(timeout.count()) * 1'000'000;
  auto session = Open(to, NowNs() + timeout_ns);
  if (!session) return std::unexpected(std::move(session.error()));
  Header h = RequestHeader(*session, MessageType::kUpload, blob.size());
  h.header_tag = HeaderTag(key.bytes, h);
  if (const IoResult r = SendAll(session->sock.fd(), Bytes(h), NowNs() + timeout_ns); r != IoResult::kOk)
    return std::unexpected(IoErr(r, to, "sending the upload header"));
  // palpad checks the header (size, nonce, key) before any body byte travels: CONTINUE or REFUSED.
  auto go = ReadReply(*session, key, to, NowNs() + timeout_ns);
  if (!go) return std::unexpected(std::move(go.error()));
  if (!go->authenticated || go->header.type != static_cast<std::uint16_t>(MessageType::kContinue))
    return std::unexpected(RefusalOrBadReply(*go, to));
  BodyMac mac(key.bytes, h);
  constexpr std::size_t kChunk = 1 << 20;
  for (std::size_t off = 0; off < blob.size(); off += kChunk) {
    const auto piece = blob.subspan(off, std::min(kChunk, blob.size() - off));
    mac.Update(piece);
    if (const IoResult r = SendAll(session->sock.fd(), piece, NowNs() + timeout_ns); r != IoResult::kOk) {
      // palpad may have refused mid-body (its read deadline): show its reason if it sent one.
      if (auto late = ReadReply(*session, key, to, NowNs() + timeout_ns); late)
        return std::unexpected(RefusalOrBadReply(*late, to));
      return std::unexpected(IoErr(r, to, "sending the blob"));
    }
  }
  const auto tag = mac.Final();
  if (const IoResult r = SendAll(session->sock.fd(), Bytes(tag), NowNs() + timeout_ns); r != IoResult::kOk)
    return std::unexpected(IoErr(r, to, "sending the blob"));
  auto reply = ReadReply(*session, key, to, NowNs() + timeout_ns);
  if (!reply) return std::unexpected(std::move(reply.error()));
  if (!reply->authenticated || reply->header.type != static_cast<std::uint16_t>(MessageType::kUploadAccepted) ||
      reply->body.size() != sizeof(AcceptedBody))
    return std::unexpected(RefusalOrBadReply(*reply, to));
  AcceptedBody b;
  std::memcpy(&b, reply->body.data(), sizeof b);
  return UploadAccepted{b.crc32c, b.dims, b.voxel_m, b.swaps};
}

}  // namespace palpa::net
