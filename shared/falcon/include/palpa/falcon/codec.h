// Novint Falcon runtime packet codec (Novint/nVent firmware, "FalconFirmwareNovintSDK" protocol)
// and the FTDI IN-transfer framing around it. Both directions are here: the host encodes
// commands and decodes status packets; the virtual Falcon decodes commands and encodes status
// packets, so both ends of the wire share one definition of the bytes.
//
// Packet (16 bytes, docs/falcon.md §2; source: libnifalcon src/firmware/FalconFirmwareNovintSDK.cpp):
//
//   byte  0      1..4        5..8        9..12       13        14   15
//        '<'   value 1     value 2     value 3     control   'A'  '>'
//
// Each 16-bit value (motor command host→device, encoder count device→host) is two's complement,
// sent as four 4-bit nibbles, least significant first, each as nibble + 0x41 ('A'..'P').
// Host→device byte 13 = control nibble + 0x41: 0x01 homing mode, 0x02 green, 0x04 blue, 0x08 red LED.
// Device→host byte 13 = s + 0x41 with 7 bits in s: bits 0-3 buttons, bits 4-6 homed flags of
// axes 1-3. Byte 14 is unknown (host sends 'A'; the device's is not checked).
//
// FTDI framing (docs/falcon.md §1.2): every full-speed USB IN packet (≤ 64 bytes) starts with two
// modem/line status bytes that are not serial data; a transfer of only 2 bytes carries no data.
//
// RT-safe: everything here is allocation-free, lock-free and bounded; FrameReader uses a fixed
// buffer. Errors are return values (no exceptions).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>

