// Packet codec and FTDI re-framing. Truths: the packet strings of docs/falcon.md §5.1 (derived
// by hand from libnifalcon's nibble rules, independently of this code), libnifalcon's documented
// decode example, and exhaustive round trips over every int16.

#include <gtest/gtest.h>

#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "palpa/falcon/codec.h"

namespace palpa::falcon {
namespace {

std::string Text(const Packet& p) { return std::string(p.begin(), p.end()); }

Packet FromText(const std::string& s) {
  Packet p{};
  EXPECT_EQ(s.size(), kPacketBytes);
  for (std::size_t i = 0; i < kPacketBytes && i < s.size(); ++i) p[i] = static_cast<std::uint8_t>(s[i]);
  return p;
}

TEST(FalconCodec, CommandVectorsFromTheNotes) {
  EXPECT_EQ(Text(EncodeCommand({{0, 0, 0}, 0})), "<AAAAAAAAAAAAAA>");  // libnifalcon's "null" packet
  EXPECT_EQ(Text(EncodeCommand({{0, 0, 0}, kControlHoming})), "<AAAAAAAAAAAABA>");
  EXPECT_EQ(Text(EncodeCommand({{1447, -1, 4095}, kControlHoming | kLedGreen})), "<HKFAPPPPPPPADA>");
  EXPECT_EQ(Text(EncodeCommand({{-4096, 4096, -1447}, kLedRed | kLedBlue})), "<AAAPAAABJFKPMA>");
  EXPECT_EQ(Text(EncodeCommand({{100, -100, 0}, 0x0F})), "<EGAAMJPPAAAAPA>");
  // The same packet as bytes: 3c 48 4b 46 41 50 50 50 50 50 50 50 41 44 41 3e.
  const Packet p = EncodeCommand({{1447, -1, 4095}, 0x03});
  const Packet bytes = {0x3c, 0x48, 0x4b, 0x46, 0x41, 0x50, 0x50, 0x50, 0x50, 0x50, 0x50, 0x50, 0x41, 0x44, 0x41, 0x3e};
  EXPECT_EQ(p, bytes);
}

TEST(FalconCodec, StatusVectorsFromTheNotes) {
  // libnifalcon's example: "<JFKP" → nibbles 9,5,A,F → 0xFA59 → −1447.
  const auto s = DecodeStatus(FromText("<JFKPAAAAAAAAAA>"));
  ASSERT_TRUE(s.has_value());
  EXPECT_EQ(s->encoders, (std::array<std::int16_t, 3>{-1447, 0, 0}));
  EXPECT_EQ(s->buttons, 0);
  EXPECT_EQ(s->homed, 0);
  // Byte 13 carries 7 bits: 0xB5 − 0x41 = 0x74 → homed 7, buttons 0x4 (centre).
  Packet p = FromText("<AAAAAAAAAAAAAA>");
  p[13] = 0xB5;
  const auto h = DecodeStatus(p);
  ASSERT_TRUE(h.has_value());
  EXPECT_EQ(h->homed, 7);
  EXPECT_EQ(h->buttons, kButtonCenter);
  EXPECT_TRUE(h->AllHomed());
}

TEST(FalconCodec, EveryInt16RoundTripsInEverySlot) {
  for (int v = -32768; v <= 32767; ++v) {
    const auto x = static_cast<std::int16_t>(v);
    for (std::size_t slot = 0; slot < 3; ++slot) {
      MotorCommand c;
      c.counts[slot] = x;
      c.control = static_cast<std::uint8_t>(v & 0x0F);
      const auto back = DecodeCommand(EncodeCommand(c));
      ASSERT_TRUE(back.has_value()) << v;
      ASSERT_EQ(*back, c) << v;
      DeviceStatus s;
      s.encoders[slot] = x;
      s.buttons = static_cast<std::uint8_t>(v & 0x0F);
      s.homed = static_cast<std::uint8_t>((v >> 4) & 0x07);
      const auto sb = DecodeStatus(EncodeStatus(s));
      ASSERT_TRUE(sb.has_value()) << v;
      ASSERT_EQ(*sb, s) << v;
    }
  }
}

TEST(FalconCodec, NibbleOrderIsLeastSignificantFirst) {
  // Independent of PutValue: build 0x1234 by hand: nibbles 4,3,2,1 → 'E','D','C','B'.
  const Packet p = EncodeCommand({{0x1234, 0, 0}, 0});
  EXPECT_EQ(Text(p).substr(1, 4), "EDCB");
}

TEST(FalconCodec, MalformedFramesAreRejected) {
  EXPECT_FALSE(DecodeStatus(FromText("<AAAAAAAAAAAAAA<")).has_value());   // no '>'
  EXPECT_FALSE(DecodeStatus(FromText(">AAAAAAAAAAAAAA>")).has_value());   // no '<'
  EXPECT_FALSE(DecodeStatus(FromText("<AAAAAQAAAAAAAA>")).has_value());   // 'Q' is not a nibble
  EXPECT_FALSE(DecodeStatus(FromText("<AAAAAAAAAAAA@A>")).has_value());   // byte 13 below 'A'
  EXPECT_FALSE(DecodeCommand(FromText("<AAAAAAAAAAAAQA>")).has_value());  // command control: 4 bits only
  EXPECT_TRUE(DecodeStatus(FromText("<AAAAAAAAAAAAA?>")).has_value());    // byte 14 unknown: not checked
}

TEST(FalconCodec, FtdiStatusBytesAreStrippedPerUsbPacket) {
  // 130 bytes = packets of 64, 64, 2: payload 62 + 62 + 0.
  std::vector<std::uint8_t> transfer(130);
  for (std::size_t i = 0; i < transfer.size(); ++i) transfer[i] = static_cast<std::uint8_t>(i);
  std::vector<std::uint8_t> out(200);
  std::uint8_t modem = 0;
  const std::size_t n = StripFtdiStatus(transfer, out, modem);
  ASSERT_EQ(n, 124u);
  EXPECT_EQ(modem, 0);
  EXPECT_EQ(out[0], 2);
  EXPECT_EQ(out[61], 63);
  EXPECT_EQ(out[62], 66);  // bytes 64 and 65 were the second packet's status
  EXPECT_EQ(out[123], 127);
  // A 2-byte transfer carries no data.
  const std::uint8_t only_status[2] = {0x31, 0x60};
  EXPECT_EQ(StripFtdiStatus(only_status, out, modem), 0u);
  EXPECT_EQ(modem, 0x31);
}

// The raw IN transfers a device would send for `payload`, cut at `cuts` (payload offsets), each
// with the 2 FTDI status bytes in front.
std::vector<std::vector<std::uint8_t>> Transfers(const std::vector<std::uint8_t>& payload,
                                                 const std::vector<std::size_t>& cuts) {
  std::vector<std::vector<std::uint8_t>> out;
  std::size_t from = 0;
  std::vector<std::size_t> ends = cuts;
  ends.push_back(payload.size());
  for (const std::size_t to : ends) {
    std::vector<std::uint8_t> t = {0x31, 0x60};
    t.insert(t.end(), payload.begin() + static_cast<std::ptrdiff_t>(from),
             payload.begin() + static_cast<std::ptrdiff_t>(to));
    out.push_back(t);
    from = to;
  }
  return out;
}

TEST(FalconCodec, ReaderReassemblesAFrameSplitAtEveryPoint) {
  const DeviceStatus s{{123, -4567, 32767}, kButtonMinus, 5};
  const Packet p = EncodeStatus(s);
  const std::vector<std::uint8_t> payload(p.begin(), p.end());
  for (std::size_t cut = 1; cut < kPacketBytes; ++cut) {
    FrameReader r;
    Packet got{};
    const auto ts = Transfers(payload, {cut});
    r.PushUsbTransfer(ts[0]);
    EXPECT_FALSE(r.Next(got)) << cut;
    r.PushUsbTransfer(ts[1]);
    ASSERT_TRUE(r.Next(got)) << cut;
    EXPECT_EQ(DecodeStatus(got), s);
    EXPECT_EQ(r.discarded_bytes(), 0u);
    EXPECT_EQ(r.buffered(), 0u);
  }
}

TEST(FalconCodec, ReaderResyncsAfterGarbage) {
  // Garbage with stray '<' and '>' and a cut frame, then two good frames byte by byte.
  const DeviceStatus a{{1, 2, 3}, 0, 7}, b{{-1, -2, -3}, kButtonPlus, 7};
  std::vector<std::uint8_t> bytes = {0x00, 0x3C, 0x41, 0x3E, 0xFF, 0x3C, 0x41, 0x41, 0x41};  // 9 garbage
  const Packet pa = EncodeStatus(a), pb = EncodeStatus(b);
  bytes.insert(bytes.end(), pa.begin(), pa.end());
  bytes.insert(bytes.end(), pb.begin(), pb.end());
  FrameReader r;
  std::vector<DeviceStatus> seen;
  for (const std::uint8_t byte : bytes) {
    r.PushPayload(std::span(&byte, 1));
    Packet got{};
    while (r.Next(got)) seen.push_back(*DecodeStatus(got));
  }
  ASSERT_EQ(seen.size(), 2u);
  EXPECT_EQ(seen[0], a);
  EXPECT_EQ(seen[1], b);
  EXPECT_EQ(r.discarded_bytes(), 9u);
}

TEST(FalconCodec, ReaderRecoversEveryFrameFromRandomNoiseAndCuts) {
  // Noise without '<' cannot start a frame, so every frame must come back, in order, whatever
  // the transfer boundaries; the skipped count must equal the noise bytes exactly.
  std::mt19937 rng(8);
  std::uniform_int_distribution<int> byte(0, 255), len(0, 20), cut(1, 70);
  std::vector<std::uint8_t> payload;
  std::vector<DeviceStatus> sent;
  std::size_t noise = 0;
  for (int i = 0; i < 500; ++i) {
    const int n = len(rng);
    for (int k = 0; k < n; ++k) {
      auto x = static_cast<std::uint8_t>(byte(rng));
      if (x == kFrameStart) x = 0x00;
      payload.push_back(x);
      ++noise;
    }
    DeviceStatus s;
    for (auto& e : s.encoders) e = static_cast<std::int16_t>(byte(rng) * 256 + byte(rng) - 32768);
    s.buttons = static_cast<std::uint8_t>(byte(rng) & 0x0F);
    s.homed = static_cast<std::uint8_t>(byte(rng) & 0x07);
    sent.push_back(s);
    const Packet p = EncodeStatus(s);
    payload.insert(payload.end(), p.begin(), p.end());
  }
  std::vector<std::size_t> cuts;
  for (std::size_t at = static_cast<std::size_t>(cut(rng)); at < payload.size();
       at += static_cast<std::size_t>(cut(rng)))
    cuts.push_back(at);
  // Transfers of up to 62 payload bytes (one USB packet); longer pieces go as several.
  FrameReader r;
  std::vector<DeviceStatus> got;
  for (const auto& t : Transfers(payload, cuts)) {
    for (std::size_t from = 2; from < t.size(); from += 62) {
      std::vector<std::uint8_t> usb = {0x31, 0x60};
      usb.insert(usb.end(), t.begin() + static_cast<std::ptrdiff_t>(from),
                 t.begin() + static_cast<std::ptrdiff_t>(std::min(t.size(), from + 62)));
      r.PushUsbTransfer(usb);
      Packet p{};
      while (r.Next(p)) got.push_back(*DecodeStatus(p));
    }
  }
  ASSERT_EQ(got.size(), sent.size());
  EXPECT_EQ(got, sent);
  EXPECT_EQ(r.discarded_bytes(), noise);
}

TEST(FalconCodec, ReaderOverflowDropsOldestBytes) {
  FrameReader r;
  std::vector<std::uint8_t> junk(FrameReader::kCapacity + 40, 0x00);
  r.PushPayload(junk);
  EXPECT_EQ(r.buffered(), FrameReader::kCapacity);
  EXPECT_EQ(r.discarded_bytes(), 40u);
  const Packet p = EncodeStatus({{7, 8, 9}, 0, 7});
  r.PushPayload(p);
  Packet got{};
  ASSERT_TRUE(r.Next(got));
  EXPECT_EQ(got, p);
}

TEST(FalconCodec, CommandReaderAcceptsOnlyCommandFrames) {
  FrameReader r(FrameKind::kCommand);
  Packet status = EncodeStatus({{0, 0, 0}, 0, 7});  // byte 13 = 'A' + 0x70: not a command nibble
  r.PushPayload(status);
  const Packet cmd = EncodeCommand({{5, 6, 7}, kLedBlue});
  r.PushPayload(cmd);
  Packet got{};
  ASSERT_TRUE(r.Next(got));
  EXPECT_EQ(got, cmd);
  EXPECT_EQ(r.discarded_bytes(), kPacketBytes);
}

}  // namespace
}  // namespace palpa::falcon
