// The one atomic-file writer (shared/io, issue 21), which every output of palpa and palpad goes
// through: an output replaces its target only on Commit, an abandoned one leaves the target and
// no temporary, refused targets are left as they were, and the temporary is in the registry a
// fatal-signal handler empties. (Moved here from tests/cli/atomic_output_test.cc and
// tests/firmware/report_test.cc, which tested the two writers it replaced.)
#include "palpa/io/atomic_file.h"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstddef>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <span>
#include <string>

#include "palpa/io/temp_registry.h"

namespace palpa::io {
namespace {

namespace fs = std::filesystem;

class AtomicFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("palpa_atomic_" + std::to_string(::getpid()) + "_" +
                                        ::testing::UnitTest::GetInstance()->current_test_info()->name());
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

TEST_F(AtomicFileTest, PiecesReplaceTheTargetOnlyOnCommit) {
  const std::string target = Path("out.bin");
  std::ofstream(target) << "old";
  auto out = AtomicFile::Create(target);
  ASSERT_TRUE(out) << out.error();
  EXPECT_EQ(out->temp_path().rfind(target + ".tmp.", 0), 0u) << out->temp_path();  // in the target's directory
  ASSERT_TRUE(out->Append(Bytes("first ")));
  std::fputs("second ", out->file());  // stdio and Append write one stream, in order
  ASSERT_TRUE(out->Append(Bytes("third")));
  EXPECT_EQ(Read(target), "old");  // a reader sees the old file until the commit
  EXPECT_EQ(Entries(), 2u);        // the target and the temporary
  ASSERT_TRUE(out->Commit());
  EXPECT_EQ(Read(target), "first second third");
  EXPECT_EQ(Entries(), 1u);
  EXPECT_TRUE(out->temp_path().empty());
  EXPECT_FALSE(out->Append(Bytes("late")));  // nothing after the commit
  EXPECT_FALSE(out->Commit());
  EXPECT_EQ(Read(target), "first second third");
}

TEST_F(AtomicFileTest, ANewTargetIsCreatedWithTheModeLessTheUmask) {
  const mode_t mask = ::umask(022);
  ASSERT_TRUE(WriteFileAtomically(Path("plain"), Bytes("x")));
  ASSERT_TRUE(WriteFileAtomically(Path("key"), Bytes("k"), {.mode = 0600}));
  ::umask(mask);
  struct stat st {};
  ASSERT_EQ(::stat(Path("plain").c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0644u);
  ASSERT_EQ(::stat(Path("key").c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0600u);
}

TEST_F(AtomicFileTest, AnAbandonedOutputLeavesTheTargetAndNoTemporary) {
  const std::string target = Path("out.bin");
  std::ofstream(target) << "old";
  {
    auto out = AtomicFile::Create(target);
    ASSERT_TRUE(out) << out.error();
    ASSERT_TRUE(out->Append(Bytes("half of it")));
    std::fflush(out->file());
    EXPECT_EQ(Read(out->temp_path()), "half of it");
  }  // destroyed uncommitted
  EXPECT_EQ(Read(target), "old");
  EXPECT_EQ(Entries(), 1u);
  {
    auto moved_from = AtomicFile::Create(Path("new.bin"));
    ASSERT_TRUE(moved_from) << moved_from.error();
    AtomicFile owner(std::move(*moved_from));
  }
  EXPECT_EQ(Entries(), 1u) << "a new target never appears uncommitted";
}

TEST_F(AtomicFileTest, AFifoADirectoryOrAnInputIsRefusedBeforeAnyWrite) {
  const std::string fifo = Path("fifo");
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  const auto f = AtomicFile::Create(fifo);
  ASSERT_FALSE(f);
  EXPECT_NE(f.error().find(fifo + ": is a FIFO"), std::string::npos) << f.error();
  EXPECT_FALSE(WriteFileAtomically(fifo, Bytes("x")));
  struct stat st {};
  ASSERT_EQ(::lstat(fifo.c_str(), &st), 0);
  EXPECT_TRUE(S_ISFIFO(st.st_mode)) << "the FIFO is left as it was";

  const auto dir = AtomicFile::Create(dir_.string());
  ASSERT_FALSE(dir);
  EXPECT_NE(dir.error().find(dir_.string() + ": is a directory"), std::string::npos) << dir.error();

  const std::string input = Path("in.palpa");
  std::ofstream(input) << "input";
  const auto same = AtomicFile::Create(input, {.inputs = {input}});
  ASSERT_FALSE(same);
  EXPECT_NE(same.error().find("is the same file as the input"), std::string::npos) << same.error();
  EXPECT_EQ(Read(input), "input");
  EXPECT_EQ(Entries(), 2u);  // the FIFO and the input: no temporary
}

TEST_F(AtomicFileTest, ATargetThatBecomesAFifoBeforeTheCommitIsLeftAlone) {
  const std::string target = Path("late.fifo");
  auto out = AtomicFile::Create(target);
  ASSERT_TRUE(out) << out.error();
  ASSERT_TRUE(out->Append(Bytes("data")));
  ASSERT_EQ(::mkfifo(target.c_str(), 0600), 0);
  const auto committed = out->Commit();
  ASSERT_FALSE(committed);
  EXPECT_NE(committed.error().find("is a FIFO"), std::string::npos) << committed.error();
  struct stat st {};
  ASSERT_EQ(::lstat(target.c_str(), &st), 0);
  EXPECT_TRUE(S_ISFIFO(st.st_mode));
  EXPECT_EQ(Entries(), 1u) << "the temporary is removed";
}

TEST_F(AtomicFileTest, AMissingDirectoryFailsNamingThePath) {
  const std::string target = Path("missing/out.csv");
  const auto f = AtomicFile::Create(target);
  ASSERT_FALSE(f);
  EXPECT_NE(f.error().find(target + ": cannot create a temporary file in " + Path("missing")), std::string::npos)
      << f.error();
}

TEST_F(AtomicFileTest, TheStreamReadsBackWhatWasWritten) {
  auto out = AtomicFile::Create(Path("trace.ptb"));
  ASSERT_TRUE(out) << out.error();
  std::fputs("abc", out->file());
  ASSERT_EQ(std::fseek(out->file(), 0, SEEK_SET), 0);
  char back[4] = {};
  ASSERT_EQ(std::fread(back, 1, 3, out->file()), 3u);
  EXPECT_STREQ(back, "abc");
  ASSERT_EQ(std::fseek(out->file(), 0, SEEK_END), 0);
  std::fputs("d", out->file());
  ASSERT_TRUE(out->Commit());
  EXPECT_EQ(Read(Path("trace.ptb")), "abcd");
}

TEST_F(AtomicFileTest, ANotDurableOutputIsStillReplacedAtomically) {
  const std::string target = Path("status.json");
  for (const char* text : {"{\"state\": \"running\"}\n", "{\"state\": \"ended\"}\n"}) {
    ASSERT_TRUE(WriteFileAtomically(target, Bytes(text), {.durable = false}));
    EXPECT_EQ(Read(target), text);
  }
  EXPECT_EQ(Entries(), 1u);
}

// palpad's fatal-signal handler calls UnlinkRegisteredTempPaths (firmware/palpad/src/signals.cc):
// every temporary that exists is registered, and none that was committed or abandoned.
TEST_F(AtomicFileTest, TheFatalSignalPathRemovesEveryOpenTemporaryAndOnlyThose) {
  auto committed = AtomicFile::Create(Path("committed"));
  auto open1 = AtomicFile::Create(Path("open1"));
  auto open2 = AtomicFile::Create(Path("open2"));
  ASSERT_TRUE(committed && open1 && open2);
  ASSERT_TRUE(committed->Commit());
  {
    auto abandoned = AtomicFile::Create(Path("abandoned"));
    ASSERT_TRUE(abandoned);
  }
  const std::string t1 = open1->temp_path(), t2 = open2->temp_path();
  ASSERT_TRUE(fs::exists(t1) && fs::exists(t2));
  EXPECT_EQ(UnlinkRegisteredTempPaths(), 2);
  EXPECT_FALSE(fs::exists(t1));
  EXPECT_FALSE(fs::exists(t2));
  EXPECT_TRUE(fs::exists(Path("committed")));
  EXPECT_FALSE(open1->Commit()) << "its temporary is gone";
  EXPECT_FALSE(fs::exists(Path("open1")));
}

TEST(TempRegistry, SlotsAreReusedAndTooLongPathsAreNotKept) {
  const std::string too_long(kTempRegistryPathBytes, 'x');
  EXPECT_EQ(RegisterTempPath(too_long.c_str()), -1);
  EXPECT_EQ(RegisterTempPath(""), -1);
  int slots[kTempRegistrySlots];
  for (int& s : slots) {
    s = RegisterTempPath("/nonexistent-palpa-dir/t.tmp.AAAAAA");
    ASSERT_GE(s, 0);
  }
  EXPECT_EQ(RegisterTempPath("/nonexistent-palpa-dir/one-more"), -1) << "every slot is taken";
  for (const int s : slots) UnregisterTempPath(s);
  const int again = RegisterTempPath("/nonexistent-palpa-dir/again");
  EXPECT_GE(again, 0);
  UnregisterTempPath(again);
  UnregisterTempPath(-1);  // no-op
  EXPECT_EQ(UnlinkRegisteredTempPaths(), 0);
}

}  // namespace
}  // namespace palpa::io
