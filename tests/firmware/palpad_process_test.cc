// Runs the built palpad binary (PALPAD_PATH) on good and bad inputs: exit codes, messages, and
// that a refused input never leaves an output file.

#include <dirent.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>

#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "palpa/blob/blob.h"
#include "sphere_fixture.h"

namespace palpa {
namespace {

using firmware_test::SphereField;

struct Result {
  int exit_code = -1;
  std::string out;
  std::string err;
};

std::string ReadAll(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

void WriteAll(const std::string& path, const std::string& bytes) {
  std::ofstream f(path, std::ios::binary);
  f << bytes;
}

bool Exists(const std::string& path) {
  struct stat st {};
  return stat(path.c_str(), &st) == 0;
}

std::string Quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) {
    if (c == '\'') {
      q.append("'\\''");
    } else {
      q.push_back(c);
    }
  }
  q.push_back('\'');
  return q;
}

class PalpadProcess : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = ::testing::TempDir() + "/palpad_testXXXXXX";
    ASSERT_NE(mkdtemp(dir_.data()), nullptr);
    // A small sphere: 32³ nodes, R = 10 voxels of 0.5 mm, centre near the grid's middle.
    static const SphereField field(32, 10, 6, 0.5e-3, {16.2, 15.7, 16.4});
    blob_ = std::string(reinterpret_cast<const char*>(field.bytes().data()), field.bytes().size());
    WriteAll(Path("f.palpa"), blob_);
    const double r = field.radius_m();
    const auto samples = firmware_test::TraceFromKeys(
        field, {{0.0, r + 2e-3, {0, 0, 1}}, {0.1, r - 1e-3, {0, 0, 1}}, {0.2, r - 1e-3, {0, 0, 1}}}, 0.01);
    WriteAll(Path("t.csv"), trace::FormatTrace(samples, "palpad process test"));
  }

  void TearDown() override {
    if (DIR* d = opendir(dir_.c_str())) {
      while (const dirent* e = readdir(d)) {
        const std::string name = e->d_name;
        if (name != "." && name != "..") std::remove(Path(name).c_str());
      }
      closedir(d);
    }
    rmdir(dir_.c_str());
  }

  std::string Path(const std::string& name) const { return dir_ + "/" + name; }

  Result Run(const std::vector<std::string>& args) const {
    std::string cmd = Quote(PALPAD_PATH);
    // append() rather than "x" + string: GCC 12 -Wrestrict false positive on operator+.
    for (const std::string& a : args) cmd.append(" ").append(Quote(a));
    cmd.append(" >").append(Quote(Path("stdout.txt"))).append(" 2>").append(Quote(Path("stderr.txt")));
    const int status = std::system(cmd.c_str());
    Result r;
    r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.out = ReadAll(Path("stdout.txt"));
    r.err = ReadAll(Path("stderr.txt"));
    return r;
  }

  // The usual command line with the given field file.
  Result RunWithField(const std::string& field_name) const {
    return Run(
        {"--device", "sim", "--field", Path(field_name), "--trace", Path("t.csv"), "--out", Path("out.csv"), "--fast"});
  }

  int TempFilesLeft() const {
    int n = 0;
    if (DIR* d = opendir(dir_.c_str())) {
      while (const dirent* e = readdir(d)) n += std::string(e->d_name).find(".tmp.") != std::string::npos ? 1 : 0;
      closedir(d);
    }
    return n;
  }

  void ExpectRefusedBlob(const std::string& bytes, const std::string& field_name) {
    WriteAll(Path("bad.palpa"), bytes);
    const Result r = RunWithField("bad.palpa");
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_NE(r.err.find("palpad: " + Path("bad.palpa") + ": "), std::string::npos) << r.err;
    EXPECT_NE(r.err.find(field_name), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("byte"), std::string::npos) << r.err;
    EXPECT_FALSE(Exists(Path("out.csv"))) << "a refused blob must not produce output";
    EXPECT_EQ(TempFilesLeft(), 0);
    EXPECT_EQ(r.out, "") << "nothing ran, nothing to summarise";
  }

  std::string dir_;
  std::string blob_;
};