namespace palpa::falcon {

inline constexpr std::size_t kPacketBytes = 16;
using Packet = std::array<std::uint8_t, kPacketBytes>;

inline constexpr std::uint8_t kFrameStart = 0x3C;  ///< '<'
inline constexpr std::uint8_t kFrameEnd = 0x3E;    ///< '>'
inline constexpr std::uint8_t kNibbleBase = 0x41;  ///< 'A'

/// Control bits of host→device byte 13 (libnifalcon FalconFirmware.h; docs/falcon.md §2.2).
inline constexpr std::uint8_t kControlHoming = 0x01;
inline constexpr std::uint8_t kLedGreen = 0x02;
inline constexpr std::uint8_t kLedBlue = 0x04;
inline constexpr std::uint8_t kLedRed = 0x08;

/// Button bits of the 4-button grip (FalconGripFourButton.h).
inline constexpr std::uint8_t kButtonPlus = 0x01;
inline constexpr std::uint8_t kButtonForward = 0x02;
inline constexpr std::uint8_t kButtonCenter = 0x04;
inline constexpr std::uint8_t kButtonMinus = 0x08;

/// Homed flags as DeviceStatus::homed holds them: bit i = axis i+1 (top, right, left).
inline constexpr std::uint8_t kAllHomed = 0x07;

/// Host → device: one motor command packet.
struct MotorCommand {
  std::array<std::int16_t, 3> counts{};  ///< motor 1 (top), 2 (right), 3 (left); practical range ±4095
  std::uint8_t control = 0;              ///< kControlHoming | kLed*; 4 bits
  friend bool operator==(const MotorCommand&, const MotorCommand&) = default;
};

/// Device → host: one status packet.
struct DeviceStatus {
  std::array<std::int16_t, 3> encoders{};  ///< encoder counts of axes 1-3 (0 ↔ θ1 = 35° once homed)
  std::uint8_t buttons = 0;                ///< kButton* bits, 4 bits
  std::uint8_t homed = 0;                  ///< bit i: axis i+1 homed, 3 bits
  bool AllHomed() const { return (homed & kAllHomed) == kAllHomed; }
  friend bool operator==(const DeviceStatus&, const DeviceStatus&) = default;
};

/// Encodes a command; `control` is masked to 4 bits. Never fails.
Packet EncodeCommand(const MotorCommand& command);
/// Decodes a command packet (virtual Falcon side): nullopt unless it is a well-formed frame whose
/// bytes 1-13 are all 'A'..'P'.
std::optional<MotorCommand> DecodeCommand(const Packet& packet);

/// Encodes a status packet (virtual Falcon side); buttons/homed masked to 4/3 bits; byte 14 'A'.
Packet EncodeStatus(const DeviceStatus& status);
/// Decodes a status packet: nullopt unless IsStatusFrame(packet).
std::optional<DeviceStatus> DecodeStatus(const Packet& packet);

/// True if `p` (16 bytes) is a well-formed device→host frame: '<', bytes 1-12 in 'A'..'P',
/// byte 13 in 0x41..0xC0 (7 bits), any byte 14, '>'.
bool IsStatusFrame(std::span<const std::uint8_t, kPacketBytes> p);

/// True if `p` is a well-formed host→device frame: '<', bytes 1-13 in 'A'..'P', any byte 14, '>'.
bool IsCommandFrame(std::span<const std::uint8_t, kPacketBytes> p);

/// USB full-speed max packet of the FTDI bulk IN endpoint, and the status bytes it starts with.
inline constexpr std::size_t kFtdiMaxPacket = 64;
inline constexpr std::size_t kFtdiStatusBytes = 2;
/// Bit of the first FTDI status byte that mirrors the CTS line (FTDI convention).
inline constexpr std::uint8_t kFtdiModemCts = 0x10;

/// Copies the serial payload of one raw IN transfer into `out`, dropping the 2 status bytes at
/// the start of every 64-byte USB packet. Returns the payload length (≤ out.size(); bytes that do
/// not fit are dropped and counted by the caller through the return value being short).
/// `modem_status` gets the first status byte of the transfer (unchanged if the transfer is < 2 bytes).
std::size_t StripFtdiStatus(std::span<const std::uint8_t> transfer, std::span<std::uint8_t> out,
                            std::uint8_t& modem_status);

/// Which direction's frames a FrameReader accepts.
enum class FrameKind {
  kStatus,   ///< device→host (IsStatusFrame): the host's reader
  kCommand,  ///< host→device (IsCommandFrame): the virtual Falcon's reader
};

/// Re-frames a byte stream: takes raw IN transfers (FTDI status bytes included) or bare payload,
/// and hands out well-formed frames of its kind in order. Bytes that cannot start a
/// frame are skipped and counted (garbage, a frame cut by a lost byte); a frame split across
/// transfers is reassembled. A '<' too close to the end waits for more bytes. Fixed capacity:
/// when full, the oldest bytes are dropped (counted as discarded). RT-safe.
class FrameReader {
 public:
  static constexpr std::size_t kCapacity = 256;

  explicit FrameReader(FrameKind kind = FrameKind::kStatus) : kind_(kind) {}

  /// Appends the payload of one raw IN transfer (see StripFtdiStatus).
  void PushUsbTransfer(std::span<const std::uint8_t> transfer);
  /// Appends serial payload bytes.
  void PushPayload(std::span<const std::uint8_t> bytes);
  /// Takes the next complete frame into `out`; false if none is complete yet.
  bool Next(Packet& out);
  /// Drops everything buffered (e.g. after a purge).
  void Clear() { size_ = 0; }

  std::size_t buffered() const { return size_; }
  /// Bytes skipped while looking for frames (and dropped on overflow), since construction.
  std::uint64_t discarded_bytes() const { return discarded_; }
  /// First FTDI status byte of the last raw transfer pushed.
  std::uint8_t modem_status() const { return modem_status_; }

 private:
  void Discard(std::size_t n);

  FrameKind kind_;
  std::array<std::uint8_t, kCapacity> buf_{};
  std::size_t size_ = 0;
  std::uint64_t discarded_ = 0;
  std::uint8_t modem_status_ = 0;
};

}  // namespace palpa::falcon
