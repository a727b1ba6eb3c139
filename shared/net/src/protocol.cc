#include "palpa/net/protocol.h"

#include <sodium.h>

#include <cstring>

namespace palpa::net {

static_assert(kKeyBytes == crypto_auth_hmacsha512256_KEYBYTES);
static_assert(kTagBytes == crypto_auth_hmacsha512256_BYTES);

const char* RefusalName(Refusal r) {
  switch (r) {
    case Refusal::kNone:
      return "none";
    case Refusal::kGarbage:
      return "garbage";
    case Refusal::kBadVersion:
      return "unsupported version";
    case Refusal::kType:
      return "bad message type";
    case Refusal::kOversize:
      return "oversize";
    case Refusal::kReplayed:
      return "replayed";
    case Refusal::kWrongKey:
      return "wrong key";
    case Refusal::kTimeout:
      return "timeout";
    case Refusal::kHalfSent:
      return "half-sent";
    case Refusal::kBodyTag:
      return "body altered";
    case Refusal::kBlobInvalid:
      return "invalid blob";
    case Refusal::kBusy:
      return "busy";
    case Refusal::kSetup:
      return "field not renderable";
  }
  return "unknown";
}

bool InitCrypto() { return sodium_init() >= 0; }

std::array<unsigned char, kTagBytes> Mac(const std::array<unsigned char, kKeyBytes>& key,
                                         std::span<const std::byte> data) {
  std::array<unsigned char, kTagBytes> tag{};
  crypto_auth_hmacsha512256(tag.data(), reinterpret_cast<const unsigned char*>(data.data()), data.size(), key.data());
  return tag;
}

std::array<unsigned char, kTagBytes> HeaderTag(const std::array<unsigned char, kKeyBytes>& key, const Header& h) {
  std::array<unsigned char, kTagBytes> tag{};
  crypto_auth_hmacsha512256(tag.data(), reinterpret_cast<const unsigned char*>(&h), kHeaderTagOffset, key.data());
  return tag;
}

namespace {
using MacState = crypto_auth_hmacsha512256_state;
}  // namespace

BodyMac::BodyMac(const std::array<unsigned char, kKeyBytes>& key, const Header& h) {
  static_assert(sizeof(MacState) <= sizeof(state_) && alignof(MacState) <= 16);
  auto* st = reinterpret_cast<MacState*>(state_.data());
  crypto_auth_hmacsha512256_init(st, key.data(), key.size());
  crypto_auth_hmacsha512256_update(st, reinterpret_cast<const unsigned char*>(&h), kHeaderSize);
}

void BodyMac::Update(std::span<const std::byte> piece) {
  crypto_auth_hmacsha512256_update(reinterpret_cast<MacState*>(state_.data()),
                                   reinterpret_cast<const unsigned char*>(piece.data()), piece.size());
}

std::array<unsigned char, kTagBytes> BodyMac::Final() {
  std::array<unsigned char, kTagBytes> tag{};
  crypto_auth_hmacsha512256_final(reinterpret_cast<MacState*>(state_.data()), tag.data());
  sodium_memzero(state_.data(), state_.size());
  return tag;
}

std::array<unsigned char, kTagBytes> Seal(const std::array<unsigned char, kKeyBytes>& key, Header& h,
                                          std::span<const std::byte> body) {
  h.header_tag = HeaderTag(key, h);
  BodyMac mac(key, h);
  mac.Update(body);
  return mac.Final();
}

bool TagsEqual(const std::array<unsigned char, kTagBytes>& a, const std::array<unsigned char, kTagBytes>& b) {
  return sodium_memcmp(a.data(), b.data(), kTagBytes) == 0;
}

std::array<unsigned char, kNonceBytes> NewNonce() {
  std::array<unsigned char, kNonceBytes> n{};
  randombytes_buf(n.data(), n.size());
  return n;
}

Refusal CheckMagicAndVersion(const Header& h) {
  if (h.magic != kMagic) return Refusal::kGarbage;
  if (h.version != kVersion) return Refusal::kBadVersion;
  return Refusal::kNone;
}

}  // namespace palpa::net
