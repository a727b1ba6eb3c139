// Firmware file validation and upload against the virtual Falcon's boot ROM (which parses the
// TI boot stream on its own to know where it ends, and echoes every byte).

#include <gtest/gtest.h>

#include <cstdio>
#include <fstream>
#include <string>

#include "firmware_image.h"
#include "palpa/device_falcon/firmware_loader.h"
#include "palpa/device_falcon/ftdi.h"
#include "palpa/device_virtual_falcon/virtual_falcon.h"

namespace palpa::device_falcon {
namespace {

using device_virtual_falcon::FaultKind;
using device_virtual_falcon::VirtualFalcon;
using device_virtual_falcon::VirtualFalconConfig;

FirmwareImage Image(std::vector<std::uint8_t> bytes) {
  EXPECT_TRUE(ValidateFirmwareImage(bytes, "fw.bin").has_value());
  return {"fw.bin", std::move(bytes)};
}

VirtualFalcon BootRomFalcon(std::vector<device_virtual_falcon::FaultSpec> faults = {}) {
  VirtualFalconConfig c;
  c.firmware_loaded = false;
  c.faults = std::move(faults);
  return VirtualFalcon(std::move(c));
}

TEST(FalconFirmwareFile, ValidationNamesTheByte) {
  const auto good = falcon_test::SyntheticFirmware();
  // nVent's layout: 22 header bytes + blocks (3643, 241, 336, 2 words) + end word = 8492 bytes.
  EXPECT_EQ(good.size(), 8492u);
  EXPECT_TRUE(ValidateFirmwareImage(good, "fw.bin").has_value());

  auto bad_key = good;
  bad_key[0] = 0x34;
  bad_key[1] = 0x12;
  EXPECT_EQ(ValidateFirmwareImage(bad_key, "fw.bin").error(),
            "fw.bin: byte 0: key 0x1234, a Falcon firmware file (TI boot stream) starts with 0x08AA");

  auto truncated = good;
  truncated.resize(5000);  // inside the first block, which starts at byte 22
  EXPECT_EQ(ValidateFirmwareImage(truncated, "fw.bin").error(),
            "fw.bin: byte 22: block of 3643 words runs past the end of the file (5000 bytes)");

  auto trailing = good;
  trailing.push_back(0);
  EXPECT_EQ(ValidateFirmwareImage(trailing, "fw.bin").error(), "fw.bin: byte 8492: 1 bytes after the end block");

  auto no_end = good;
  no_end.resize(good.size() - 2);
  EXPECT_NE(ValidateFirmwareImage(no_end, "fw.bin").error().find("byte 8490: file ends inside the block list"),
            std::string::npos);

  EXPECT_NE(ValidateFirmwareImage(std::vector<std::uint8_t>(10), "fw.bin").error().find("byte 10: file ends after 10"),
            std::string::npos);
}

TEST(FalconFirmwareFile, ReadFileErrorsNameThePath) {
  EXPECT_EQ(ReadFirmwareFile("/nonexistent/fw.bin").error(), "/nonexistent/fw.bin: cannot open the firmware file");
  const std::string path = ::testing::TempDir() + "/falcon_fw_test.bin";
  const auto good = falcon_test::SyntheticFirmware();
  {
    std::ofstream f(path, std::ios::binary);
    f.write(reinterpret_cast<const char*>(good.data()), static_cast<std::streamsize>(good.size()));
  }
  const auto image = ReadFirmwareFile(path);
  ASSERT_TRUE(image.has_value()) << image.error();
  EXPECT_EQ(image->bytes, good);
  std::remove(path.c_str());
}

TEST(FalconFirmwareLoader, ProbeTellsRunningFirmwareFromBootRom) {
  VirtualFalcon running{VirtualFalconConfig{}};
  falcon::DeviceStatus st;
  ASSERT_EQ(ftdi::SetNormalMode(running), UsbStatus::kOk);
  EXPECT_EQ(ProbeFirmware(running, st), ProbeResult::kAnswering);

  VirtualFalcon boot = BootRomFalcon();
  ASSERT_EQ(ftdi::SetNormalMode(boot), UsbStatus::kOk);
  const std::int64_t t0 = boot.NowNs();
  EXPECT_EQ(ProbeFirmware(boot, st, 20, 10'000), ProbeResult::kSilent);
  EXPECT_LE(boot.NowNs() - t0, 20 * 10'000'000 + 1'000'000) << "bounded: tries × timeout";
}

TEST(FalconFirmwareLoader, UploadsAndTheFirmwareAnswers) {
  VirtualFalcon v = BootRomFalcon();
  const FirmwareImage image = Image(falcon_test::SyntheticFirmware());
  const LoadReport r = LoadFirmware(v, image);
  EXPECT_TRUE(r.ok) << r.Message(10);
  EXPECT_EQ(r.attempts, 1);
  EXPECT_TRUE(v.firmware_running());
  EXPECT_EQ(v.uploads_completed(), 1u);
  EXPECT_EQ(r.Message(10), "firmware loaded (attempt 1 of 10)");
}

TEST(FalconFirmwareLoader, EchoMismatchOnEveryAttemptFailsWithOneLinePerAttempt) {
  VirtualFalcon v = BootRomFalcon({{FaultKind::kEcho, 1000}});
  const auto bytes = falcon_test::SyntheticFirmware();
  const FirmwareImage image = Image(bytes);
  LoaderConfig config;
  config.attempts = 4;
  const LoadReport r = LoadFirmware(v, image, config);
  EXPECT_FALSE(r.ok);
  EXPECT_EQ(r.attempts, 4);
  ASSERT_EQ(r.failures.size(), 4u);
  char expected[128];
  std::snprintf(expected, sizeof expected, "echo mismatch at byte 1000 of fw.bin (sent 0x%02X, got 0x%02X)",
                bytes[1000], bytes[1000] ^ 0x5A);
  for (const std::string& f : r.failures) EXPECT_EQ(f, expected);
  EXPECT_FALSE(v.firmware_running());
  const std::string m = r.Message(4);
  EXPECT_NE(m.find("firmware upload failed after 4 attempts"), std::string::npos) << m;
  EXPECT_NE(m.find("attempt 4: echo mismatch at byte 1000"), std::string::npos) << m;
}

TEST(FalconFirmwareLoader, ATransientEchoMismatchIsRetried) {
  VirtualFalcon v = BootRomFalcon({{FaultKind::kEchoOnce, 62}});  // first byte of the second chunk
  const LoadReport r = LoadFirmware(v, Image(falcon_test::SyntheticFirmware()));
  EXPECT_TRUE(r.ok);
  EXPECT_EQ(r.attempts, 2);
  ASSERT_EQ(r.failures.size(), 1u);
  EXPECT_NE(r.failures[0].find("echo mismatch at byte 62 "), std::string::npos) << r.failures[0];
  EXPECT_TRUE(v.firmware_running());
}

TEST(FalconFirmwareLoader, HandshakeFailureIsBoundedAndNamed) {
  // With no handshake tries the boot ROM is never greeted: each attempt fails at that step.
  VirtualFalcon v = BootRomFalcon();
  LoaderConfig config;
  config.attempts = 2;
  config.handshake_tries = 0;
  const LoadReport r = LoadFirmware(v, Image(falcon_test::SyntheticFirmware()), config);
  EXPECT_FALSE(r.ok);
  ASSERT_EQ(r.failures.size(), 2u);
  EXPECT_EQ(r.failures[0], "handshake: no \"\\nD,\\r\" reply to 0 \"\\nC\\r\" requests");
}

}  // namespace
}  // namespace palpa::device_falcon
