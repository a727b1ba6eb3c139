// Upload to a running palpad (issue 7; docs/upload.md), through the real processes: palpad
// --listen on 127.0.0.1 with an ephemeral port, replaying a trace paced on the simulated device,
// and the client library (shared/net) or raw sockets speaking the documented wire format.
// Every refusal is checked on both sides (the client's reason, palpad's log line) and against
// the field in use (its CRC-32C from the blob itself, via palpa status). The 1,000-swap test
// checks the loop's per-tick output against the ramp's bound.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "palpa/blob/blob.h"
#include "palpa/net/client.h"
#include "palpa/net/protocol.h"
#include "palpa/net/socket.h"

extern char** environ;

namespace palpa::net {
namespace {

using namespace std::chrono_literals;

std::string ReadAll(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::ostringstream s;
  s << f.rdbuf();
  return s.str();
}

std::vector<std::byte> ReadBytes(const std::string& path) {
  const std::string s = ReadAll(path);
  std::vector<std::byte> b(s.size());
  std::memcpy(b.data(), s.data(), s.size());
  return b;
}

int RunCommand(const std::string& cmd) {
  const int status = std::system(cmd.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::uint32_t CrcOf(const std::vector<std::byte>& blob) {
  const auto view = blob::Verify(blob);
  return view ? view->crc32c : 0;
}

// Fields, a trace and keys shared by every test (built once with the real palpa).
struct Inputs {
  std::string dir;
  std::string a, b, trace, key, other_key;
  std::vector<std::byte> a_bytes, b_bytes;
  Key k, other;
};

std::string g_dir;  // removed at exit (every test's files live in it)

void RemoveDir() {
  if (!g_dir.empty()) (void)RunCommand("rm -rf '" + g_dir + "'");
}

const Inputs& Shared() {
  static const Inputs in = [] {
    Inputs i;
    i.dir = ::testing::TempDir() + "/upload_process_XXXXXX";
    if (mkdtemp(i.dir.data()) == nullptr) std::abort();
    g_dir = i.dir;
    std::atexit(RemoveDir);
    const std::string palpa = PALPA_PATH;
    const std::string data = PALPA_DATA_DIR;
    i.a = i.dir + "/a.palpa";
    i.b = i.dir + "/b.palpa";
    i.trace = i.dir + "/t.ptb";
    i.key = i.dir + "/k";
    i.other_key = i.dir + "/k2";
    // Two different real fields of one object, the second 5 % larger (radius 31.5 mm instead of
    // 30 mm): a stroke 2 mm deep in one is 3.5 mm deep in the other, so a swap without the ramp
    // would step the force by about k·1.5 mm = 1.2 N.
    if (RunCommand(palpa + " build " + data + "/sphere926.pwn -o " + i.a + " --cells 40 -q") != 0 ||
        RunCommand(palpa + " build " + data + "/sphere926.pwn -o " + i.b + " --cells 52 --fit 0.063 -q") != 0 ||
        RunCommand(palpa + " trace synth --field " + i.a +
                   " --kind strokes --depths 0.002,0.0022,0.002,0.0022,0.002,0.0022,0.002,0.0022,0.002,0.0022"
                   " --length 0.01 -o " +
                   i.trace + " >/dev/null") != 0 ||
        RunCommand(palpa + " keygen -o " + i.key + " >/dev/null") != 0 ||
        RunCommand(palpa + " keygen -o " + i.other_key + " >/dev/null") != 0)
      std::abort();
    i.a_bytes = ReadBytes(i.a);
    i.b_bytes = ReadBytes(i.b);
    i.k = *ReadKeyFile(i.key);
    i.other = *ReadKeyFile(i.other_key);
    return i;
  }();
  return in;
}

// palpad --listen as a child process; its stderr (the log) goes to a file.
class Palpad {
 public:
  explicit Palpad(const std::string& tag, std::vector<std::string> extra = {}) {
    const Inputs& in = Shared();
    log_ = in.dir + "/" + tag + ".log";
    out_ = in.dir + "/" + tag + ".csv";
    timing_ = in.dir + "/" + tag + ".timing.csv";
    summary_ = in.dir + "/" + tag + ".json";
    std::vector<std::string> args = {PALPAD_PATH,
                                     "--device",
                                     "sim",
                                     "--field",
                                     in.a,
                                     "--trace",
                                     in.trace,
                                     "--out",
                                     out_,
                                     "--record-timing",
                                     timing_,
                                     "--summary-json",
                                     summary_,
                                     "--listen",
                                     "127.0.0.1:0",
                                     "--key-file",
                                     in.key,
                                     "--max-blob",
                                     "1000000",
                                     "--net-timeout-ms",
                                     "300",
                                     "--overrun-limit",
                                     "0"};
    if (std::find(extra.begin(), extra.end(), "--net-timeout-ms") != extra.end()) {  // the test's own deadline
      const auto own = std::find(args.begin(), args.end(), "--net-timeout-ms");
      args.erase(own, own + 2);
    }
    for (auto& e : extra) args.push_back(e);
    std::vector<char*> argv;
    for (auto& s : args) argv.push_back(s.data());
    argv.push_back(nullptr);
    posix_spawn_file_actions_t fa;
    posix_spawn_file_actions_init(&fa);
    posix_spawn_file_actions_addopen(&fa, 2, log_.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
    posix_spawn_file_actions_addopen(&fa, 1, "/dev/null", O_WRONLY, 0);
    if (posix_spawn(&pid_, PALPAD_PATH, &fa, nullptr, argv.data(), environ) != 0) pid_ = -1;
    posix_spawn_file_actions_destroy(&fa);
    // Wait for "listening on 127.0.0.1:PORT".
    for (int i = 0; i < 500 && port_ == 0; ++i) {
      const std::string log = ReadAll(log_);
      const auto at = log.find("listening on 127.0.0.1:");
      if (at != std::string::npos) port_ = static_cast<std::uint16_t>(std::atoi(log.c_str() + at + 23));
      if (port_ == 0) std::this_thread::sleep_for(10ms);
    }
  }
  ~Palpad() { Stop(); }
  int Stop() {
    if (pid_ <= 0) return exit_;
    kill(pid_, SIGTERM);
    int status = 0;
    waitpid(pid_, &status, 0);
    pid_ = -1;
    exit_ = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    return exit_;
  }
  Endpoint endpoint() const { return {"127.0.0.1", port_}; }
  std::uint16_t port() const { return port_; }
  std::string log() const { return ReadAll(log_); }
  const std::string& out() const { return out_; }
  const std::string& timing() const { return timing_; }
  const std::string& summary() const { return summary_; }

 private:
  pid_t pid_ = -1;
  std::uint16_t port_ = 0;
  int exit_ = -1;
  std::string log_, out_, timing_, summary_;
};

std::uint32_t FieldInUse(const Palpad& p) {
  const auto s = FetchStatus(p.endpoint(), Shared().k, 2000ms);
  return s ? s->field_crc32c : 0;
}

// A raw client: the HELLO read, then whatever the test sends.
struct Raw {
  Socket sock;
  Header hello;
};

Raw RawOpen(std::uint16_t port) {
  Raw r;
  auto s = ConnectTcp("127.0.0.1", port, NowNs() + 2'000'000'000);
  if (!s) return r;
  r.sock = std::move(*s);
  std::array<std::byte, kHeaderSize + sizeof(HelloBody) + kTagBytes> m{};
  std::size_t got = 0;
  if (RecvAll(r.sock.fd(), m, NowNs() + 2'000'000'000, 0, got) == IoResult::kOk)
    std::memcpy(&r.hello, m.data(), kHeaderSize);
  return r;
}

Header UploadHeader(const Header& hello, const Key& key, std::uint64_t size) {
  Header h;
  h.magic = kMagic;
  h.version = kVersion;
  h.type = static_cast<std::uint16_t>(MessageType::kUpload);
  h.body_size = size;
  h.server_nonce = hello.server_nonce;
  h.client_nonce = NewNonce();
  h.header_tag = HeaderTag(key.bytes, h);
  return h;
}

bool Send(const Raw& r, std::span<const std::byte> b) {
  return SendAll(r.sock.fd(), b, NowNs() + 2'000'000'000) == IoResult::kOk;
}

// Reads one reply: its type and, for REFUSED, the refusal and text.
struct RawReply {
  std::uint16_t type = 0;
  Refusal refusal = Refusal::kNone;
  std::string text;
};
RawReply ReadRawReply(const Raw& r) {
  RawReply out;
  Header h;
  std::size_t got = 0;
  if (RecvAll(r.sock.fd(), std::as_writable_bytes(std::span<Header>(&h, 1)), NowNs() + 3'000'000'000, 0, got) !=
      IoResult::kOk)
    return out;
  out.type = h.type;
  std::vector<std::byte> body(static_cast<std::size_t>(std::min<std::uint64_t>(h.body_size, 4096)) + kTagBytes);
  if (RecvAll(r.sock.fd(), body, NowNs() + 3'000'000'000, 0, got) != IoResult::kOk) return out;
  if (h.type == static_cast<std::uint16_t>(MessageType::kRefused) && h.body_size == sizeof(RefusedBody)) {
    RefusedBody b;
    std::memcpy(&b, body.data(), sizeof b);
    b.text.back() = '\0';
    out.refusal = static_cast<Refusal>(b.refusal);
    out.text = b.text.data();
  }
  return out;
}

bool LogHas(const Palpad& p, const std::string& what) { return p.log().find(what) != std::string::npos; }

TEST(UploadProcess, StatusReportsTheFieldAndAnAcceptedUploadSwapsIt) {
  const Inputs& in = Shared();
  Palpad p("accept");
  ASSERT_NE(p.port(), 0) << p.log();
  // palpad's listener starts just before its servo loop: a status fetched in between, on a
  // loaded machine, reads "not running" (CI, 2026-11-27). Asked again for up to 2 s; a loop that
  // ended (a fault) still reads false.
  auto s = FetchStatus(p.endpoint(), in.k, 2000ms);
  for (int again = 0; again < 20 && s.has_value() && !s->running; ++again) {
    std::this_thread::sleep_for(100ms);
    s = FetchStatus(p.endpoint(), in.k, 2000ms);
  }
  ASSERT_TRUE(s.has_value()) << s.error().message;
  EXPECT_EQ(s->field_crc32c, CrcOf(in.a_bytes));
  EXPECT_EQ(s->field_bytes, in.a_bytes.size());
  EXPECT_TRUE(s->running);
  EXPECT_EQ(s->rate_hz, 1000);
  const auto up = Upload(p.endpoint(), in.k, in.b_bytes, 5000ms);
  ASSERT_TRUE(up.has_value()) << up.error().message;
  EXPECT_EQ(up->field_crc32c, CrcOf(in.b_bytes));
  EXPECT_EQ(up->swaps, 1u);
  const auto view = blob::Verify(in.b_bytes);
  ASSERT_TRUE(view.has_value());
  for (std::size_t a = 0; a < 3; ++a) EXPECT_EQ(up->dims[a], static_cast<std::uint32_t>(view->dims[a]));
  std::this_thread::sleep_for(50ms);
  s = FetchStatus(p.endpoint(), in.k, 2000ms);
  ASSERT_TRUE(s.has_value());
  EXPECT_EQ(s->field_crc32c, CrcOf(in.b_bytes));
  EXPECT_EQ(s->swaps, 1u);
  EXPECT_EQ(s->uploads_accepted, 1u);
  EXPECT_GT(s->ticks, 0u);
  EXPECT_TRUE(LogHas(p, "accepted: field crc32c")) << p.log();
}

TEST(UploadProcess, EveryRefusalHasAReasonOnBothSidesAndKeepsTheField) {
  const Inputs& in = Shared();
  Palpad p("refuse");
  ASSERT_NE(p.port(), 0) << p.log();
  const std::uint32_t a_crc = CrcOf(in.a_bytes);
  ASSERT_EQ(FieldInUse(p), a_crc);
  int refusals = 0;
  const auto expect_refused = [&](const char* what, Refusal expected, Refusal got, const std::string& client_text,
                                  const std::string& log_name) {
    SCOPED_TRACE(what);
    std::printf("[ refused ] %-12s client: %s\n", what, client_text.c_str());
    EXPECT_EQ(got, expected) << client_text;
    EXPECT_NE(client_text.find(log_name), std::string::npos) << client_text;
    // palpad logs the same sentence; give the log a moment (the refusal is logged before it is sent).
    EXPECT_TRUE(LogHas(p, "refused: " + log_name)) << p.log();
    EXPECT_EQ(FieldInUse(p), a_crc) << "a refused upload must leave the field in use";
    ++refusals;
  };

  {  // wrong key
    const auto r = Upload(p.endpoint(), in.other, in.b_bytes, 3000ms);
    ASSERT_FALSE(r.has_value());
    EXPECT_EQ(r.error().code, NetErrorCode::kRefused);
    EXPECT_FALSE(r.error().reply_authenticated);
    expect_refused("wrong key", Refusal::kWrongKey, r.error().refusal, r.error().message, "wrong key");
  }
  {  // replayed: a request recorded on one connection, sent on another
    Raw first = RawOpen(p.port());
    const Header recorded = UploadHeader(first.hello, in.k, in.b_bytes.size());
    first.sock = Socket();
    Raw second = RawOpen(p.port());
    ASSERT_TRUE(Send(second, std::as_bytes(std::span<const Header>(&recorded, 1))));
    const RawReply r = ReadRawReply(second);
    expect_refused("replayed", Refusal::kReplayed, r.refusal, r.text, "replayed");
  }
  {  // oversize: refused from the header, before any body byte is sent
    const std::vector<std::byte> big(1'000'001);
    const auto r = Upload(p.endpoint(), in.k, big, 3000ms);
    ASSERT_FALSE(r.has_value());
    EXPECT_TRUE(r.error().reply_authenticated);
    expect_refused("oversize", Refusal::kOversize, r.error().refusal, r.error().message, "oversize");
    EXPECT_NE(r.error().message.find("1000001"), std::string::npos) << r.error().message;
  }
  {  // slow: the body stops arriving; palpad's 300 ms read deadline refuses it
    Raw raw = RawOpen(p.port());
    const Header h = UploadHeader(raw.hello, in.k, in.b_bytes.size());
    ASSERT_TRUE(Send(raw, std::as_bytes(std::span<const Header>(&h, 1))));
    EXPECT_EQ(ReadRawReply(raw).type, static_cast<std::uint16_t>(MessageType::kContinue));
    ASSERT_TRUE(Send(raw, std::span<const std::byte>(in.b_bytes).first(1000)));
    const auto t0 = std::chrono::steady_clock::now();
    const RawReply r = ReadRawReply(raw);
    const auto waited = std::chrono::steady_clock::now() - t0;
    EXPECT_GE(waited, 250ms);
    EXPECT_LT(waited, 2500ms);
    expect_refused("slow", Refusal::kTimeout, r.refusal, r.text, "timeout");
    EXPECT_NE(r.text.find("1000 of " + std::to_string(in.b_bytes.size())), std::string::npos) << r.text;
  }
  {  // half-sent: the client closes mid-body
    Raw raw = RawOpen(p.port());
    const Header h = UploadHeader(raw.hello, in.k, in.b_bytes.size());
    ASSERT_TRUE(Send(raw, std::as_bytes(std::span<const Header>(&h, 1))));
    EXPECT_EQ(ReadRawReply(raw).type, static_cast<std::uint16_t>(MessageType::kContinue));
    ASSERT_TRUE(Send(raw, std::span<const std::byte>(in.b_bytes).first(5000)));
    raw.sock = Socket();
    std::this_thread::sleep_for(100ms);
    EXPECT_TRUE(LogHas(p, "refused: half-sent: the connection closed after 5000 of")) << p.log();
    EXPECT_EQ(FieldInUse(p), a_crc);
    ++refusals;
  }
  {  // garbage bytes instead of a header
    Raw raw = RawOpen(p.port());
    const std::string junk(200, 'x');
    ASSERT_TRUE(Send(raw, std::as_bytes(std::span<const char>(junk.data(), junk.size()))));
    const RawReply r = ReadRawReply(raw);
    expect_refused("garbage", Refusal::kGarbage, r.refusal, r.text, "garbage");
  }
  {  // a blob that fails Verify: one payload byte changed (the CRC no longer matches)
    std::vector<std::byte> bad = in.b_bytes;
    bad[bad.size() - 3] ^= std::byte{0x40};
    const auto local = blob::Verify(bad);
    ASSERT_FALSE(local.has_value());
    const auto r = Upload(p.endpoint(), in.k, bad, 3000ms);
    ASSERT_FALSE(r.has_value());
    expect_refused("invalid blob", Refusal::kBlobInvalid, r.error().refusal, r.error().message, "invalid blob");
    EXPECT_NE(r.error().message.find(local.error().what()), std::string::npos)
        << "palpad's reason is the verifier's field-and-byte sentence: " << r.error().message;
  }
  {  // body altered in transit: a correct header, a body whose tag does not match
    Raw raw = RawOpen(p.port());
    const Header h = UploadHeader(raw.hello, in.k, in.b_bytes.size());
    ASSERT_TRUE(Send(raw, std::as_bytes(std::span<const Header>(&h, 1))));
    EXPECT_EQ(ReadRawReply(raw).type, static_cast<std::uint16_t>(MessageType::kContinue));
    ASSERT_TRUE(Send(raw, in.b_bytes));
    const std::array<std::byte, kTagBytes> zero_tag{};
    ASSERT_TRUE(Send(raw, zero_tag));
    const RawReply r = ReadRawReply(raw);
    expect_refused("body tag", Refusal::kBodyTag, r.refusal, r.text, "body altered");
  }
  // The transcript: palpad's side of every refusal above.
  std::istringstream log(p.log());
  for (std::string line; std::getline(log, line);)
    if (line.find("refused") != std::string::npos) std::printf("[ palpad  ] %s\n", line.c_str());
  const auto s = FetchStatus(p.endpoint(), in.k, 2000ms);
  ASSERT_TRUE(s.has_value());
  EXPECT_EQ(s->uploads_refused, static_cast<std::uint64_t>(refusals));
  EXPECT_EQ(s->uploads_accepted, 0u);
  EXPECT_EQ(s->swaps, 0u);
  EXPECT_EQ(s->field_crc32c, a_crc);
}

TEST(UploadProcess, CliPrintsTheControllersAnswer) {
  const Inputs& in = Shared();
  Palpad p("cli");
  ASSERT_NE(p.port(), 0) << p.log();
  const std::string palpa = PALPA_PATH;
  const std::string to = " --to 127.0.0.1:" + std::to_string(p.port());
  const std::string err = in.dir + "/cli.err", out = in.dir + "/cli.out";
  EXPECT_EQ(RunCommand(palpa + " upload " + in.b + to + " --key-file " + in.key + " >" + out + " 2>" + err), 0)
      << ReadAll(err);
  EXPECT_NE(ReadAll(out).find("accepted by 127.0.0.1"), std::string::npos) << ReadAll(out);
  EXPECT_EQ(RunCommand(palpa + " upload " + in.a + to + " --key-file " + in.other_key + " >" + out + " 2>" + err), 1);
  EXPECT_NE(ReadAll(err).find("refused by 127.0.0.1:" + std::to_string(p.port()) + ": wrong key"), std::string::npos)
      << ReadAll(err);
  EXPECT_EQ(RunCommand(palpa + " status" + to + " --key-file " + in.key + " --json >" + out + " 2>" + err), 0);
  char crc[16];
  std::snprintf(crc, sizeof crc, "0x%08x", CrcOf(in.b_bytes));
  EXPECT_NE(ReadAll(out).find(std::string("\"field_crc32c\": \"") + crc), std::string::npos) << ReadAll(out);
  // A key file others can read is refused before anything is sent.
  const std::string loose = in.dir + "/loose.key";
  std::ofstream(loose, std::ios::binary) << ReadAll(in.key);
  chmod(loose.c_str(), 0644);
  EXPECT_EQ(RunCommand(palpa + " status" + to + " --key-file " + loose + " >" + out + " 2>" + err), 2);
  EXPECT_NE(ReadAll(err).find("group/other may read it"), std::string::npos) << ReadAll(err);
}

// Reads a CSV with a header line into rows of numbers.
std::vector<std::vector<double>> ReadCsv(const std::string& path) {
  std::vector<std::vector<double>> rows;
  std::istringstream in(ReadAll(path));
  std::string line;
  std::getline(in, line);  // header
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::vector<double> row;
    std::istringstream cells(line);
    for (std::string cell; std::getline(cells, cell, ',');) row.push_back(std::strtod(cell.c_str(), nullptr));
    rows.push_back(std::move(row));
  }
  return rows;
}

double Dist(double ax, double ay, double az, double bx, double by, double bz) {
  return std::sqrt((ax - bx) * (ax - bx) + (ay - by) * (ay - by) + (az - bz) * (az - bz));
}

// 1,000 accepted swaps between two real fields while a stroke trace replays in contact, paced at
// 1 kHz, with refused uploads of four kinds interleaved (every 10th swap) and three slow ones.
// Checks: every swap is taken by exactly one tick; no swap's own work overruns (at most 1 % of the
// swap ticks, the hypervisor's stalls); the force never steps by more than
// the cross-fade's slope plus the HIP's own effect, B = 2·F_max/N + k·3·max|ΔX_h| (N = ramp ticks;
// the new field's force at tick n differs from the held one by ≤ 2·F_max, of which 1/N is added
// per tick; in steady contact on a sphere the proxy moves at most ~R/(R − depth) ≤ 2 times the
// HIP, so |Δ(X_p − X_h)| ≤ 3|ΔX_h|); the field in use after each refusal is the last accepted one.
TEST(UploadProcess, ThousandSwapsWhileInContactNeverStepTheForce) {
  const Inputs& in = Shared();
  // PALPA_TEST_SWAP_RAMP_MS=0 shows the test failing without the ramp (docs/upload.md).
  const char* ramp_env = std::getenv("PALPA_TEST_SWAP_RAMP_MS");
  const std::string ramp_ms = ramp_env != nullptr ? ramp_env : "50";
  Palpad p("swap", {"--swap-ramp-ms", ramp_ms, "--rate", "1000"});
  ASSERT_NE(p.port(), 0) << p.log();
  const std::vector<std::byte>* blobs[2] = {&in.a_bytes, &in.b_bytes};
  const std::uint32_t crcs[2] = {CrcOf(in.a_bytes), CrcOf(in.b_bytes)};
  std::vector<std::byte> bad = in.b_bytes;
  bad[bad.size() - 3] ^= std::byte{0x40};
  std::uint32_t current = crcs[0];
  int accepted = 0, refused = 0, slow = 0;
  const auto t0 = std::chrono::steady_clock::now();
  while (accepted < 1000) {
    const int next = (accepted + 1) % 2;
    const auto r = Upload(p.endpoint(), in.k, *blobs[next], 5000ms);
    if (!r.has_value()) {
      for (int probe = 0; probe < 3; ++probe) {
        const auto st = FetchStatus(p.endpoint(), in.k, 2000ms);
        if (st)
          std::printf("probe: running %d ticks %llu last_tick %llu swaps %llu t_s %.3f\n", st->running ? 1 : 0,
                      static_cast<unsigned long long>(st->ticks), static_cast<unsigned long long>(st->last_tick),
                      static_cast<unsigned long long>(st->swaps), st->t_s);
        std::this_thread::sleep_for(200ms);
      }
    }
    ASSERT_TRUE(r.has_value()) << "swap " << accepted << ": " << r.error().message << "\npalpad's log ends: "
                               << p.log().substr(p.log().size() > 600 ? p.log().size() - 600 : 0);
    ASSERT_EQ(r->field_crc32c, crcs[next]);
    current = crcs[next];
    ++accepted;
    if (accepted % 10 != 0) continue;
    switch ((accepted / 10) % 4) {
      case 0: {
        const auto w = Upload(p.endpoint(), in.other, *blobs[1 - next], 3000ms);
        ASSERT_FALSE(w.has_value());
        EXPECT_EQ(w.error().refusal, Refusal::kWrongKey);
        break;
      }
      case 1: {
        const auto w = Upload(p.endpoint(), in.k, bad, 3000ms);
        ASSERT_FALSE(w.has_value());
        EXPECT_EQ(w.error().refusal, Refusal::kBlobInvalid);
        break;
      }
      case 2: {
        Raw raw = RawOpen(p.port());
        const Header h = UploadHeader(raw.hello, in.k, blobs[1 - next]->size());
        ASSERT_TRUE(Send(raw, std::as_bytes(std::span<const Header>(&h, 1))));
        ASSERT_EQ(ReadRawReply(raw).type, static_cast<std::uint16_t>(MessageType::kContinue));
        ASSERT_TRUE(Send(raw, std::span<const std::byte>(*blobs[1 - next]).first(20000)));
        if (slow < 3) {  // stall: palpad's read deadline refuses it
          EXPECT_EQ(ReadRawReply(raw).refusal, Refusal::kTimeout);
          ++slow;
        }
        break;  // otherwise closed mid-body: half-sent
      }
      default: {
        Raw raw = RawOpen(p.port());
        const std::string junk(300, '\x7f');
        ASSERT_TRUE(Send(raw, std::as_bytes(std::span<const char>(junk.data(), junk.size()))));
        EXPECT_EQ(ReadRawReply(raw).refusal, Refusal::kGarbage);
        break;
      }
    }
    ++refused;
    ASSERT_EQ(FieldInUse(p), current) << "after refusal " << refused << " the field in use changed";
  }
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  const auto status = FetchStatus(p.endpoint(), in.k, 2000ms);
  ASSERT_TRUE(status.has_value());
  EXPECT_TRUE(status->running) << "the trace must outlast the swaps";
  EXPECT_EQ(status->swaps, 1000u);
  ASSERT_EQ(p.Stop(), 0) << p.log();

  const auto rows = ReadCsv(p.out());
  const auto timing = ReadCsv(p.timing());
  ASSERT_EQ(rows.size(), timing.size());
  ASSERT_GT(rows.size(), 1000u);
  const double k = 800, f_max = 8, ramp_ticks = 50;
  std::size_t swap_overruns = 0;
  double max_compute_ns = 0, max_swap_compute_ns = 0;
  std::size_t swaps = 0, overruns = 0, contact = 0, first_swap = 0, last_swap = 0, loaded_swaps = 0;
  double max_dh = 0, max_step = 0, max_step_at_swap = 0;
  for (std::size_t t = 0; t < rows.size(); ++t) {
    const auto& r = rows[t];
    const auto flags = static_cast<std::uint32_t>(timing[t].back());
    if (flags & (1u << 3)) ++overruns;
    max_compute_ns = std::max(max_compute_ns, timing[t][3]);
    if (flags & (1u << 5)) {
      max_swap_compute_ns = std::max(max_swap_compute_ns, timing[t][3]);
      // An overrun the swap caused: its own compute took half the 1 ms period. (A late wake-up,
      // which the hypervisor causes on this shared VM whatever the tick does, is not the swap's.)
      if ((flags & (1u << 3)) != 0 && timing[t][3] > 0.5e6) ++swap_overruns;
      if (swaps == 0) first_swap = t;
      last_swap = t;
      ++swaps;
      if (t > 0 && Dist(rows[t - 1][7], rows[t - 1][8], rows[t - 1][9], 0, 0, 0) > 0.5) ++loaded_swaps;
    }
    if (t == 0) continue;
    const auto& q = rows[t - 1];
    max_dh = std::max(max_dh, Dist(r[1], r[2], r[3], q[1], q[2], q[3]));
    const double step = Dist(r[7], r[8], r[9], q[7], q[8], q[9]);
    max_step = std::max(max_step, step);
    if (flags & (1u << 5)) max_step_at_swap = std::max(max_step_at_swap, step);
  }
  for (std::size_t t = first_swap; t <= last_swap; ++t) contact += rows[t][10] != 0 ? 1u : 0u;
  const double bound = 2 * f_max / ramp_ticks + k * 3 * max_dh;
  const double contact_share = static_cast<double>(contact) / static_cast<double>(last_swap - first_swap + 1);
  std::printf(
      "[ swaps ] %d accepted, %d refused (%d slow) in %.1f s; %zu ticks, %zu swap ticks (%zu under > 0.5 N), "
      "%zu overruns, contact %.1f %% of the ticks between the first and last swap\n",
      accepted, refused, slow, seconds, rows.size(), swaps, loaded_swaps, overruns, 100 * contact_share);
  std::printf(
      "[ swaps ] max |dF| per tick %.4f N (at a swap tick %.4f N); bound 2*Fmax/N + 3k*max|dXh| = %.4f N "
      "(max |dXh| %.2f um/tick)\n",
      max_step, max_step_at_swap, bound, max_dh * 1e6);
  EXPECT_EQ(swaps, 1000u) << "each accepted swap is taken by exactly one tick";
  std::printf("[ swaps ] compute time: max %.1f us over all ticks, max %.1f us on the swap ticks\n",
              max_compute_ns / 1e3, max_swap_compute_ns / 1e3);
  // A missed tick on a shared 2-core VM can come from the hypervisor (docs/runtime.md: 1-4 per
  // 10 s at 1 kHz under load, cyclictest sees them too), and a stall that lands inside a swap
  // tick's compute is counted here: one did in CI (1,048 us, 1 of 1,000). A cost the swap itself
  // had would be paid at every swap, so more than 1 % of the swap ticks slow fails.
  std::printf("[ swaps ] swap ticks whose own compute missed the deadline: %zu of %zu\n", swap_overruns, swaps);
  EXPECT_LE(swap_overruns, swaps / 100) << "swap ticks' own work missed their deadline";
  // The machine's own wake-up tail, not the code: on 2026-11-27 this VM, idle, woke 0.9 % of
  // cyclictest's 1 kHz wake-ups over 1 ms late and 1.9 % over 0.5 ms (docs/runtime.md), and this
  // test saw 1.7-2.1 % of its ticks overrun. Over 5 % the machine is too loaded for the figures above
  // to mean anything.
  EXPECT_LE(overruns, rows.size() / 20) << "missed ticks: more than 5 % (machine overloaded?)";
  EXPECT_GT(contact_share, 0.5) << "the trace must be in contact most of the time";
  EXPECT_GT(loaded_swaps, 100u) << "many swaps must happen under load, or the bound proves nothing";
  EXPECT_LE(max_step, bound);
}

// Issue 18, finding 9: 200 unauthenticated clients that send 1 byte a second used to hold the
// listener one at a time for their whole header deadline, locking out every status and upload.
// Now each connection has its own worker and deadline: a status is answered while all 200 are
// still connected. The latency is printed (not asserted tightly: the machine is noisy); the
// bound, 4 s, is below the 5 s header deadline that served the first slow client before.
TEST(UploadProcess, StatusIsAnsweredWhileTwoHundredSlowClientsAreConnected) {
  const Inputs& in = Shared();
  Palpad p("slow", {"--net-timeout-ms", "5000"});
  ASSERT_NE(p.port(), 0) << p.log();
  constexpr int kSlow = 200;
  std::vector<Socket> slow;
  for (int i = 0; i < kSlow; ++i) {
    auto s = ConnectTcp("127.0.0.1", p.port(), NowNs() + 5'000'000'000);
    ASSERT_TRUE(s.has_value()) << s.error();
    slow.push_back(std::move(*s));
  }
  std::atomic<bool> stop{false};
  std::thread drip([&] {  // one byte of a valid magic per client per second
    const char magic[] = {'P', 'L', 'P', 'U'};
    for (int second = 0; !stop.load(); ++second) {
      const auto b = static_cast<std::byte>(magic[second % 4]);
      for (Socket& s : slow) (void)send(s.fd(), &b, 1, MSG_NOSIGNAL | MSG_DONTWAIT);
      for (int i = 0; i < 20 && !stop.load(); ++i) std::this_thread::sleep_for(50ms);
    }
  });
  std::this_thread::sleep_for(1500ms);  // every slow client has sent its first bytes
  const auto t0 = std::chrono::steady_clock::now();
  const auto st = FetchStatus(p.endpoint(), in.k, 4000ms);
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  int still_open = 0;  // read what the server sent (its HELLO); EAGAIN then means no EOF yet
  for (Socket& s : slow) {
    std::array<char, 512> buf{};
    ssize_t n = 0;
    while ((n = recv(s.fd(), buf.data(), buf.size(), MSG_DONTWAIT)) > 0) {
    }
    if (n < 0 && (errno == EAGAIN || errno == EWOULDBLOCK)) ++still_open;
  }
  stop = true;
  drip.join();
  std::printf("status answered in %.1f ms with %d slow clients connected (%d still open after it)\n", ms, kSlow,
              still_open);
  ASSERT_TRUE(st.has_value()) << st.error().message << "\n" << p.log();
  EXPECT_EQ(still_open, kSlow);  // served while every slow client was connected: none refused or evicted yet
  EXPECT_LT(ms, 4000.0);
}

// Past the cap (256 connections), the oldest unauthenticated connection is closed for the newest:
// 300 idle clients, then a status, which is answered, and palpad logs each eviction.
TEST(UploadProcess, PastTheConnectionCapTheOldestUnauthenticatedIsEvicted) {
  const Inputs& in = Shared();
  Palpad p("cap", {"--net-timeout-ms", "5000"});
  ASSERT_NE(p.port(), 0) << p.log();
  constexpr int kIdle = 300;
  std::vector<Socket> idle;
  for (int i = 0; i < kIdle; ++i) {
    auto s = ConnectTcp("127.0.0.1", p.port(), NowNs() + 5'000'000'000);
    ASSERT_TRUE(s.has_value()) << s.error();
    idle.push_back(std::move(*s));
  }
  const auto st = FetchStatus(p.endpoint(), in.k, 4000ms);
  ASSERT_TRUE(st.has_value()) << st.error().message << "\n" << p.log();
  const std::string log = p.log();
  std::size_t evictions = 0;
  for (std::size_t at = log.find("256 connections open, it was the oldest one not yet authenticated");
       at != std::string::npos; at = log.find("it was the oldest one not yet authenticated", at + 1))
    ++evictions;
  EXPECT_GE(evictions, static_cast<std::size_t>(kIdle + 1 - 256)) << log;
}

// Issue 18, finding 11: a recorded reply, replayed to a later request, verifies under the key
// but answers other nonces. The client used to call that "wrong key?", which sends the operator
// to rotate a good key; it now says it is a replayed or stale answer. A relay between the client
// and palpad records the first status reply and plays it back to the second request.
TEST(UploadProcess, AReplayedReplyIsReportedAsAReplayNotAWrongKey) {
  const Inputs& in = Shared();
  Palpad p("replay");
  ASSERT_NE(p.port(), 0) << p.log();
  auto relay = ListenTcp("127.0.0.1", 0);
  ASSERT_TRUE(relay.has_value()) << relay.error();
  const std::uint16_t relay_port = LocalPort(relay->fd());
  constexpr std::size_t kHello = kHeaderSize + sizeof(HelloBody) + kTagBytes;
  constexpr std::size_t kRequest = kHeaderSize + kTagBytes;
  constexpr std::size_t kReply = kHeaderSize + sizeof(StatusBody) + kTagBytes;
  std::thread man_in_the_middle([&] {
    std::vector<std::byte> recorded(kReply);
    for (int session = 0; session < 2; ++session) {
      const int c = accept(relay->fd(), nullptr, nullptr);
      if (c < 0) return;
      Socket client(c);
      auto up = ConnectTcp("127.0.0.1", p.port(), NowNs() + 2'000'000'000);
      if (!up) return;
      const std::int64_t deadline = NowNs() + 3'000'000'000;
      std::vector<std::byte> hello(kHello), request(kRequest), reply(kReply);
      std::size_t got = 0;
      if (RecvAll(up->fd(), hello, deadline, 0, got) != IoResult::kOk ||
          SendAll(client.fd(), hello, deadline) != IoResult::kOk ||
          RecvAll(client.fd(), request, deadline, 0, got) != IoResult::kOk)
        return;
      if (session == 0) {  // relay honestly, and keep the reply
        if (SendAll(up->fd(), request, deadline) != IoResult::kOk ||
            RecvAll(up->fd(), reply, deadline, 0, got) != IoResult::kOk)
          return;
        recorded = reply;
      }
      (void)SendAll(client.fd(), recorded, deadline);  // session 1: the old reply, not palpad's
    }
  });
  const Endpoint via{"127.0.0.1", relay_port};
  const auto first = FetchStatus(via, in.k, 3000ms);
  const auto second = FetchStatus(via, in.k, 3000ms);
  man_in_the_middle.join();
  ASSERT_TRUE(first.has_value()) << first.error().message;
  ASSERT_FALSE(second.has_value());
  EXPECT_EQ(second.error().code, NetErrorCode::kBadReply);
  EXPECT_NE(second.error().message.find("belongs to another exchange"), std::string::npos) << second.error().message;
  EXPECT_NE(second.error().message.find("replayed or stale answer"), std::string::npos) << second.error().message;
  EXPECT_EQ(second.error().message.find("wrong key"), std::string::npos) << second.error().message;
}

}  // namespace
}  // namespace palpa::net
