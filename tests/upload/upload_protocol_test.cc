// The upload protocol library (shared/net) on its own: wire layout, the MAC against RFC 4231,
// key files, endpoints, the status JSON. Independent truths: the RFC's published digest, the
// offsets written in docs/upload.md, file modes from stat(2).
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <fstream>
#include <string>

#include "palpa/net/client.h"
#include "palpa/net/protocol.h"
#include "palpa/net/socket.h"

namespace palpa::net {
namespace {

std::string TempPath(const char* name) { return ::testing::TempDir() + "/upload_protocol_" + name; }

TEST(UploadProtocol, HeaderLayoutMatchesTheSpec) {
  // docs/upload.md: magic 0, version 4, type 6, body_size 8, server nonce 16, client nonce 40,
  // header tag 64, 96 bytes in all.
  EXPECT_EQ(offsetof(Header, magic), 0u);
  EXPECT_EQ(offsetof(Header, version), 4u);
  EXPECT_EQ(offsetof(Header, type), 6u);
  EXPECT_EQ(offsetof(Header, body_size), 8u);
  EXPECT_EQ(offsetof(Header, server_nonce), 16u);
  EXPECT_EQ(offsetof(Header, client_nonce), 40u);
  EXPECT_EQ(offsetof(Header, header_tag), 64u);
  EXPECT_EQ(sizeof(Header), 96u);
  EXPECT_EQ(sizeof(HelloBody), 16u);
  EXPECT_EQ(sizeof(AcceptedBody), 40u);
  EXPECT_EQ(sizeof(RefusedBody), 256u);
  EXPECT_EQ(sizeof(StatusBody), 272u);
  Header h;
  h.magic = kMagic;
  h.version = kVersion;
  h.type = static_cast<std::uint16_t>(MessageType::kUpload);
  h.body_size = 0x0102030405060708ull;
  unsigned char raw[96];
  std::memcpy(raw, &h, sizeof raw);
  EXPECT_EQ(std::string(reinterpret_cast<const char*>(raw), 4), "PLPU");
  EXPECT_EQ(raw[4], 1);  // little-endian version
  EXPECT_EQ(raw[6], 2);
  EXPECT_EQ(raw[8], 0x08);  // body_size low byte first
  EXPECT_EQ(raw[15], 0x01);
}

// RFC 4231 test case 2 (key "Jefe", data "what do ya want for nothing?"): HMAC-SHA-512 begins
// 164b7a7b fcf819e2 e395fbe7 3b56e0a3 87bd6422 2e831fd6 10270cd7 ea250554, and HMAC-SHA-512/256
// is its first 32 bytes. HMAC pads a short key with zeros to the block size, so the 32-byte key
// "Jefe" + 28 zero bytes gives the same MAC. Then HeaderTag and Seal must equal that MAC over the
// byte ranges docs/upload.md names.
TEST(UploadProtocol, HmacSha512256MatchesRfc4231Case2) {
  std::array<unsigned char, kKeyBytes> key{};
  std::memcpy(key.data(), "Jefe", 4);
  const char* data = "what do ya want for nothing?";
  const unsigned char expected[32] = {0x16, 0x4b, 0x7a, 0x7b, 0xfc, 0xf8, 0x19, 0xe2, 0xe3, 0x95, 0xfb,
                                      0xe7, 0x3b, 0x56, 0xe0, 0xa3, 0x87, 0xbd, 0x64, 0x22, 0x2e, 0x83,
                                      0x1f, 0xd6, 0x10, 0x27, 0x0c, 0xd7, 0xea, 0x25, 0x05, 0x54};
  std::array<unsigned char, kTagBytes> rfc{};
  std::memcpy(rfc.data(), expected, 32);
  EXPECT_TRUE(TagsEqual(Mac(key, std::as_bytes(std::span<const char>(data, std::strlen(data)))), rfc));

  Header h;
  h.magic = kMagic;
  h.version = kVersion;
  h.body_size = 5;
  EXPECT_TRUE(
      TagsEqual(HeaderTag(key, h), Mac(key, std::as_bytes(std::span<const Header>(&h, 1)).first(kHeaderTagOffset))));
  // Seal: header tag as above, body tag over the 96 header bytes (tag filled) then the body.
  const std::byte body[5] = {std::byte{1}, std::byte{2}, std::byte{3}, std::byte{4}, std::byte{5}};
  const auto body_tag = Seal(key, h, body);
  std::vector<std::byte> whole(96 + 5);
  std::memcpy(whole.data(), &h, 96);
  std::memcpy(whole.data() + 96, body, 5);
  EXPECT_TRUE(TagsEqual(body_tag, Mac(key, whole)));
  // Any change to the body or the key changes the tag.
  whole[100] ^= std::byte{1};
  EXPECT_FALSE(TagsEqual(body_tag, Mac(key, whole)));
  key[31] ^= 1;
  EXPECT_FALSE(TagsEqual(HeaderTag(key, h), h.header_tag));
}

TEST(UploadProtocol, NoncesAreFreshAndRefusalsHaveNames) {
  EXPECT_NE(NewNonce(), NewNonce());
  for (std::uint32_t r = 0; r <= 12; ++r) EXPECT_STRNE(RefusalName(static_cast<Refusal>(r)), "unknown") << r;
  Header h;
  EXPECT_EQ(CheckMagicAndVersion(h), Refusal::kGarbage);
  h.magic = kMagic;
  h.version = 2;
  EXPECT_EQ(CheckMagicAndVersion(h), Refusal::kBadVersion);
  h.version = 1;
  EXPECT_EQ(CheckMagicAndVersion(h), Refusal::kNone);
}

TEST(UploadKeyFile, KeygenWritesMode0600AndRefusesToOverwrite) {
  const std::string path = TempPath("key");
  std::remove(path.c_str());
  ASSERT_TRUE(WriteNewKeyFile(path, false).has_value());
  struct stat st {};
  ASSERT_EQ(stat(path.c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
  EXPECT_EQ(st.st_size, 32);
  const auto first = ReadKeyFile(path);
  ASSERT_TRUE(first.has_value()) << first.error().message;
  const auto again = WriteNewKeyFile(path, false);
  ASSERT_FALSE(again.has_value());
  EXPECT_NE(again.error().message.find("refusing to overwrite"), std::string::npos) << again.error().message;
  EXPECT_EQ(ReadKeyFile(path)->bytes, first->bytes) << "a refused keygen must leave the key alone";
  ASSERT_TRUE(WriteNewKeyFile(path, true).has_value());
  EXPECT_NE(ReadKeyFile(path)->bytes, first->bytes) << "--force writes a new random key";
  std::remove(path.c_str());
}

TEST(UploadKeyFile, ReadersRefuseGroupOrOtherPermissionsAndWrongSizes) {
  const std::string path = TempPath("key_perm");
  std::remove(path.c_str());
  ASSERT_TRUE(WriteNewKeyFile(path, true).has_value());
  ASSERT_EQ(chmod(path.c_str(), 0640), 0);
  auto r = ReadKeyFile(path);
  ASSERT_FALSE(r.has_value());
  EXPECT_EQ(r.error().code, NetErrorCode::kKeyFile);
  EXPECT_NE(r.error().message.find("mode 0640"), std::string::npos) << r.error().message;
  ASSERT_EQ(chmod(path.c_str(), 0604), 0);
  EXPECT_FALSE(ReadKeyFile(path).has_value());
  ASSERT_EQ(chmod(path.c_str(), 0400), 0);
  EXPECT_TRUE(ReadKeyFile(path).has_value()) << "read-only for the owner is fine";
  std::remove(path.c_str());
  {
    std::ofstream f(path, std::ios::binary);
    f << "short";
  }
  ASSERT_EQ(chmod(path.c_str(), 0600), 0);
  r = ReadKeyFile(path);
  ASSERT_FALSE(r.has_value());
  EXPECT_NE(r.error().message.find("exactly 32 bytes"), std::string::npos) << r.error().message;
  std::remove(path.c_str());
  EXPECT_FALSE(ReadKeyFile(path).has_value());
}

TEST(UploadEndpoint, ParsesHostPortAndRefusesTheRest) {
  auto e = ParseEndpoint("127.0.0.1:7700");
  ASSERT_TRUE(e.has_value());
  EXPECT_EQ(e->host, "127.0.0.1");
  EXPECT_EQ(e->port, 7700);
  e = ParseEndpoint("[::1]:1");
  ASSERT_TRUE(e.has_value());
  EXPECT_EQ(e->host, "::1");
  for (const char* bad : {"host", ":80", "host:", "host:0", "host:65536", "host:8x", "[::1:80"})
    EXPECT_FALSE(ParseEndpoint(bad).has_value()) << bad;
}

TEST(UploadStatus, JsonCarriesEveryField) {
  ControllerStatus s;
  s.field_crc32c = 0xdeadbeef;
  s.dims = {40, 41, 42};
  s.voxel_m = 0.5e-3;
  s.ticks = 1234;
  s.hip_m = {0.25, -0.5, 1};
  s.contact = true;
  const std::string j = ToJson(s);
  EXPECT_NE(j.find("\"field_crc32c\": \"0xdeadbeef\""), std::string::npos) << j;
  EXPECT_NE(j.find("\"dims\": [40, 41, 42]"), std::string::npos) << j;
  EXPECT_NE(j.find("\"ticks\": 1234"), std::string::npos) << j;
  EXPECT_NE(j.find("\"hip_m\": [0.25, -0.5, 1]"), std::string::npos) << j;
  EXPECT_NE(j.find("\"contact\": true"), std::string::npos) << j;
  EXPECT_EQ(j.front(), '{');
  EXPECT_EQ(j.back(), '}');
}

TEST(UploadClient, ConnectionRefusedIsAClearError) {
  // Bind, learn a free port, close it: nothing listens there now.
  auto l = ListenTcp("127.0.0.1", 0);
  ASSERT_TRUE(l.has_value());
  const std::uint16_t port = LocalPort(l->fd());
  *l = Socket();
  const auto r = FetchStatus(Endpoint{"127.0.0.1", port}, Key{}, std::chrono::milliseconds(500));
  ASSERT_FALSE(r.has_value());
  EXPECT_EQ(r.error().code, NetErrorCode::kConnect);
  EXPECT_NE(r.error().message.find("cannot connect"), std::string::npos) << r.error().message;
}

}  // namespace
}  // namespace palpa::net