TEST_F(PalpadProcess, ValidInputsWriteTheCsvAndSummary) {
  const Result r = Run({"--device", "sim", "--field", Path("f.palpa"), "--trace", Path("t.csv"), "--out",
                        Path("out.csv"), "--fast", "--summary-json", Path("summary.json")});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string csv = ReadAll(Path("out.csv"));
  EXPECT_TRUE(csv.starts_with("t_s,hip_x_m,hip_y_m,hip_z_m,proxy_x_m,proxy_y_m,proxy_z_m,fx_n,fy_n,fz_n,contact\n"));
  std::size_t lines = 0;
  for (char c : csv) lines += c == '\n' ? 1 : 0;
  EXPECT_EQ(lines, 1u + 201u);  // header + ticks at 0, 1 ms, …, 200 ms
  EXPECT_NE(csv.find(",1\n"), std::string::npos) << "some ticks in contact";
  EXPECT_NE(r.out.find("ticks: 201\n"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("mode: fast\n"), std::string::npos) << r.out;
  for (const char* key : {"ticks in contact: ", "max force (N): ", "max penetration (mm): ", "median tick (ns): ",
                          "p99 tick (ns): ", "force clamps: ", "device errors: 0"}) {
    EXPECT_NE(r.out.find(key), std::string::npos) << key;
  }
  const std::string json = ReadAll(Path("summary.json"));
  EXPECT_NE(json.find("\"ticks\": 201"), std::string::npos) << json;
  EXPECT_NE(json.find("\"fast\": true"), std::string::npos) << json;
  EXPECT_EQ(TempFilesLeft(), 0);
}

TEST_F(PalpadProcess, PacedRunAtTheRequestedRate) {
  const Result r = Run({"--device", "sim", "--field", Path("f.palpa"), "--trace", Path("t.csv"), "--out",
                        Path("out.csv"), "--rate", "2000"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("ticks: 401\n"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("mode: paced at 2000 Hz\n"), std::string::npos) << r.out;
}

TEST_F(PalpadProcess, FlippedPayloadByteIsRefused) {
  std::string bad = blob_;
  bad[blob::kHeaderSize + 1000] = static_cast<char>(bad[blob::kHeaderSize + 1000] ^ 0x01);
  ExpectRefusedBlob(bad, "crc32c");
}

TEST_F(PalpadProcess, TruncatedBlobIsRefused) {
  ExpectRefusedBlob(blob_.substr(0, blob_.size() - 7), "payload");
  ExpectRefusedBlob(blob_.substr(0, 100), "header");
}

TEST_F(PalpadProcess, WrongMagicIsRefused) {
  std::string bad = blob_;
  bad[0] = 'X';
  ExpectRefusedBlob(bad, "magic");
}

TEST_F(PalpadProcess, WrongVersionIsRefused) {
  std::string bad = blob_;
  bad[8] = 7;  // version, little-endian uint16 at byte 8
  ExpectRefusedBlob(bad, "version");
}

TEST_F(PalpadProcess, MissingFieldFileIsRefused) {
  const Result r = RunWithField("absent.palpa");
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find(Path("absent.palpa")), std::string::npos) << r.err;
  EXPECT_FALSE(Exists(Path("out.csv")));
}

TEST_F(PalpadProcess, BadTraceLineIsRefusedNamingTheLine) {
  WriteAll(Path("bad.csv"), "t_s,x_m,y_m,z_m\n0,0,0,0.02\n0.1,abc,0,0.02\n0.2,0,0,0.02\n");
  const Result r = Run(
      {"--device", "sim", "--field", Path("f.palpa"), "--trace", Path("bad.csv"), "--out", Path("out.csv"), "--fast"});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find(Path("bad.csv") + ":3"), std::string::npos) << r.err;
  EXPECT_FALSE(Exists(Path("out.csv")));
}

TEST_F(PalpadProcess, MissingTraceFileIsRefused) {
  const Result r = Run({"--device", "sim", "--field", Path("f.palpa"), "--trace", Path("absent.csv"), "--out",
                        Path("out.csv"), "--fast"});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find(Path("absent.csv")), std::string::npos) << r.err;
  EXPECT_FALSE(Exists(Path("out.csv")));
}

TEST_F(PalpadProcess, BadStiffnessIsRefused) {
  const Result r = Run({"--device", "sim", "--field", Path("f.palpa"), "--trace", Path("t.csv"), "--out",
                        Path("out.csv"), "--fast", "--k", "-5"});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("stiffness"), std::string::npos) << r.err;
  EXPECT_FALSE(Exists(Path("out.csv")));
}

TEST_F(PalpadProcess, UnwritableOutputIsRefusedBeforeRunning) {
  const Result r = Run({"--device", "sim", "--field", Path("f.palpa"), "--trace", Path("t.csv"), "--out",
                        Path("no-such-dir/out.csv"), "--fast"});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("no-such-dir/out.csv"), std::string::npos) << r.err;
  EXPECT_EQ(r.out, "");
}

TEST_F(PalpadProcess, NoFalconConnectedExitsThree) {
  // No Falcon exists on the test machines (no USB stack at all): the libusb backend must say so.
  const Result r = Run({"--device", "falcon", "--field", Path("f.palpa"), "--out", Path("out.csv")});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_EQ(r.err, "palpad: no Novint Falcon (USB 0403:cb48) found\n");
  EXPECT_FALSE(Exists(Path("out.csv")));
}

