// Issue 18 (fail safe), the controller side, as a user runs palpad: device faults injected by the
// virtual Falcon at each phase (homing, free motion, contact) with the frozen-encoder regression
// on the kitten stroke; every catchable signal mid-contact ends in a zero-force write and a normal
// exit, every fatal one in a best-effort zero-torque packet, and no temporary file survives;
// stiffness and force above the device's limits are refused, in --check-config too.
//
// PALPA_TEST_PALPAD=/path/to/palpad runs these against another palpad (e.g. main's, to see them
// fail there).

#include <dirent.h>
#include <fcntl.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "sphere_fixture.h"

namespace palpa {
namespace {

using firmware_test::SphereField;

std::string Palpad() {
  const char* other = std::getenv("PALPA_TEST_PALPAD");
  return other != nullptr && *other != '\0' ? other : PALPAD_PATH;
}

std::string ReadAll(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

bool Has(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> out;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) out.push_back(line);
  return out;
}

// The force columns (fx, fy, fz: 8th-10th) of one output CSV row.
std::array<double, 3> ForceOf(const std::string& row) {
  std::array<double, 3> f{};
  std::istringstream in(row);
  std::string cell;
  for (int col = 0; std::getline(in, cell, ','); ++col)
    if (col >= 7 && col <= 9) f[static_cast<std::size_t>(col - 7)] = std::stod(cell);
  return f;
}

// The number after `key` in `text` ("ticks: 1001" → 1001), −1 if absent.
long long NumberAfter(const std::string& text, const std::string& key) {
  const auto at = text.find(key);
  if (at == std::string::npos) return -1;
  return std::atoll(text.c_str() + at + key.size());
}

struct Child {
  pid_t pid = -1;
  std::string dir;
};

struct Result {
  int exit_code = -1;  // −1 when killed by a signal
  int signal = 0;      // the signal that killed it, 0 if it exited
  std::string out, err;
};

// Starts `program args` with stdout/stderr into `out_dir`/stdout.txt, stderr.txt.
Child Start(const std::string& program, const std::vector<std::string>& args, const std::string& out_dir) {
  Child c;
  c.dir = out_dir;
  c.pid = fork();
  if (c.pid == 0) {
    const int out = open((out_dir + "/stdout.txt").c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int err = open((out_dir + "/stderr.txt").c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    dup2(out, 1);
    dup2(err, 2);
    std::vector<char*> argv;
    argv.push_back(const_cast<char*>(program.c_str()));
    for (const std::string& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    execv(program.c_str(), argv.data());
    _exit(127);
  }
  return c;
}

// Waits ≤ 60 s; a child still there then (e.g. suspended by SIGTSTP) is killed and reported as
// killed by SIGKILL, so a palpad that ignores its signal fails the test instead of hanging it.
Result Wait(const Child& c) {
  int status = 0;
  bool done = false;
  for (int i = 0; i < 1200 && !done; ++i) {
    done = waitpid(c.pid, &status, WNOHANG) == c.pid;
    if (!done) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  if (!done) {
    kill(c.pid, SIGKILL);
    waitpid(c.pid, &status, 0);
  }
  Result r;
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  r.signal = WIFSIGNALED(status) ? WTERMSIG(status) : 0;
  r.out = ReadAll(c.dir + "/stdout.txt");
  r.err = ReadAll(c.dir + "/stderr.txt");
  return r;
}

Child FailSafeStart(const std::string& dir, const std::vector<std::string>& args) { return Start(Palpad(), args, dir); }
Result FailSafeWait(const Child& c) { return Wait(c); }

class FailSafe : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = ::testing::TempDir() + "/fail_safe_XXXXXX";
    ASSERT_NE(mkdtemp(dir_.data()), nullptr);
    static const SphereField field;  // R = 10 mm near the device-frame origin
    {
      std::ofstream f(Path("f.palpa"), std::ios::binary);
      f.write(reinterpret_cast<const char*>(field.bytes().data()), static_cast<std::streamsize>(field.bytes().size()));
    }
    const double r = field.radius_m();
    // 0-0.3 s free (3 mm outside), then 2 mm deep, sliding back and forth over the surface
    // (0.4 rad each second: ~4 mm/s, so the encoders keep moving) until 20 s.
    std::vector<firmware_test::KeyFrame> keys = {{0.0, r + 3e-3, {0, 0.3, 1}}, {0.3, r - 2e-3, {0, 0.3, 1}}};
    for (int s = 1; s <= 20; ++s) keys.push_back({static_cast<double>(s), r - 2e-3, {s % 2 == 1 ? 0.4 : 0.0, 0.3, 1}});
    std::ofstream(Path("long.csv")) << trace::FormatTrace(firmware_test::TraceFromKeys(field, keys, 0.01), "fail-safe");
    keys.resize(5);  // 3 s: the --fast fault runs
    keys.back().t_s = 3.0;
    std::ofstream(Path("short.csv")) << trace::FormatTrace(firmware_test::TraceFromKeys(field, keys, 0.01),
                                                           "fail-safe");
  }

  void TearDown() override {
    if (HasFailure()) return;  // keep the files of a failed test
    for (const std::string& name : Files(dir_)) {
      const std::string p = dir_ + "/" + name;
      struct stat st {};
      if (stat(p.c_str(), &st) == 0 && S_ISDIR(st.st_mode)) {
        for (const std::string& inner : Files(p)) std::remove((p + "/" + inner).c_str());
        rmdir(p.c_str());
      } else {
        std::remove(p.c_str());
      }
    }
    rmdir(dir_.c_str());
  }

  static std::vector<std::string> Files(const std::string& dir) {
    std::vector<std::string> names;
    if (DIR* d = opendir(dir.c_str())) {
      while (const dirent* e = readdir(d)) {
        const std::string name = e->d_name;
        if (name != "." && name != "..") names.push_back(name);
      }
      closedir(d);
    }
    return names;
  }

  std::string Path(const std::string& name) const { return dir_ + "/" + name; }

  Result Run(const std::vector<std::string>& args) const { return Wait(Start(Palpad(), args, dir_)); }

  // A --fast virtual-Falcon run of the 3 s trace.
  Result Virtual(std::vector<std::string> extra) const {
    std::vector<std::string> args = {"--device",        "virtual-falcon", "--field",       Path("f.palpa"), "--trace",
                                     Path("short.csv"), "--out",          Path("out.csv"), "--fast"};
    args.insert(args.end(), extra.begin(), extra.end());
    return Run(args);
  }

  // Packet exchanges before forces came on (homing and the pull-out), from a clean run: fault
  // indices of `frozen@N` count from power-up, so "tick T of the run" is N = this + T.
  long long HomingExchanges() const {
    const Result r = Virtual({});
    EXPECT_EQ(r.exit_code, 0) << r.err;
    const long long exchanges = NumberAfter(r.err, "palpad: falcon: ");
    const long long ticks = NumberAfter(r.out, "ticks: ");
    EXPECT_GT(exchanges, ticks) << r.err << r.out;
    return exchanges - ticks;
  }

  std::string dir_;
};

// ---- Device supervision in contact (finding 1) ----

TEST_F(FailSafe, FrozenEncodersInContactStopTheForceAfterTheStatedTime) {
  const long long homing = HomingExchanges();
  const long long freeze_tick = 800;  // 0.8 s: in contact (from 0.3 s) and sliding
  const Result r = Virtual({"--fault", "frozen@" + std::to_string(homing + freeze_tick)});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_TRUE(Has(r.err, "device fault: encoders frozen at (")) << r.err;
  EXPECT_TRUE(Has(r.err, "for 500.000 ms while commanding torque (")) << r.err;
  EXPECT_TRUE(Has(r.err, "torque zero at the end")) << r.err;
  EXPECT_TRUE(Has(r.out, "device errors: 1")) << r.out;
  EXPECT_TRUE(Has(r.out, "end: device error")) << r.out;
  // The force was non-zero when the encoders froze, and the run ends 500 ms of ticks after it plus
  // the 50 ms fade of the held torque (±10: the freeze tick is known from the clean run's exchange
  // count to a few exchanges).
  const auto rows = Lines(ReadAll(Path("out.csv")));
  ASSERT_GT(rows.size(), static_cast<std::size_t>(freeze_tick + 1));
  const auto f = ForceOf(rows[static_cast<std::size_t>(freeze_tick)]);
  EXPECT_GT(std::abs(f[0]) + std::abs(f[1]) + std::abs(f[2]), 0.1);
  EXPECT_LE(static_cast<long long>(rows.size()) - 1, freeze_tick + 550 + 10);
  EXPECT_GE(static_cast<long long>(rows.size()) - 1, freeze_tick + 550 - 10);  // and not before it
}

TEST_F(FailSafe, FrozenEncodersInFreeMotionCommandNoForce) {
  // Frozen at 0.1 s, 3 mm outside: the HIP stays there while the hand goes in, so palpad never
  // commands a force (the detector only watches commanded torque: an idle grip may rest still).
  const long long homing = HomingExchanges();
  const Result r = Virtual({"--fault", "frozen@" + std::to_string(homing + 100)});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(Has(r.err, "torque zero at the end")) << r.err;
  const auto rows = Lines(ReadAll(Path("out.csv")));
  ASSERT_GT(rows.size(), 2000u);
  for (std::size_t i = 1; i < rows.size(); ++i) {
    const auto f = ForceOf(rows[i]);
    ASSERT_EQ(f[0] == 0.0 && f[1] == 0.0 && f[2] == 0.0, true) << "row " << i << ": " << rows[i];
  }
}

TEST_F(FailSafe, FrozenEncodersDuringThePullOutEndHoming) {
  // Frozen a few exchanges before forces would come on (blue LED, the grip being pulled out):
  // the grip never reads beyond z 0.170 m, forces never come on, homing times out.
  const long long homing = HomingExchanges();
  const Result r = Virtual({"--fault", "frozen@" + std::to_string(homing - 40), "--home-timeout", "2"});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_TRUE(Has(r.err, "Falcon homed, but the grip was not pulled out")) << r.err;
  EXPECT_TRUE(Has(r.err, "torque zero at the end, 0 commands with torque before homing")) << r.err;
}

TEST_F(FailSafe, EachFaultInFreeMotionEndsTheRunWithZeroTorque) {
  for (const std::string fault : {"drop@100", "corrupt@100", "jump@100", "unplug@100"}) {
    const Result r = Virtual({"--fault", fault});
    EXPECT_EQ(r.exit_code, 1) << fault << "\n" << r.err;
    EXPECT_GE(NumberAfter(r.out, "device errors: "), 1) << fault << "\n" << r.out;
    EXPECT_TRUE(Has(r.err, fault.starts_with("unplug") ? "zero torque could not be sent" : "torque zero at the end"))
        << fault << "\n"
        << r.err;
    const auto rows = Lines(ReadAll(Path("out.csv")));
    EXPECT_LE(rows.size(), 103u) << fault;  // header + ≤ 101 ticks + the failing one
  }
}

// `palpad --device virtual-falcon --fault frozen@2774 --fast` on the kitten stroke (issue 18,
// finding 1): the same force was commanded for 1,775 ticks until the trace ended, exit 0.
TEST_F(FailSafe, KittenStrokeFrozenAt2774StopsAndExitsOne) {
  const std::string src = PALPA_SOURCE_DIR;
  {
    const Child b =
        Start(PALPA_PATH, {"build", src + "/data/kitten.xyz", "--fit", "0.06", "-o", Path("kitten.palpa"), "-q"}, dir_);
    const Result built = Wait(b);
    ASSERT_EQ(built.exit_code, 0) << built.err;
  }
  const Result r =
      Run({"--device", "virtual-falcon", "--fault", "frozen@2774", "--fast", "--field", Path("kitten.palpa"), "--trace",
           src + "/hil/traces/kitten-stroke.ptb", "--out", Path("k.csv")});
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_TRUE(Has(r.err, "device fault: encoders frozen at (")) << r.err;
  EXPECT_TRUE(Has(r.out, "device errors: 1")) << r.out;
  EXPECT_TRUE(Has(r.err, "torque zero at the end")) << r.err;
  // The run stops ≤ 500 ms + the 50 ms fade of ticks after the freeze, not at the end of the trace.
  const long long ticks = NumberAfter(r.out, "ticks: ");
  const long long exchanges = NumberAfter(r.err, "palpad: falcon: ");
  ASSERT_GT(ticks, 0) << r.out;
  EXPECT_LE(exchanges, 2774 + 550 + 2) << r.err;
  EXPECT_LT(ticks, 3290) << r.out;
}

// ---- Every way out writes zero force first (finding 2) ----

// Runs paced (as a service does) with every output that has a temporary file, in their own
// directory; the overrun and watchdog faults are off so that a loaded test machine cannot end
// the run before the signal does.
Child StartPaced(const std::string& dir, const std::string& field, const std::string& trace,
                 const std::string& device) {
  mkdir(dir.c_str(), 0755);
  return FailSafeStart(dir, {"--device",        device,
                             "--field",         field,
                             "--trace",         trace,
                             "--out",           dir + "/out.csv",
                             "--status",        dir + "/status.json",
                             "--record",        dir + "/rec.ptb",
                             "--record-timing", dir + "/timing.csv",
                             "--summary-json",  dir + "/summary.json",
                             "--overrun-limit", "0",
                             "--watchdog-ms",   "0"});
}

// Waits until the live status shows ticks in contact (≤ 60 s).
bool WaitForContact(const Child& c) {
  for (int i = 0; i < 1200; ++i) {
    if (NumberAfter(ReadAll(c.dir + "/status.json"), "\"contact_ticks\": ") > 0) return true;
    int status = 0;
    if (waitpid(c.pid, &status, WNOHANG) == c.pid) return false;  // it ended by itself
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  return false;
}

std::vector<std::string> TempFilesIn(const std::string& dir) {
  std::vector<std::string> temps;
  if (DIR* d = opendir(dir.c_str())) {
    while (const dirent* e = readdir(d)) {
      const std::string name = e->d_name;
      if (name.find(".tmp") != std::string::npos) temps.push_back(name);
    }
    closedir(d);
  }
  return temps;
}

const std::vector<int>& StopSignals() {
  static const std::vector<int> sigs = {SIGHUP,  SIGINT,    SIGQUIT, SIGTERM, SIGUSR1, SIGUSR2,
                                        SIGALRM, SIGVTALRM, SIGPROF, SIGXCPU, SIGXFSZ, SIGIO,
                                        SIGPWR,  SIGTSTP,   SIGTTIN, SIGTTOU, SIGRTMIN};
  return sigs;
}

void CheckStopSignals(const std::string& base, const std::string& field, const std::string& trace,
                      const std::string& device) {
  // All runs at once (each waits for contact before its signal): ~20 paced processes.
  std::vector<Child> runs;
  for (const int sig : StopSignals())
    runs.push_back(StartPaced(base + "/" + device + "-" + std::to_string(sig), field, trace, device));
  std::vector<bool> signalled(runs.size(), false);
  for (std::size_t i = 0; i < runs.size(); ++i) {
    signalled[i] = WaitForContact(runs[i]);
    if (signalled[i]) kill(runs[i].pid, StopSignals()[i]);
  }
  for (std::size_t i = 0; i < runs.size(); ++i) {
    const int sig = StopSignals()[i];
    const std::string name = sigabbrev_np(sig) != nullptr ? sigabbrev_np(sig) : std::to_string(sig);
    const Result r = FailSafeWait(runs[i]);
    SCOPED_TRACE(device + " SIG" + name + "\n" + r.err);
    ASSERT_TRUE(signalled[i]) << "never reached contact";
    EXPECT_EQ(r.signal, 0) << "killed by signal " << r.signal;
    EXPECT_EQ(r.exit_code, 0);
    EXPECT_TRUE(Has(r.err, "palpad: stopped by signal ")) << r.err;
    if (device == "sim") {
      EXPECT_TRUE(Has(r.err, "palpad: sim device: last force written (0, 0, 0) N")) << r.err;
    } else {
      EXPECT_TRUE(Has(r.err, "virtual falcon: torque zero at the end")) << r.err;
    }
    EXPECT_TRUE(TempFilesIn(runs[i].dir).empty()) << TempFilesIn(runs[i].dir).front();
    // The outputs were committed: the CSV holds the ticks up to the signal, contact among them.
    const std::string csv = ReadAll(runs[i].dir + "/out.csv");
    EXPECT_TRUE(Has(csv, ",1\n")) << "no contact row in out.csv";
    EXPECT_TRUE(Has(ReadAll(runs[i].dir + "/summary.json"), "\"end\": \"stopped\"")) << runs[i].dir;
  }
}

TEST_F(FailSafe, EveryStopSignalMidContactWritesZeroForceAndExitsCleanlyVirtualFalcon) {
  CheckStopSignals(dir_, Path("f.palpa"), Path("long.csv"), "virtual-falcon");
}

TEST_F(FailSafe, EveryStopSignalMidContactWritesZeroForceAndExitsCleanlySim) {
  CheckStopSignals(dir_, Path("f.palpa"), Path("long.csv"), "sim");
}

TEST_F(FailSafe, SigpipeIsIgnored) {
  const Child c = StartPaced(Path("pipe"), Path("f.palpa"), Path("long.csv"), "virtual-falcon");
  ASSERT_TRUE(WaitForContact(c));
  kill(c.pid, SIGPIPE);
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  int status = 0;
  EXPECT_EQ(waitpid(c.pid, &status, WNOHANG), 0) << "palpad died of SIGPIPE";
  kill(c.pid, SIGTERM);
  const Result r = FailSafeWait(c);
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(Has(r.err, "stopped by signal SIGTERM")) << r.err;
}

TEST_F(FailSafe, FatalSignalsSendZeroTorqueAndLeaveNoTemporaryFile) {
  const std::vector<int> fatal = {SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT, SIGTRAP, SIGSYS};
  std::vector<Child> runs;
  for (const int sig : fatal)
    runs.push_back(
        StartPaced(Path("fatal-" + std::to_string(sig)), Path("f.palpa"), Path("long.csv"), "virtual-falcon"));
  for (std::size_t i = 0; i < runs.size(); ++i) {
    ASSERT_TRUE(WaitForContact(runs[i]));
    kill(runs[i].pid, fatal[i]);
  }
  for (std::size_t i = 0; i < runs.size(); ++i) {
    const Result r = FailSafeWait(runs[i]);
    SCOPED_TRACE(std::string("SIG") + sigabbrev_np(fatal[i]) + "\n" + r.err);
    EXPECT_EQ(r.signal, fatal[i]);  // dies of the same signal (core dump as usual)
    EXPECT_TRUE(Has(r.err, std::string("palpad: fatal signal SIG") + sigabbrev_np(fatal[i]))) << r.err;
    EXPECT_TRUE(Has(r.err, "palpad: zero-torque packet sent to the Falcon")) << r.err;
    EXPECT_TRUE(Has(r.err, "palpad: virtual falcon: torque zero after the fatal signal")) << r.err;
    EXPECT_TRUE(TempFilesIn(runs[i].dir).empty()) << TempFilesIn(runs[i].dir).front();
  }
  // The sim device: nothing to zero, the temporary files still go.
  const Child c = StartPaced(Path("fatal-sim"), Path("f.palpa"), Path("long.csv"), "sim");
  ASSERT_TRUE(WaitForContact(c));
  kill(c.pid, SIGSEGV);
  const Result r = FailSafeWait(c);
  EXPECT_EQ(r.signal, SIGSEGV);
  EXPECT_TRUE(Has(r.err, "palpad: fatal signal SIGSEGV: temporary files removed")) << r.err;
  EXPECT_TRUE(TempFilesIn(c.dir).empty()) << TempFilesIn(c.dir).front();
}

// ---- Stiffness and force limits from the device (finding 3); --check-config (finding 11) ----

TEST_F(FailSafe, StiffnessAndForceAboveTheDeviceAreRefusedAtStartAndInCheckConfig) {
  struct Case {
    std::vector<std::string> args;
    std::string message;
  };
  const std::vector<std::string> vf = {"--device", "virtual-falcon", "--trace", Path("short.csv")};
  const std::vector<std::string> sim = {"--device", "sim", "--trace", Path("short.csv")};
  const auto with = [](std::vector<std::string> a, std::vector<std::string> more) {
    a.insert(a.end(), more.begin(), more.end());
    return a;
  };
  const std::vector<Case> cases = {
      {with(vf, {"--k", "100000"}), "--k 100000 N/m is above the 3000 N/m that the Novint Falcon renders stably"},
      {with(vf, {"--k", "3001"}), "--k 3001 N/m is above the 3000 N/m"},
      {with(vf, {"--max-force", "8.5"}), "--max-force 8.5 N is above the 8 N force rating of the Novint Falcon"},
      {with(sim, {"--k", "1e9"}), "--k 1e+09 N/m is above the 100000 N/m"},
      {with(sim, {"--k", "-5"}), "--k must be a stiffness > 0 N/m, got -5"},
      {with(sim, {"--max-force", "0"}), "--max-force must be a force > 0 N, got 0"},
      {with(sim, {"--max-force", "1e6"}), "--max-force 1e+06 N is above the 100 N force rating"},
      {with(vf, {"--k", "1e9", "--allow-unsafe-stiffness"}), "--k 1e+09 N/m is above the 100000 N/m"},
  };
  for (const Case& c : cases) {
    for (const bool check : {true, false}) {
      std::vector<std::string> args = with(c.args, {"--field", Path("f.palpa"), "--out", Path("lim.csv"), "--fast"});
      if (check) args.push_back("--check-config");
      const Result r = Run(args);
      EXPECT_EQ(r.exit_code, 2) << (check ? "--check-config " : "run ") << c.message << "\n" << r.err;
      EXPECT_TRUE(Has(r.err, c.message)) << r.err;
      EXPECT_FALSE(Has(ReadAll(Path("lim.csv")), "t_s")) << "the run started";
    }
  }
  // Within the limits, and above them with the documented override: accepted.
  EXPECT_EQ(
      Run(with(vf, {"--field", Path("f.palpa"), "--out", Path("lim.csv"), "--k", "3000", "--check-config"})).exit_code,
      0);
  const Result unsafe = Virtual({"--k", "5000", "--allow-unsafe-stiffness"});
  EXPECT_EQ(unsafe.exit_code, 0) << unsafe.err;
}

TEST_F(FailSafe, ConfigRangeErrorsNameTheFileAndLine) {
  std::ofstream(Path("palpad.toml")) << "# palpad\nfield = \"" << Path("f.palpa") << "\"\nout = \"" << Path("o.csv")
                                     << "\"\ntrace = \"" << Path("short.csv") << "\"\n\nk = 1e9\n";
  Result r = Run({"--config", Path("palpad.toml"), "--check-config"});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_TRUE(Has(r.err, Path("palpad.toml") + ":6: key 'k': --k 1e+09 N/m is above")) << r.err;
  std::ofstream(Path("palpad.toml"), std::ios::app) << "rate = 20000\n";
  r = Run({"--config", Path("palpad.toml"), "--check-config", "--k", "800"});
  EXPECT_TRUE(Has(r.err, Path("palpad.toml") + ":7: key 'rate': --rate must be in 1..10000 Hz")) << r.err;
  // The command line's own value is not blamed on the file.
  r = Run({"--config", Path("palpad.toml"), "--check-config", "--k", "800", "--rate", "0"});
  EXPECT_TRUE(Has(r.err, "palpad: --rate must be in 1..10000 Hz")) << r.err;
}

TEST_F(FailSafe, HelpNamesBothBlobVersions) {
  const Result r = Run({"--help"});
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_FALSE(Has(r.out, "blob v1 (")) << r.out;
  EXPECT_TRUE(Has(r.out, "blob v1 or v2")) << r.out;
}

}  // namespace
}  // namespace palpa
