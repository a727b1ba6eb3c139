// palpad and palpa as a user runs them: --device falcon without a Falcon, --device virtual-falcon
// with each fault (exit code, message, zero torque at the end), SIGTERM mid-contact, firmware
// files, and `palpa falcon ik|fk` against the notes' vectors.

#include <dirent.h>
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "firmware_image.h"
#include "sphere_fixture.h"

namespace palpa {
namespace {

using firmware_test::SphereField;

struct Result {
  int exit_code = -1;
  std::string out, err;
};

std::string ReadAll(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

bool Exists(const std::string& path) {
  struct stat st {};
  return stat(path.c_str(), &st) == 0;
}

bool Has(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

class FalconProcess : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = ::testing::TempDir() + "/falcon_proc_XXXXXX";
    ASSERT_NE(mkdtemp(dir_.data()), nullptr);
    static const SphereField field;  // R = 10 mm near the device-frame origin
    {
      std::ofstream f(Path("f.palpa"), std::ios::binary);
      f.write(reinterpret_cast<const char*>(field.bytes().data()), static_cast<std::streamsize>(field.bytes().size()));
    }
    const double r = field.radius_m();
    const auto samples = firmware_test::TraceFromKeys(
        field, {{0.0, r + 3e-3, {0, 0.3, 1}}, {0.3, r - 2e-3, {0, 0.3, 1}}, {1.0, r - 2e-3, {0.4, 0.3, 1}}}, 0.01);
    std::ofstream(Path("t.csv")) << trace::FormatTrace(samples, "falcon process test");
    const auto fw = falcon_test::SyntheticFirmware();
    std::ofstream(Path("fw.bin"), std::ios::binary)
        .write(reinterpret_cast<const char*>(fw.data()), static_cast<std::streamsize>(fw.size()));
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

  // fork/exec with stdout/stderr to files; optional SIGTERM after `term_after`.
  Result Run(const std::string& program, const std::vector<std::string>& args,
             std::chrono::milliseconds term_after = std::chrono::milliseconds(0)) const {
    std::remove(Path("stdout.txt").c_str());
    std::remove(Path("stderr.txt").c_str());
    const pid_t pid = fork();
    if (pid == 0) {
      const int out = open(Path("stdout.txt").c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      const int err = open(Path("stderr.txt").c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
      dup2(out, 1);
      dup2(err, 2);
      std::vector<char*> argv;
      argv.push_back(const_cast<char*>(program.c_str()));
      for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
      argv.push_back(nullptr);
      execv(program.c_str(), argv.data());
      _exit(127);
    }
    if (term_after.count() > 0) {
      std::this_thread::sleep_for(term_after);
      kill(pid, SIGTERM);
    }
    int status = 0;
    waitpid(pid, &status, 0);
    Result r;
    r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
    r.out = ReadAll(Path("stdout.txt"));
    r.err = ReadAll(Path("stderr.txt"));
    return r;
  }

  Result Virtual(std::vector<std::string> extra, bool fast = true) const {
    std::vector<std::string> args = {"--device", "virtual-falcon", "--field", Path("f.palpa"),
                                     "--trace",  Path("t.csv"),    "--out",   Path("out.csv")};
    if (fast) args.push_back("--fast");
    args.insert(args.end(), extra.begin(), extra.end());
    return Run(PALPAD_PATH, args);
  }

  std::string dir_;
};

TEST_F(FalconProcess, NoFalconAttachedExitsThree) {
  const Result r = Run(PALPAD_PATH, {"--device", "falcon", "--field", Path("f.palpa"), "--out", Path("out.csv")});
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_TRUE(Has(r.err, "palpad: no Novint Falcon (USB 0403:cb48) found")) << r.err;
  EXPECT_FALSE(Exists(Path("out.csv")));
  const Result i = Run(
      PALPAD_PATH, {"--device", "falcon", "--usb-index", "2", "--field", Path("f.palpa"), "--out", Path("out.csv")});
  EXPECT_EQ(i.exit_code, 3);
  EXPECT_TRUE(Has(i.err, "no Novint Falcon (USB 0403:cb48) found")) << i.err;
}

TEST_F(FalconProcess, VirtualFalconRunsTheTrace) {
  const Result r = Virtual({});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(Has(r.err, "Falcon: firmware already loaded")) << r.err;
  EXPECT_TRUE(Has(r.err, "virtual falcon: torque zero at the end, 0 commands with torque before homing")) << r.err;
  EXPECT_TRUE(Has(r.out, "ticks: 1001")) << r.out;
  EXPECT_TRUE(Has(r.out, "device errors: 0")) << r.out;
  const std::string csv = ReadAll(Path("out.csv"));
  EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 1002);  // header + 1001 ticks
}

TEST_F(FalconProcess, VirtualFalconUploadsTheGivenFirmware) {
  const Result r = Virtual({"--firmware", Path("fw.bin")});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(Has(r.err, "uploading " + Path("fw.bin") + " (8492 bytes)")) << r.err;
  EXPECT_TRUE(Has(r.err, "firmware loaded (attempt 1 of 10)")) << r.err;
}

TEST_F(FalconProcess, EachFaultEndsWithZeroTorqueAndAClearMessage) {
  struct Case {
    std::string fault;
    int exit_code;
    std::string message;
  };
  const Case cases[] = {
      {"drop@400", 1, "Falcon stopped replying: no valid reply 2.000 ms after a command"},
      {"corrupt@400", 1, "Falcon stopped replying"},
      {"jump@400", 1, "Falcon encoder 2 jumped by"},
      {"unplug@400", 1, "Falcon disconnected (USB: no device)"},
      {"split@0", 0, " split replies"},
      {"garbage@400", 0, "13 bytes skipped re-framing"},
  };
  for (const Case& c : cases) {
    const Result r = Virtual({"--fault", c.fault});
    EXPECT_EQ(r.exit_code, c.exit_code) << c.fault << "\n" << r.err;
    EXPECT_TRUE(Has(r.err, c.message)) << c.fault << "\n" << r.err;
    if (c.fault.starts_with("unplug")) {
      EXPECT_TRUE(Has(r.err, "zero torque could not be sent")) << r.err;
    } else {
      EXPECT_TRUE(Has(r.err, "torque zero at the end")) << c.fault << "\n" << r.err;
    }
  }
  // Frozen encoders: homing cannot finish; nothing is run, no output file.
  std::remove(Path("out.csv").c_str());
  const Result f = Virtual({"--fault", "frozen", "--home-timeout", "2"});
  EXPECT_EQ(f.exit_code, 1) << f.err;
  EXPECT_TRUE(Has(f.err, "the firmware answers but no encoder changed")) << f.err;
  EXPECT_TRUE(Has(f.err, "torque zero at the end")) << f.err;
  EXPECT_FALSE(Exists(Path("out.csv")));
  // Firmware echo mismatch on every attempt: the upload fails with one line per attempt.
  const Result e = Virtual({"--firmware", Path("fw.bin"), "--fault", "echo@100"});
  EXPECT_EQ(e.exit_code, 1) << e.err;
  EXPECT_TRUE(Has(e.err, "firmware upload failed after 10 attempts")) << e.err;
  EXPECT_TRUE(Has(e.err, "attempt 10: echo mismatch at byte 100 of " + Path("fw.bin"))) << e.err;
}

TEST_F(FalconProcess, SigtermMidContactWritesZeroTorque) {
  // Paced at 1 kHz, the 1 s trace runs ≈ 1 s of wall time after homing; SIGTERM lands mid-run.
  const Result r = Run(
      PALPAD_PATH,
      {"--device", "virtual-falcon", "--field", Path("f.palpa"), "--trace", Path("t.csv"), "--out", Path("out.csv")},
      std::chrono::milliseconds(700));
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(Has(r.err, "stopped by signal")) << r.err;
  EXPECT_TRUE(Has(r.err, "torque zero at the end")) << r.err;
}

TEST_F(FalconProcess, BadInputsExitTwo) {
  std::ofstream(Path("bad.bin"), std::ios::binary) << "not firmware at all, definitely";
  Result r = Virtual({"--firmware", Path("bad.bin")});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_TRUE(Has(r.err, Path("bad.bin") + ": byte 0: key 0x6F6E")) << r.err;
  r = Virtual({"--fault", "meteor@3"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_TRUE(Has(r.err, "unknown fault 'meteor@3'")) << r.err;
  r = Run(PALPAD_PATH, {"--device", "sim", "--fault", "drop@1", "--field", "f", "--trace", "t", "--out", "o"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_TRUE(Has(r.err, "--fault needs --device virtual-falcon")) << r.err;
}

TEST_F(FalconProcess, PalpaFalconIkFk) {
  Result r = Run(PALPA_PATH, {"falcon", "ik", "0.02,-0.02,0.13"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  double t[3] = {0, 0, 0};
  const auto at = r.out.find("theta1_deg: ");
  ASSERT_NE(at, std::string::npos) << r.out;
  ASSERT_EQ(std::sscanf(r.out.c_str() + at, "theta1_deg: %lf %lf %lf", &t[0], &t[1], &t[2]), 3) << r.out;
  EXPECT_NEAR(t[0], 48.474, 6e-4);  // notes §5.3
  EXPECT_NEAR(t[1], 19.908, 6e-4);
  EXPECT_NEAR(t[2], 34.785, 6e-4);
  r = Run(PALPA_PATH, {"falcon", "fk", "300,-200,100"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(Has(r.out, "position_m: 0.014528 -0.011579 0.136148")) << r.out;  // notes §5.4
  r = Run(PALPA_PATH, {"falcon", "fk", "-500,-500,-500"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(Has(r.out, "position_m: 0.000000 0.000000 0.110754")) << r.out;
  r = Run(PALPA_PATH, {"falcon", "ik", "0.06,0.06,0.15"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_TRUE(Has(r.err, "outside the Falcon's reach")) << r.err;
  r = Run(PALPA_PATH, {"falcon", "fk", "1,2"});
  EXPECT_EQ(r.exit_code, 2);
}

}  // namespace
}  // namespace palpa