TEST_F(PalpadProcess, UsageErrors) {
  for (const std::vector<std::string>& args : std::vector<std::vector<std::string>>{
           {"--device", "sim", "--field", "f", "--trace", "t", "--out", "o", "--bogus"},
           {"--device", "sim", "--field", "f", "--trace", "t", "--out"},
           {"--device", "sim", "--field", "f", "--trace", "t", "--out", "o", "--rate", "20000"},
       }) {
    const Result r = Run(args);
    EXPECT_EQ(r.exit_code, 2) << r.err;
    EXPECT_NE(r.err.find("usage: palpad"), std::string::npos) << r.err;
  }
  const Result help = Run({"--help"});
  EXPECT_EQ(help.exit_code, 0);
  EXPECT_NE(help.out.find("usage: palpad"), std::string::npos);
}

// ---------------------------------------------------------------- runtime (issue 9)

TEST_F(PalpadProcess, EstopOnAMachineWithoutTheChipExitsThreeNamingTheChip) {
  // Real here: the development and CI kernels have no GPIO chip at all.
  struct stat st {};
  if (stat("/dev/gpiochip0", &st) == 0) GTEST_SKIP() << "this machine has a GPIO chip";
  const Result r = Run({"--device", "sim", "--field", Path("f.palpa"), "--trace", Path("t.csv"), "--out",
                        Path("out.csv"), "--estop", "gpiochip0:17"});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_EQ(r.err,
            "palpad: --estop gpiochip0:17: cannot open GPIO chip 'gpiochip0': No such file or directory (this system "
            "has no such chip; `gpiodetect` lists the chips)\n");
  EXPECT_FALSE(Exists(Path("out.csv")));
  EXPECT_EQ(TempFilesLeft(), 0);
}

TEST_F(PalpadProcess, ARefusedRealtimeStepIsOneLoudWarningAndMarksEveryReport) {
  // CPU 1023 exists on no machine palpa runs on: the kernel refuses the affinity. The run's
  // timing is not what this test asserts: without real-time steps, on a machine busy with the
  // rest of the suite, 10 consecutive overruns at 2,000 Hz ended one fresh-clone run with the
  // overrun fault (exit 1), so the limit is off here.
  const Result r = Run({"--device", "sim", "--field", Path("f.palpa"), "--trace", Path("t.csv"), "--out",
                        Path("out.csv"), "--rate", "2000", "--cpu", "1023", "--overrun-limit", "0", "--summary-json",
                        Path("s.json"), "--status", Path("status.json")});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string warning = "palpad: WARNING: NOT REAL-TIME: CPU affinity (CPU 1023) refused: Invalid argument";
  EXPECT_NE(r.err.find(warning), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find(warning), r.err.rfind(warning)) << "one warning, not one per tick";
  EXPECT_NE(r.out.find("real-time: NO (refused: CPU affinity (CPU 1023): Invalid argument"), std::string::npos)
      << r.out;
  EXPECT_NE(r.out.find("wake-up latency (us): p50 "), std::string::npos) << r.out;
  const std::string json = ReadAll(Path("s.json"));
  EXPECT_NE(json.find("\"realtime\": false"), std::string::npos) << json;
  EXPECT_NE(json.find("\"rt_refused\": \"CPU affinity (CPU 1023): Invalid argument"), std::string::npos) << json;
  const std::string status = ReadAll(Path("status.json"));
  EXPECT_NE(status.find("\"state\": \"ended\""), std::string::npos) << status;
  EXPECT_NE(status.find("\"realtime\": false"), std::string::npos) << status;
  EXPECT_NE(status.find("\"samples\": 401"), std::string::npos) << status;
}

TEST_F(PalpadProcess, ConfigFileRunsAndTheCommandLineWins) {
  WriteAll(Path("p.toml"), "device = \"sim\"\nfield = \"" + Path("f.palpa") + "\"\ntrace = \"" + Path("t.csv") +
                               "\"\nout = \"" + Path("wrong.csv") + "\"\nfast = true\n");
  const Result r = Run({"--config", Path("p.toml"), "--out", Path("out.csv")});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("ticks: 201\n"), std::string::npos) << r.out;
  EXPECT_TRUE(Exists(Path("out.csv")));
  EXPECT_FALSE(Exists(Path("wrong.csv")));

  const Result check = Run({"--config", Path("p.toml"), "--check-config"});
  EXPECT_EQ(check.exit_code, 0) << check.err;
  EXPECT_NE(check.out.find("fast = true\n"), std::string::npos) << check.out;
  EXPECT_FALSE(Exists(Path("wrong.csv"))) << "--check-config runs nothing";

  WriteAll(Path("bad.toml"), "device = \"sim\"\n\nrate = \"1 kHz\"\n");
  const Result bad = Run({"--config", Path("bad.toml")});
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.err.find("palpad: " + Path("bad.toml") + ":3: key 'rate': must be a number"), std::string::npos)
      << bad.err;
}

TEST_F(PalpadProcess, OutDevNullKeepsNoCsv) {
  const Result r =
      Run({"--device", "sim", "--field", Path("f.palpa"), "--trace", Path("t.csv"), "--out", "/dev/null", "--fast"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("ticks: 201\n"), std::string::npos) << r.out;
}

}  // namespace
}  // namespace palpa
