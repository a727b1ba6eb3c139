#include "palpa/device_falcon/ftdi.h"

#include <initializer_list>
#include <utility>

namespace palpa::device_falcon::ftdi {
namespace {

UsbStatus Sequence(FalconTransport& t, std::initializer_list<std::pair<std::uint8_t, std::uint16_t>> steps) {
  for (const auto& [request, value] : steps) {
    const UsbStatus s = t.ControlOut(request, value, kControlTimeoutMs);
    if (s != UsbStatus::kOk) return s;
  }
  return UsbStatus::kOk;
}

}  // namespace

UsbStatus SetNormalMode(FalconTransport& t) {
  return Sequence(t, {{kReqReset, kPurgeRx},
                      {kReqReset, kPurgeTx},
                      {kReqSetLatency, kLatencyNormalMs},
                      {kReqSetBaudRate, kBaud1M5},
                      {kReqReset, kPurgeRx},
                      {kReqReset, kPurgeTx}});
}

UsbStatus SetFirmwareMode(FalconTransport& t) {
  return Sequence(t, {{kReqReset, kPurgeRx},
                      {kReqReset, kPurgeTx},
                      {kReqSetLatency, kLatencyFirmwareMs},
                      {kReqSetBaudRate, kBaud9600},
                      {kReqSetData, kData8N1},
                      {kReqSetFlowCtrl, 0},
                      {kReqModemCtrl, kRtsLow},
                      {kReqModemCtrl, kDtrLow},
                      {kReqModemCtrl, kDtrHigh}});
}

}  // namespace palpa::device_falcon::ftdi
