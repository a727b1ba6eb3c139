#include "palpa/falcon/codec.h"

#include <algorithm>

namespace palpa::falcon {
namespace {

constexpr std::uint8_t kNibbleMax = kNibbleBase + 0x0F;  // 'P'

bool IsNibble(std::uint8_t b) { return b >= kNibbleBase && b <= kNibbleMax; }

// Four nibbles, least significant first, at p[first..first+3]; the value is taken as uint16 so
// that every int16 (two's complement) round-trips.
void PutValue(Packet& p, std::size_t first, std::int16_t value) {
  const auto v = static_cast<std::uint16_t>(value);
  for (std::size_t i = 0; i < 4; ++i) p[first + i] = static_cast<std::uint8_t>(kNibbleBase + ((v >> (4 * i)) & 0x0F));
}

std::int16_t GetValue(std::span<const std::uint8_t, kPacketBytes> p, std::size_t first) {
  unsigned v = 0;
  for (std::size_t i = 0; i < 4; ++i) v |= static_cast<unsigned>((p[first + i] - kNibbleBase) & 0x0F) << (4 * i);
  return static_cast<std::int16_t>(static_cast<std::uint16_t>(v));  // sign from bit 15 (modular in C++20)
}

bool ValuesAreNibbles(std::span<const std::uint8_t, kPacketBytes> p) {
  for (std::size_t i = 1; i <= 12; ++i)
    if (!IsNibble(p[i])) return false;
  return true;
}

}  // namespace

Packet EncodeCommand(const MotorCommand& command) {
  Packet p{};
  p[0] = kFrameStart;
  for (std::size_t m = 0; m < 3; ++m) PutValue(p, 1 + 4 * m, command.counts[m]);
  p[13] = static_cast<std::uint8_t>(kNibbleBase + (command.control & 0x0F));
  p[14] = kNibbleBase;
  p[15] = kFrameEnd;
  return p;
}

bool IsCommandFrame(std::span<const std::uint8_t, kPacketBytes> p) {
  return p[0] == kFrameStart && p[15] == kFrameEnd && ValuesAreNibbles(p) && IsNibble(p[13]);
}

std::optional<MotorCommand> DecodeCommand(const Packet& packet) {
  if (!IsCommandFrame(packet)) return std::nullopt;
  MotorCommand c;
  for (std::size_t m = 0; m < 3; ++m) c.counts[m] = GetValue(packet, 1 + 4 * m);
  c.control = static_cast<std::uint8_t>(packet[13] - kNibbleBase);
  return c;
}

Packet EncodeStatus(const DeviceStatus& status) {
  Packet p{};
  p[0] = kFrameStart;
  for (std::size_t a = 0; a < 3; ++a) PutValue(p, 1 + 4 * a, status.encoders[a]);
  const unsigned s = (status.buttons & 0x0Fu) | ((status.homed & kAllHomed) << 4u);
  p[13] = static_cast<std::uint8_t>(kNibbleBase + s);
  p[14] = kNibbleBase;
  p[15] = kFrameEnd;
  return p;
}

bool IsStatusFrame(std::span<const std::uint8_t, kPacketBytes> p) {
  return p[0] == kFrameStart && p[15] == kFrameEnd && ValuesAreNibbles(p) && p[13] >= kNibbleBase &&
         p[13] <= kNibbleBase + 0x7F;
}

std::optional<DeviceStatus> DecodeStatus(const Packet& packet) {
  if (!IsStatusFrame(packet)) return std::nullopt;
  DeviceStatus s;
  for (std::size_t a = 0; a < 3; ++a) s.encoders[a] = GetValue(packet, 1 + 4 * a);
  const auto b13 = static_cast<std::uint8_t>(packet[13] - kNibbleBase);
  s.buttons = b13 & 0x0F;
  s.homed = static_cast<std::uint8_t>((b13 >> 4) & kAllHomed);
  return s;
}

std::size_t StripFtdiStatus(std::span<const std::uint8_t> transfer, std::span<std::uint8_t> out,
                            std::uint8_t& modem_status) {
  if (transfer.size() >= kFtdiStatusBytes) modem_status = transfer[0];
  std::size_t n = 0;
  for (std::size_t packet = 0; packet < transfer.size(); packet += kFtdiMaxPacket) {
    const std::size_t end = std::min(transfer.size(), packet + kFtdiMaxPacket);
    for (std::size_t i = packet + kFtdiStatusBytes; i < end && n < out.size(); ++i) out[n++] = transfer[i];
  }
  return n;
}

void FrameReader::PushUsbTransfer(std::span<const std::uint8_t> transfer) {
  // One transfer is split into its ≤ 64-byte USB packets here so that no large temporary is needed.
  for (std::size_t packet = 0; packet < transfer.size(); packet += kFtdiMaxPacket) {
    const std::size_t end = std::min(transfer.size(), packet + kFtdiMaxPacket);
    if (end - packet >= kFtdiStatusBytes) {
      if (packet == 0) modem_status_ = transfer[0];
      PushPayload(transfer.subspan(packet + kFtdiStatusBytes, end - packet - kFtdiStatusBytes));
    }
  }
}

void FrameReader::PushPayload(std::span<const std::uint8_t> bytes) {
  for (const std::uint8_t b : bytes) {
    if (size_ == kCapacity) Discard(1);  // overflow: oldest byte goes
    buf_[size_++] = b;
  }
}

void FrameReader::Discard(std::size_t n) {
  n = std::min(n, size_);
  std::copy(buf_.begin() + static_cast<std::ptrdiff_t>(n), buf_.begin() + static_cast<std::ptrdiff_t>(size_),
            buf_.begin());
  size_ -= n;
  discarded_ += n;
}

bool FrameReader::Next(Packet& out) {
  std::size_t i = 0;
  for (; i < size_; ++i) {
    if (buf_[i] != kFrameStart) continue;
    if (size_ - i < kPacketBytes) break;  // a candidate at the tail: wait for the rest
    const std::span<const std::uint8_t, kPacketBytes> candidate(buf_.data() + i, kPacketBytes);
    const bool ok = kind_ == FrameKind::kStatus ? IsStatusFrame(candidate) : IsCommandFrame(candidate);
    if (!ok) continue;
    std::copy(candidate.begin(), candidate.end(), out.begin());
    Discard(i);  // garbage before the frame
    // The frame itself is consumed, not discarded.
    std::copy(buf_.begin() + kPacketBytes, buf_.begin() + static_cast<std::ptrdiff_t>(size_), buf_.begin());
    size_ -= kPacketBytes;
    return true;
  }
  Discard(i);  // nothing before i can start a frame any more
  return false;
}

}  // namespace palpa::falcon
