// Issue 18, findings 4-8 and 11 (host part), as a user meets them: palpa and palpad never replace a
// device, FIFO, directory or an input with an output; never read a FIFO or a device as a file;
// quote input bytes escaped. Every command runs under `timeout` so that a hang (the old FIFO
// behaviour) fails the test instead of stalling it. Truths: the node types made here (stat), the
// exit codes README.md documents (0 ok, 1 I/O, 2 bad input), the bytes of the inputs.
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "palpa/trace/trace.h"
#include "process.h"

namespace {

namespace fs = std::filesystem;
using palpa::test_support::Outcome;

Outcome Palpa(const std::string& args) {
  return palpa::test_support::Run("timeout 60 " + std::string(PALPA_BIN) + " " + args);
}
Outcome Palpad(const std::string& args) {
  return palpa::test_support::Run("timeout 60 " + std::string(PALPA_NATIVE_PALPAD) + " " + args);
}

std::string Slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

bool IsFifo(const std::string& p) {
  struct stat st {};
  return ::lstat(p.c_str(), &st) == 0 && S_ISFIFO(st.st_mode);
}
bool IsCharDevice(const std::string& p) {
  struct stat st {};
  return ::lstat(p.c_str(), &st) == 0 && S_ISCHR(st.st_mode);
}

class FileSafety : public palpa::test_support::TempDirTest {
 protected:
  void SetUp() override {
    TempDirTest::SetUp();
    points_ = std::string(PALPA_DATA_DIR) + "/sphere926.pwn";
  }
  // A small field, built once per test that needs one.
  std::string Field() {
    const std::string f = Path("f.palpa");
    if (!fs::exists(f)) {
      const Outcome b = Palpa("build " + points_ + " -o " + f + " --cells 32 -q");
      EXPECT_EQ(b.code, 0) << b.out;
    }
    return f;
  }
  // A character device to aim outputs at. As root a regression would replace the target, so root
  // gets a private copy of /dev/null's node (1, 3) made here, never the system's; others get
  // /dev/null and /dev/full, which they cannot replace anyway. Empty if no node can be made.
  std::vector<std::string> Devices() {
    if (::geteuid() != 0) return {"/dev/null", "/dev/full"};
    const std::string p = Path("null.dev");
    if (!fs::exists(p) && ::mknod(p.c_str(), S_IFCHR | 0666, ::makedev(1, 3)) != 0) return {};
    return {p};
  }
  std::string Fifo(const std::string& leaf) {
    const std::string p = Path(leaf);
    EXPECT_EQ(::mkfifo(p.c_str(), 0600), 0);
    return p;
  }
  std::string points_;
};

// Finding 4: `palpa build scan.xyz -o scan.xyz` replaced the point set with the blob, exit 0.
TEST_F(FileSafety, BuildRefusesAnOutputThatIsItsInput) {
  const std::string scan = Write("scan.xyz", Slurp(points_));
  const std::string before = Slurp(scan);
  const Outcome r = Palpa("build " + scan + " -o " + scan + " --cells 32");
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_NE(r.out.find(scan + ": is the same file as the input"), std::string::npos) << r.out;
  EXPECT_EQ(Slurp(scan), before);
  fs::create_hard_link(scan, Path("hard.xyz"));  // same inode, another name
  EXPECT_EQ(Palpa("build " + scan + " -o " + Path("hard.xyz") + " --cells 32").code, 2);
  EXPECT_EQ(Slurp(scan), before);
}

// Finding 4: every writer renamed its temporary file over whatever was at the target (run as root,
// /dev/full became a regular file). Each command now refuses a device, FIFO or directory, exit 2,
// and leaves the node as it was.
TEST_F(FileSafety, EveryHostWriterRefusesDevicesFifosAndDirectories) {
  const std::string field = Field();
  const std::string fifo = Fifo("out.fifo");
  fs::create_directories(Path("dir.palpa"));
  const std::string mesh_in =
      Write("tetra.off", "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n");
  const std::string commands[] = {
      "build " + points_ + " --cells 32 -o ",
      "export " + field + " --npy ",
      "mesh " + field + " -o ",
      "slice " + field + " --axis z --at 0 -o ",
      "trace synth --field " + field + " -o ",
      "sample " + mesh_in + " --count 100 -o ",
  };
  for (const std::string& command : commands) {
    std::vector<std::string> targets = Devices();
    targets.push_back(fifo);
    targets.push_back(Path("dir.palpa"));
    for (const std::string& target : targets) {
      // mesh and sample want an extension; the check comes first for every target anyway.
      const Outcome r = Palpa(command + target);
      EXPECT_EQ(r.code, 2) << command << target << "\n" << r.out;
      EXPECT_NE(r.out.find(target + ": is a"), std::string::npos) << command << target << "\n" << r.out;
    }
  }
  for (const std::string& device : Devices()) EXPECT_TRUE(IsCharDevice(device)) << device;
  EXPECT_TRUE(IsFifo(fifo));
  EXPECT_TRUE(fs::is_directory(Path("dir.palpa")));
  for (const std::string& device : Devices()) {
    const Outcome keygen = Palpa("keygen -o " + device + " --force");
    EXPECT_EQ(keygen.code, 2) << keygen.out;
    EXPECT_TRUE(IsCharDevice(device));
  }
}

// Finding 6: `palpa info /dev/zero` read without limit and aborted (std::bad_alloc, signal 6).
TEST_F(FileSafety, InputsThatAreNotRegularFilesAreRefusedAtOnce) {
  for (const std::string& command :
       {std::string("info /dev/zero"), "export /dev/zero --npy " + Path("x.npy"), "mesh /dev/zero -o " + Path("x.ply"),
        "trace synth --field /dev/zero -o " + Path("x.csv")}) {
    const Outcome r = Palpa(command);
    EXPECT_EQ(r.code, 2) << command << r.out;
    EXPECT_NE(r.out.find("/dev/zero: is a character device, not a regular file"), std::string::npos) << r.out;
  }
  const std::string fifo = Fifo("points.xyz");
  const Outcome r = Palpa("build " + fifo + " -o " + Path("f.palpa"));
  EXPECT_EQ(r.code, 2) << r.out;  // used to block in open() until `timeout` killed it (124)
  EXPECT_NE(r.out.find("points.xyz: is a FIFO"), std::string::npos) << r.out;
}

// Finding 7: a FIFO as key file hung `palpa status` for ever; a symlinked key was refused with
// "Too many levels of symbolic links".
TEST_F(FileSafety, KeyFilesMustBeRegularAndLinksAreNamed) {
  const std::string fifo = Fifo("fifo.key");
  const Outcome f = Palpa("status --to 127.0.0.1:9 --key-file " + fifo);
  EXPECT_EQ(f.code, 2) << f.out;
  EXPECT_NE(f.out.find("not a regular file"), std::string::npos) << f.out;

  ASSERT_EQ(Palpa("keygen -o " + Path("real.key")).code, 0);
  fs::create_symlink(Path("real.key"), Path("link.key"));
  const Outcome l = Palpa("status --to 127.0.0.1:9 --key-file " + Path("link.key"));
  EXPECT_EQ(l.code, 2) << l.out;
  EXPECT_NE(l.out.find("is a symbolic link to " + fs::canonical(Path("real.key")).string()), std::string::npos)
      << l.out;
  EXPECT_EQ(l.out.find("Too many levels"), std::string::npos) << l.out;
}

// Finding 11: keygen into a directory it cannot write exited 2; the README says I/O failures exit 1.
TEST_F(FileSafety, KeygenIntoAReadOnlyDirectoryExitsOne) {
  std::string target;
  if (::geteuid() == 0) {
    target = "/proc/palpa-test.key";  // root ignores mode bits; /proc refuses new files to anyone
  } else {
    fs::create_directories(Path("ro"));
    fs::permissions(Path("ro"), fs::perms::owner_read | fs::perms::owner_exec);
    target = Path("ro/k.key");
  }
  const Outcome r = Palpa("keygen -o " + target);
  if (::geteuid() != 0) fs::permissions(Path("ro"), fs::perms::owner_all);
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_NE(r.out.find("cannot create"), std::string::npos) << r.out;
  // An existing key without --force is the user's choice: still 2.
  ASSERT_EQ(Palpa("keygen -o " + Path("a.key")).code, 0);
  EXPECT_EQ(Palpa("keygen -o " + Path("a.key")).code, 2);
}

// palpad (findings 4, 6): outputs checked before the run; the config read bounded.
TEST_F(FileSafety, PalpadRefusesBadOutputsAndConfigsBeforeTheRun) {
  const std::string field = Field();
  std::vector<palpa::trace::TraceSample> samples;
  for (int i = 0; i < 50; ++i) samples.push_back({i * 1e-3, {0.0, 0.0, 0.05}});
  const std::string trace = Write("t.csv", palpa::trace::FormatTrace(samples, "file safety test"));
  const std::string base = "--device sim --field " + field + " --trace " + trace + " --fast ";
  const std::string fifo = Fifo("status.fifo");
  struct Case {
    std::string args, names;
  };
  std::vector<Case> cases = {
      {"--out " + Path("o.csv") + " --status " + fifo, "--status " + fifo + ": is a FIFO"},
      {"--out " + Path("o.csv") + " --record " + dir_.string(), "--record " + dir_.string() + ": is a directory"},
      {"--out " + trace, "--out " + trace + ": is the same file as the input " + trace},
  };
  for (const std::string& device : Devices()) {
    cases.push_back({"--out " + Path("o.csv") + " --summary-json " + device,
                     "--summary-json " + device + ": is a character device"});
  }
  for (const Case& c : cases) {
    const Outcome r = Palpad(base + c.args);
    EXPECT_EQ(r.code, 2) << c.args << "\n" << r.out;
    EXPECT_NE(r.out.find(c.names), std::string::npos) << c.args << "\n" << r.out;
  }
  for (const std::string& device : Devices()) EXPECT_TRUE(IsCharDevice(device)) << device;
  EXPECT_TRUE(IsFifo(fifo));
  EXPECT_NE(Slurp(trace).find("# palpa-trace"), std::string::npos);
  // --out /dev/null still means "no CSV" (a service running for hours).
  const Outcome ok = Palpad(base + "--out /dev/null");
  EXPECT_EQ(ok.code, 0) << ok.out;

  const Outcome zero = Palpad("--config /dev/zero");
  EXPECT_EQ(zero.code, 2) << zero.out;  // was std::bad_alloc, signal 6
  EXPECT_NE(zero.out.find("/dev/zero: is a character device"), std::string::npos) << zero.out;
  const Outcome cfifo = Palpad("--config " + Fifo("c.toml"));
  EXPECT_EQ(cfifo.code, 2) << cfifo.out;
  EXPECT_NE(cfifo.out.find("is a FIFO"), std::string::npos) << cfifo.out;
}

// Finding 8: error messages copied raw bytes (escape sequences, NULs) to the terminal.
TEST_F(FileSafety, MessagesQuoteInputBytesEscaped) {
  const std::string bad = Write("esc.xyz", std::string("0 0 0 0 0 1\n\x1b]0;pwned\x07\0 0 0 0 0 1\n", 31));
  const Outcome r = Palpa("build " + bad + " -o " + Path("o.palpa"));
  EXPECT_EQ(r.code, 2) << r.out;
  EXPECT_EQ(r.out.find('\x1b'), std::string::npos) << r.out;
  EXPECT_EQ(r.out.find('\0'), std::string::npos);
  EXPECT_NE(r.out.find("'\\x1b]0;pwned\\x07\\x00' is not a number"), std::string::npos) << r.out;

  // A 100,000-digit number is quoted as its first 64 digits, by palpa (CLI11) and palpad.
  const std::string digits(100000, '7');
  const Outcome p = Palpa("build " + points_ + " -o " + Path("o.palpa") + " --scale 1 --offset " + digits + "x");
  EXPECT_EQ(p.code, 2) << p.out.size();
  EXPECT_LT(p.out.size(), 1000U);
  EXPECT_NE(p.out.find(std::string(64, '7') + "…"), std::string::npos) << p.out;
  const Outcome k = Palpad("--device sim --field " + Field() + " --k " + digits + "x --out " + Path("o.csv"));
  EXPECT_EQ(k.code, 2) << k.out.size();
  EXPECT_EQ(k.out.find(std::string(65, '7')), std::string::npos) << k.out.size();
  EXPECT_NE(k.out.find("--k: '" + std::string(64, '7') + "…' is not a finite number"), std::string::npos)
      << k.out.substr(0, 300);

  const std::string trace = Write("t.csv", "# palpa-trace v2 units=s,m frame=\x1b[31mred columns=t_s,x_m,y_m,z_m\n");
  const Outcome t = Palpad("--device sim --field " + Field() + " --trace " + trace + " --out " + Path("o.csv"));
  EXPECT_EQ(t.code, 2) << t.out;
  EXPECT_EQ(t.out.find('\x1b'), std::string::npos) << t.out;
  EXPECT_NE(t.out.find("\\x1b[31mred"), std::string::npos) << t.out;
}

}  // namespace
