// Running a command-line tool from a test, as a user would: through the shell, with stdout and
// stderr captured together, and per-test scratch directories. Header-only; link
// palpa_test_process (tests/support/CMakeLists.txt) for the include path.
#pragma once

#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

namespace palpa::test_support {

/// What a command did: its exit code (-1 if it did not exit normally) and its output.
struct Outcome {
  int code = -1;
  std::string out;  ///< stdout and stderr together
};

/// Runs `command` through /bin/sh with stderr joined to stdout, and waits for it.
inline Outcome Run(const std::string& command) {
  Outcome r;
  std::FILE* p = ::popen((command + " 2>&1").c_str(), "r");
  if (p == nullptr) return r;
  std::array<char, 4096> buf;
  std::size_t n = 0;
  while ((n = std::fread(buf.data(), 1, buf.size(), p)) > 0) r.out.append(buf.data(), n);
  const int status = ::pclose(p);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

/// A fixture with a scratch directory per test (palpa-SUITE-PID-TEST under the system temp
/// directory), removed afterwards.
class TempDirTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = std::filesystem::temp_directory_path() /
           ("palpa-" + std::string(info->test_suite_name()) + "-" + std::to_string(::getpid()) + "-" + info->name());
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string Path(const std::string& leaf) const { return (dir_ / leaf).string(); }
  std::string Write(const std::string& leaf, const std::string& text) const {
    std::ofstream(Path(leaf), std::ios::binary) << text;
    return Path(leaf);
  }
  std::filesystem::path dir_;
};

}  // namespace palpa::test_support
