// AtomicOutput (host/cli/src/atomic_file.h): an output written in pieces replaces its target only
// on Commit, and leaves nothing behind when abandoned (issue 21: palpa export and palpa mesh
// stream outputs larger than memory should hold through it).
#include <gtest/gtest.h>

#include <unistd.h>

#include <cstddef>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <span>
#include <string>
#include <vector>

#include "atomic_file.h"

namespace palpa::cli {
namespace {

namespace fs = std::filesystem;

class AtomicOutputTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("palpa-atomic-" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Path(const std::string& leaf) const { return (dir_ / leaf).string(); }
  static std::string Read(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  }
  std::size_t Entries() const {
    return static_cast<std::size_t>(std::distance(fs::directory_iterator(dir_), fs::directory_iterator()));
  }
  fs::path dir_;
};

std::span<const std::byte> Bytes(const std::string& s) { return std::as_bytes(std::span(s.data(), s.size())); }

TEST_F(AtomicOutputTest, PiecesReplaceTheTargetOnlyOnCommit) {
  const std::string target = Path("out.bin");
  std::ofstream(target) << "old";
  auto out = AtomicOutput::Create(target);
  ASSERT_TRUE(out) << out.error();
  ASSERT_TRUE(out->Append(Bytes("first ")));
  ASSERT_TRUE(out->Append(Bytes("second")));
  EXPECT_EQ(Read(target), "old");  // a reader sees the old file until the commit
  EXPECT_EQ(Entries(), 2u);        // the target and the temporary
  ASSERT_TRUE(out->Commit());
  EXPECT_EQ(Read(target), "first second");
  EXPECT_EQ(Entries(), 1u);
  EXPECT_FALSE(out->Append(Bytes("late")));  // nothing after the commit
}

TEST_F(AtomicOutputTest, AnAbandonedOutputLeavesTheTargetAndNoTemporary) {
  const std::string target = Path("out.bin");
  std::ofstream(target) << "old";
  {
    auto out = AtomicOutput::Create(target);
    ASSERT_TRUE(out) << out.error();
    ASSERT_TRUE(out->Append(Bytes("half of it")));
  }
  EXPECT_EQ(Read(target), "old");
  EXPECT_EQ(Entries(), 1u);
}

TEST_F(AtomicOutputTest, ADirectoryOrAnInputIsRefusedBeforeAnyWrite) {
  const auto dir = AtomicOutput::Create(dir_.string());
  ASSERT_FALSE(dir);
  EXPECT_NE(dir.error().find(dir_.string()), std::string::npos) << dir.error();
  const std::string input = Path("in.palpa");
  std::ofstream(input) << "input";
  EXPECT_FALSE(AtomicOutput::Create(input, {input}));
  EXPECT_EQ(Read(input), "input");
  EXPECT_EQ(Entries(), 1u);
}

}  // namespace
}  // namespace palpa::cli
