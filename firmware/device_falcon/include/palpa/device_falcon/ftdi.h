// FTDI vendor requests the Falcon needs, and the two set-up sequences built from them
// (docs/falcon.md §1.3-1.5; source: libnifalcon src/comm/FalconCommLibUSB.cpp, request numbers
// from libftdi). All are control OUT transfers, bmRequestType 0x40, wIndex 0, no data.
// Non-RT (start-up and firmware loading only).
#pragma once

#include <cstdint>

#include "palpa/device_falcon/transport.h"

namespace palpa::device_falcon::ftdi {

inline constexpr std::uint8_t kReqReset = 0;        ///< SIO_RESET: wValue 1 purge RX, 2 purge TX
inline constexpr std::uint8_t kReqModemCtrl = 1;    ///< SIO_MODEM_CTRL: (mask << 8) | level
inline constexpr std::uint8_t kReqSetFlowCtrl = 2;  ///< SIO_SET_FLOW_CTRL: 0 none
inline constexpr std::uint8_t kReqSetBaudRate = 3;  ///< SIO_SET_BAUD_RATE: divisor of 3 MHz
inline constexpr std::uint8_t kReqSetData = 4;      ///< SIO_SET_DATA: 0x0008 = 8N1
inline constexpr std::uint8_t kReqSetLatency = 9;   ///< SET_LATENCY_TIMER: ms

inline constexpr std::uint16_t kPurgeRx = 1;
inline constexpr std::uint16_t kPurgeTx = 2;
inline constexpr std::uint16_t kRtsLow = 0x0200;
inline constexpr std::uint16_t kDtrLow = 0x0100;
inline constexpr std::uint16_t kDtrHigh = 0x0101;
inline constexpr std::uint16_t kData8N1 = 0x0008;
inline constexpr std::uint16_t kBaud9600 = 0x4138;       ///< 3 MHz / 312.5: boot-ROM handshake
inline constexpr std::uint16_t kBaud140k = 0x0015;       ///< 3 MHz / 21 ≈ 142 857 Bd: firmware upload
inline constexpr std::uint16_t kBaud1M5 = 0x0002;        ///< 3 MHz / 2 = 1.5 MBd: runtime protocol
inline constexpr std::uint16_t kLatencyFirmwareMs = 16;  ///< "otherwise firmware checks tend to always fail"
inline constexpr std::uint16_t kLatencyNormalMs = 1;     ///< else replies wait up to 16 ms in the FTDI

/// Control transfer timeout, ms (libnifalcon: 1000).
inline constexpr int kControlTimeoutMs = 1000;

/// Normal (runtime) mode, used on every open and after a firmware load: purge RX, purge TX,
/// latency 1 ms, baud 1.5 MBd, purge RX, purge TX. Stops at the first failing request.
UsbStatus SetNormalMode(FalconTransport& t);

/// Boot-ROM mode, before a firmware upload: purge RX/TX, latency 16 ms, 9600 Bd, 8N1, no flow
/// control, RTS low, DTR low, DTR high (the DTR edge restarts the DSP into its boot ROM).
UsbStatus SetFirmwareMode(FalconTransport& t);

}  // namespace palpa::device_falcon::ftdi
