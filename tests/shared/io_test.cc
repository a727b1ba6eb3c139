// shared/io (issue 18): output-target checks, bounded readers, escaped quotes. Truths are the
// node types made here (FIFO, directory, /dev/null) and byte strings written out by hand.
#include "palpa/io/file_safety.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

namespace {

namespace fs = std::filesystem;
using palpa::io::CheckOutputTarget;
using palpa::io::Escape;
using palpa::io::Fault;
using palpa::io::LineReader;
using palpa::io::ReadBounded;

fs::path TempDir() {
  const fs::path dir = fs::temp_directory_path() / ("palpa_io_test_" + std::to_string(::getpid()) + "_" +
                                                    ::testing::UnitTest::GetInstance()->current_test_info()->name());
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

void Write(const fs::path& p, const std::string& text) { std::ofstream(p, std::ios::binary) << text; }

TEST(Escape, ControlBytesAndNonUtf8BecomeHexAndLongInputIsCut) {
  EXPECT_EQ(Escape("abc 1.5e3"), "abc 1.5e3");
  EXPECT_EQ(Escape(std::string("\x1b]0;owned\x07", 10)), "\\x1b]0;owned\\x07");
  EXPECT_EQ(Escape(std::string("a\0b", 3)), "a\\x00b");
  EXPECT_EQ(Escape("tab\tnl\ncr\r\\"), "tab\\tnl\\ncr\\r\\\\");
  EXPECT_EQ(Escape("\xff\xfe"), "\\xff\\xfe");
  EXPECT_EQ(Escape("caf\xc3\xa9 \xe2\x80\xa6"), "caf\xc3\xa9 \xe2\x80\xa6");  // café …
  EXPECT_EQ(Escape("\xc2\x9b"), "\\xc2\\x9b");                                // C1 CSI, not passed
  EXPECT_EQ(Escape("\xc3"), "\\xc3");                                         // truncated sequence
  EXPECT_EQ(Escape("\x7f"), "\\x7f");
  const std::string digits(100000, '7');
  const std::string cut = Escape(digits);
  EXPECT_EQ(cut, std::string(64, '7') + "…");
  EXPECT_EQ(Escape("abcdef", 3), "abc…");
  EXPECT_EQ(Escape("ab\xc3\xa9", 3), "ab…");  // never splits a character
}

TEST(CheckOutputTarget, AcceptsNewAndRegularFilesRefusesNodesAndInputs) {
  const fs::path dir = TempDir();
  EXPECT_TRUE(CheckOutputTarget((dir / "new.palpa").string()));
  Write(dir / "old.palpa", "x");
  EXPECT_TRUE(CheckOutputTarget((dir / "old.palpa").string()));

  const auto refused = [](const std::string& path, const char* says) {
    const auto r = CheckOutputTarget(path);
    ASSERT_FALSE(r) << path;
    EXPECT_EQ(r.error().fault, Fault::kBadInput);
    EXPECT_NE(r.error().message.find(path), std::string::npos) << r.error().message;
    EXPECT_NE(r.error().message.find(says), std::string::npos) << r.error().message;
  };
  refused(dir.string(), "a directory");
  refused("/dev/null", "a character device");
  ASSERT_EQ(::mkfifo((dir / "fifo").c_str(), 0600), 0);
  refused((dir / "fifo").string(), "a FIFO");
  fs::create_symlink("/dev/null", dir / "link");
  refused((dir / "link").string(), "a character device");

  Write(dir / "scan.xyz", "0 0 0 0 0 1\n");
  fs::create_hard_link(dir / "scan.xyz", dir / "hard.xyz");
  const std::string inputs[] = {(dir / "other.xyz").string(), (dir / "scan.xyz").string()};
  for (const char* out : {"scan.xyz", "hard.xyz"}) {
    const auto r = CheckOutputTarget((dir / out).string(), inputs);
    ASSERT_FALSE(r) << out;
    EXPECT_NE(r.error().message.find("same file as the input"), std::string::npos) << r.error().message;
  }
  EXPECT_TRUE(CheckOutputTarget((dir / "old.palpa").string(), inputs));
  fs::remove_all(dir);
}

TEST(ReadBounded, RefusesNonRegularFilesAtOnceAndFilesOverTheCap) {
  const fs::path dir = TempDir();
  ASSERT_EQ(::mkfifo((dir / "fifo").c_str(), 0600), 0);
  const auto fifo = ReadBounded((dir / "fifo").string(), 1024, "config file");  // would hang without O_NONBLOCK
  ASSERT_FALSE(fifo);
  EXPECT_NE(fifo.error().message.find("a FIFO"), std::string::npos) << fifo.error().message;
  EXPECT_NE(fifo.error().message.find("config file"), std::string::npos);

  const auto zero = ReadBounded("/dev/zero", 1024, "point file");
  ASSERT_FALSE(zero);
  EXPECT_EQ(zero.error().fault, Fault::kBadInput);
  EXPECT_NE(zero.error().message.find("/dev/zero: is a character device"), std::string::npos) << zero.error().message;

  const auto missing = ReadBounded((dir / "none").string(), 1024, "trace file");
  ASSERT_FALSE(missing);
  EXPECT_NE(missing.error().message.find("No such file"), std::string::npos);

  Write(dir / "big", std::string(2049, 'a'));
  const auto big = ReadBounded((dir / "big").string(), 2048, "key file");
  ASSERT_FALSE(big);
  EXPECT_NE(big.error().message.find("2049 bytes; at most 2 KiB"), std::string::npos) << big.error().message;
  const auto fits = ReadBounded((dir / "big").string(), 2049, "key file");
  ASSERT_TRUE(fits);
  EXPECT_EQ(fits->size(), 2049U);
  fs::remove_all(dir);
}

// A file longer than its size at open (here procfs, which reports 0 bytes: the path a file that
// grows after the open takes) is read past that size, whole, through the end probe; past the
// cap it is refused as "more than" the cap.
TEST(ReadBounded, ReadsPastTheSizeAtOpenUpToTheCap) {
  std::ifstream in("/proc/self/cmdline", std::ios::binary);
  const std::string expected((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_GT(expected.size(), 10U);
  const auto whole = ReadBounded("/proc/self/cmdline", 1 << 20, "command line");
  ASSERT_TRUE(whole) << whole.error().message;
  EXPECT_EQ(std::string(reinterpret_cast<const char*>(whole->data()), whole->size()), expected);
  const auto capped = ReadBounded("/proc/self/cmdline", expected.size() - 1, "command line");
  ASSERT_FALSE(capped);
  // ("holds more than": under qemu-user the guest's /proc/self/cmdline is a copy of known size.)
  EXPECT_NE(capped.error().message.find("; at most"), std::string::npos) << capped.error().message;
}

TEST(LineReader, ReturnsLinesAndRefusesALineOverTheCap) {
  const fs::path dir = TempDir();
  std::string text = "one\n\ntwo\r\n";
  text += std::string(70000, 'x') + "\nlast";  // a line across the 64 KiB buffer, then no '\n'
  Write(dir / "f", text);
  auto r = LineReader::Open((dir / "f").string(), 100000, "point file");
  ASSERT_TRUE(r);
  std::string_view line;
  ASSERT_EQ(r->Next(line), LineReader::Status::kLine);
  EXPECT_EQ(line, "one");
  ASSERT_EQ(r->Next(line), LineReader::Status::kLine);
  EXPECT_EQ(line, "");
  ASSERT_EQ(r->Next(line), LineReader::Status::kLine);
  EXPECT_EQ(line, "two\r");
  ASSERT_EQ(r->Next(line), LineReader::Status::kLine);
  EXPECT_EQ(line.size(), 70000U);
  ASSERT_EQ(r->Next(line), LineReader::Status::kLine);
  EXPECT_EQ(line, "last");
  EXPECT_EQ(r->line_number(), 5U);
  EXPECT_EQ(r->Next(line), LineReader::Status::kEnd);

  auto capped = LineReader::Open((dir / "f").string(), 4096, "point file");
  ASSERT_TRUE(capped);
  for (int i = 0; i < 3; ++i) ASSERT_EQ(capped->Next(line), LineReader::Status::kLine);
  EXPECT_EQ(capped->Next(line), LineReader::Status::kTooLong);
  EXPECT_EQ(capped->line_number(), 4U);

  EXPECT_FALSE(LineReader::Open("/dev/zero", 4096, "point file"));
  fs::remove_all(dir);
}

}  // namespace
