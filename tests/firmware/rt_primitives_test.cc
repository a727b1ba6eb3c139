// The real-time building blocks: the SPSC ring (order, exact capacity, drop counting, a
// concurrent producer/consumer), the fixed histograms (against hand-computed percentiles and a
// sort of the raw values), and the RT set-up's reporting — every refusal provoked through the
// syscall seam, then the real system calls in child processes (an invalid CPU; a dropped
// capability).

#include <gtest/gtest.h>
#include <linux/capability.h>
#include <sched.h>
#include <sys/resource.h>
#include <sys/syscall.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "palpa/rt/histogram.h"
#include "palpa/rt/realtime.h"
#include "palpa/rt/spsc_ring.h"

namespace palpa::rt {
namespace {

bool Has(const std::string& text, const std::string& part) { return text.find(part) != std::string::npos; }

// ---------------------------------------------------------------- SPSC ring

using IntRing = SpscRing<std::uint64_t, OnFull::kDropNewest>;

TEST(SpscRing, KeepsOrderAndExactCapacityAndCountsDrops) {
  IntRing ring(5);  // not a power of two: slot = counter mod 5
  EXPECT_EQ(ring.capacity(), 5u);
  for (std::uint64_t i = 0; i < 8; ++i) EXPECT_EQ(ring.Push(i), i < 5) << i;
  EXPECT_EQ(ring.size(), 5u);
  EXPECT_EQ(ring.dropped(), 3u);  // 5, 6, 7: the newest are dropped, the queued kept
  EXPECT_EQ(ring.pushed(), 5u);
  std::vector<std::uint64_t> seen;
  ring.ForEachQueued([&](std::uint64_t v) { seen.push_back(v); });
  EXPECT_EQ(seen, (std::vector<std::uint64_t>{0, 1, 2, 3, 4}));
  std::uint64_t v = 0;
  ASSERT_TRUE(ring.Pop(v));
  EXPECT_EQ(v, 0u);
  EXPECT_TRUE(ring.TryPush(100));  // room for exactly one
  EXPECT_FALSE(ring.TryPush(101));
  EXPECT_EQ(ring.dropped(), 3u) << "TryPush does not count";
  for (const std::uint64_t want : {1u, 2u, 3u, 4u, 100u}) {
    ASSERT_TRUE(ring.Pop(v));
    EXPECT_EQ(v, want);
  }
  EXPECT_FALSE(ring.Pop(v));
  EXPECT_EQ(ring.size(), 0u);
}

TEST(SpscRing, WrapsManyTimes) {
  IntRing ring(3);
  std::uint64_t v = 0;
  for (std::uint64_t i = 0; i < 1000; ++i) {
    ASSERT_TRUE(ring.Push(i));
    ASSERT_TRUE(ring.Pop(v));
    ASSERT_EQ(v, i);
  }
}

// A producer thread pushes 0, 1, 2, … (dropping when full) while the consumer pops: the consumer
// must see a strictly increasing sequence, and popped + dropped must equal everything pushed.
TEST(SpscRing, ConcurrentProducerAndConsumerLoseNothingUncounted) {
  constexpr std::uint64_t kCount = 100'000;
  IntRing ring(64);
  std::atomic<bool> done{false};
  std::thread producer([&] {
    for (std::uint64_t i = 0; i < kCount; ++i) (void)ring.Push(i);
    done.store(true, std::memory_order_release);
  });
  std::uint64_t popped = 0, last = 0, v = 0;
  bool first = true, increasing = true;
  for (;;) {
    if (ring.Pop(v)) {
      increasing = increasing && (first || v > last);
      first = false;
      last = v;
      ++popped;
    } else if (done.load(std::memory_order_acquire) && ring.size() == 0) {
      break;
    }
  }
  producer.join();
  while (ring.Pop(v)) ++popped;
  EXPECT_TRUE(increasing);
  EXPECT_EQ(popped + ring.dropped(), kCount);
  EXPECT_GE(popped, 64u) << "at least what the ring held when the producer finished";
  std::printf("[ measured ] %llu popped, %llu dropped of %llu\n", static_cast<unsigned long long>(popped),
              static_cast<unsigned long long>(ring.dropped()), static_cast<unsigned long long>(kCount));
}

TEST(SpscRing, WaitingProducerLosesNothing) {
  constexpr std::uint64_t kCount = 20'000;
  IntRing ring(16);
  std::thread producer([&] {
    for (std::uint64_t i = 0; i < kCount; ++i)
      while (!ring.TryPush(i)) std::this_thread::yield();
  });
  std::uint64_t next = 0, v = 0;
  while (next < kCount) {
    if (ring.Pop(v)) {
      ASSERT_EQ(v, next++);
    } else {
      std::this_thread::yield();  // both sides yield: under qemu-user the two may share a core
    }
  }
  producer.join();
  EXPECT_EQ(ring.dropped(), 0u);
}

// ---------------------------------------------------------------- histograms

TEST(LinearHistogram, HandComputedPercentiles) {
  LinearHistogram<1000, 100> h;  // 1 µs bins to 100 µs
  // 100 values: 1..100 µs + 500 ns each → bin i holds value i.5 µs.
  for (int i = 0; i < 99; ++i) h.Add(i * 1000 + 500);
  h.Add(250'000);  // the 100th: beyond the range → overflow
  EXPECT_EQ(h.count(), 100u);
  EXPECT_EQ(h.overflow(), 1u);
  EXPECT_EQ(h.min_ns(), 500);
  EXPECT_EQ(h.max_ns(), 250'000);
  // Nearest rank: p50 is the 50th value (49.5 µs → bin 49 → 49 000 ns), p99 the 99th (98.5 µs).
  EXPECT_EQ(h.PercentileNs(0.50), 49'000);
  EXPECT_EQ(h.PercentileNs(0.99), 98'000);
  EXPECT_EQ(h.PercentileNs(0.995), 250'000) << "rank 100 is in the overflow: the exact max";
  EXPECT_EQ(h.PercentileNs(0.0), 0);
  EXPECT_DOUBLE_EQ(h.mean_ns(), (99.0 * 49.0 * 1000 + 99 * 500 + 250'000) / 100.0);
}

TEST(LinearHistogram, AgreesWithSortingTheRawValuesTruncatedToBins) {
  std::mt19937_64 rng(9);
  std::lognormal_distribution<double> dist(std::log(40e3), 0.8);  // ~40 µs typical, long tail
  LinearHistogram<1000, 20000> h;
  std::vector<std::int64_t> raw;
  for (int i = 0; i < 20000; ++i) {
    const auto v = static_cast<std::int64_t>(dist(rng));
    raw.push_back(v);
    h.Add(v);
  }
  std::sort(raw.begin(), raw.end());
  for (const double q : {0.5, 0.9, 0.99, 0.999}) {
    const auto rank = static_cast<std::size_t>(std::ceil(q * static_cast<double>(raw.size())));
    const std::int64_t exact = raw[rank - 1];
    const std::int64_t want = exact >= 20'000'000 ? raw.back() : exact / 1000 * 1000;
    EXPECT_EQ(h.PercentileNs(q), want) << q;
  }
  EXPECT_EQ(h.max_ns(), raw.back());
}

TEST(LinearHistogram, NegativeValuesCountInTheFirstBin) {
  LinearHistogram<10, 4> h;
  h.Add(-5);
  EXPECT_EQ(h.bins()[0], 1u);
  EXPECT_EQ(h.min_ns(), 0);
}

// ---------------------------------------------------------------- RT set-up through the seam

// Fake system calls: each refuses with the errno in `g_refuse[step]` (0: succeeds) and records
// the order of the calls.
int g_refuse[kRtStepCount] = {};
std::string g_calls;
int g_closed_fd = -1;
int g_last_cpu = -2, g_last_priority = -2;

int FakeLock() {
  g_calls += "lock,";
  return g_refuse[0];
}
int FakeAffinity(int cpu) {
  g_calls += "affinity,";
  g_last_cpu = cpu;
  return g_refuse[2];
}
int FakeFifo(int priority) {
  g_calls += "fifo,";
  g_last_priority = priority;
  return g_refuse[3];
}
int FakePmQos(std::int32_t) {
  g_calls += "pmqos,";
  return g_refuse[4] != 0 ? -g_refuse[4] : 42;
}
void FakeClosePmQos(int fd) { g_closed_fd = fd; }
int FakeName(const char*) {
  g_calls += "name,";
  return g_refuse[5];
}
constexpr RtSyscalls kFake = {FakeLock, FakeAffinity, FakeFifo, FakePmQos, FakeClosePmQos, FakeName};

void ResetFake() {
  std::fill(std::begin(g_refuse), std::end(g_refuse), 0);
  g_calls.clear();
  g_closed_fd = -1;
  g_last_cpu = g_last_priority = -2;
}

TEST(RtSetup, AllStepsGrantedIsRealtimeAndSilentInOrder) {
  ResetFake();
  {
    RtRequest r;
    r.cpu = 1;
    r.priority = 80;
    const RtSetup s = PrepareRealtimeThread(r, kFake);
    EXPECT_TRUE(s.realtime());
    EXPECT_EQ(s.Refused(), "");
    EXPECT_EQ(s.Warnings("palpad"), "");
    EXPECT_EQ(g_calls, "lock,affinity,fifo,pmqos,name,");  // mlockall first, the name last
    EXPECT_EQ(g_last_cpu, 1);
    EXPECT_EQ(g_last_priority, 80);
    EXPECT_EQ(g_closed_fd, -1) << "the cpu_dma_latency request holds while the set-up lives";
  }
  EXPECT_EQ(g_closed_fd, 42) << "and is released with it";
}

TEST(RtSetup, NoCpuRequestedIsNotARefusal) {
  ResetFake();
  const RtSetup s = PrepareRealtimeThread(RtRequest{}, kFake);
  EXPECT_TRUE(s.realtime());
  EXPECT_FALSE(s.step(RtStep::kAffinity).requested);
  EXPECT_EQ(g_calls, "lock,fifo,pmqos,name,");
}

TEST(RtSetup, EachRefusalIsOneLoudLineAndMarksTheRunNotRealtime) {
  struct Case {
    RtStep step;
    int error;
    const char* words;  // in the warning
  };
  const Case cases[] = {
      {RtStep::kMemoryLock, ENOMEM, "memory lock refused: Cannot allocate memory"},
      {RtStep::kAffinity, EINVAL, "CPU affinity (CPU 7) refused: Invalid argument"},
      {RtStep::kFifo, EPERM, "SCHED_FIFO (priority 80) refused: Operation not permitted"},
      {RtStep::kPmQos, EACCES, "cpu_dma_latency refused: Permission denied"},
      {RtStep::kThreadName, ERANGE, "thread name refused"},
  };
  for (const Case& c : cases) {
    ResetFake();
    g_refuse[static_cast<std::size_t>(c.step)] = c.error;
    RtRequest r;
    r.cpu = 7;
    const RtSetup s = PrepareRealtimeThread(r, kFake);
    EXPECT_FALSE(s.realtime()) << RtStepName(c.step);
    const std::string w = s.Warnings("palpad");
    EXPECT_EQ(std::count(w.begin(), w.end(), '\n'), 1) << w;
    EXPECT_TRUE(w.starts_with("palpad: WARNING: NOT REAL-TIME: ")) << w;
    EXPECT_TRUE(Has(w, c.words)) << w;
    EXPECT_TRUE(Has(s.Refused(), RtStepName(c.step))) << s.Refused();
    EXPECT_EQ(g_calls, "lock,affinity,fifo,pmqos,name,") << "every step is tried even after a refusal";
  }
}

TEST(RtSetup, SeveralRefusalsAreAllListed) {
  ResetFake();
  g_refuse[0] = EPERM;
  g_refuse[3] = EPERM;
  const RtSetup s = PrepareRealtimeThread(RtRequest{}, kFake);
  EXPECT_FALSE(s.realtime());
  EXPECT_EQ(s.Refused(), "memory lock: Operation not permitted; SCHED_FIFO (priority 80): Operation not permitted");
  const std::string w = s.Warnings("x");
  EXPECT_EQ(std::count(w.begin(), w.end(), '\n'), 2) << w;
}

TEST(RtSetup, BuffersArePrefaultedAndPriorityIsChecked) {
  ResetFake();
  std::vector<std::byte> a(3 * 4096 + 5), b(10);
  const std::span<const std::byte> spans[] = {a, b};
  RtRequest r;
  r.buffers = spans;
  r.priority = 0;  // out of range: refused without calling the system
  const RtSetup s = PrepareRealtimeThread(r, kFake);
  EXPECT_TRUE(s.step(RtStep::kPrefault).ok);
  EXPECT_FALSE(s.step(RtStep::kFifo).ok);
  EXPECT_EQ(s.step(RtStep::kFifo).error, EINVAL);
  EXPECT_EQ(g_calls, "lock,pmqos,name,");
}

// ---------------------------------------------------------------- the real system calls

// Runs `body` in a child process (the set-up changes the whole process: memory lock, scheduling)
// and returns what it wrote to the pipe.
template <typename Body>
std::string InChild(Body body) {
  int fds[2];
  if (pipe(fds) != 0) return "pipe failed";
  const pid_t pid = fork();
  if (pid == 0) {
    close(fds[0]);
    const std::string out = body();
    (void)!write(fds[1], out.data(), out.size());
    _exit(0);
  }
  close(fds[1]);
  std::string out;
  char buf[512];
  ssize_t n = 0;
  while ((n = read(fds[0], buf, sizeof buf)) > 0) out.append(buf, static_cast<std::size_t>(n));
  close(fds[0]);
  int status = 0;
  waitpid(pid, &status, 0);
  return out;
}

TEST(RtSetupReal, AnInvalidCpuIsRefusedByTheKernel) {
  const std::string out = InChild([] {
    RtRequest r;
    r.cpu = 1023;  // no machine palpa builds for has 1024 CPUs
    r.pm_qos = false;
    const RtSetup s = PrepareRealtimeThread(r);
    return std::string(s.realtime() ? "realtime" : "not-realtime") + "|" + s.Warnings("palpad");
  });
  std::printf("[ child ] %s", out.c_str());
  EXPECT_TRUE(out.starts_with("not-realtime|")) << out;
  EXPECT_TRUE(Has(out, "CPU affinity (CPU 1023) refused: Invalid argument")) << out;
}

// Drops CAP_SYS_NICE and CAP_IPC_LOCK (raw capset: no libcap needed) and sets RLIMIT_RTPRIO = 0
// and a 64 KiB RLIMIT_MEMLOCK: as an unprivileged service would run without palpad.service's limits.
bool DropRtPrivileges() {
  __user_cap_header_struct header{_LINUX_CAPABILITY_VERSION_3, 0};
  __user_cap_data_struct data[2] = {};
  if (syscall(SYS_capget, &header, data) != 0) return false;
  for (const int cap : {CAP_SYS_NICE, CAP_IPC_LOCK}) {
    data[cap / 32].effective &= ~(1u << (cap % 32));
    data[cap / 32].permitted &= ~(1u << (cap % 32));
  }
  if (syscall(SYS_capset, &header, data) != 0) return false;
  const rlimit rtprio{0, 0};
  const rlimit memlock{64 * 1024, 64 * 1024};
  return setrlimit(RLIMIT_RTPRIO, &rtprio) == 0 && setrlimit(RLIMIT_MEMLOCK, &memlock) == 0;
}

TEST(RtSetupReal, WithoutTheCapabilitiesFifoAndTheMemoryLockAreRefusedLoudly) {
  const std::string out = InChild([] {
    if (!DropRtPrivileges()) return std::string("cannot drop: ") + std::strerror(errno);
    std::vector<std::byte> big(1 << 20, std::byte{1});  // more than the 64 KiB lock limit
    const std::span<const std::byte> spans[] = {big};
    RtRequest r;
    r.buffers = spans;
    r.pm_qos = false;
    const RtSetup s = PrepareRealtimeThread(r);
    return std::string(s.realtime() ? "realtime" : "not-realtime") + "|" + s.Warnings("palpad");
  });
  std::printf("[ child ] %s", out.c_str());
  ASSERT_FALSE(out.starts_with("cannot drop")) << out;
  EXPECT_TRUE(out.starts_with("not-realtime|")) << out;
  EXPECT_TRUE(Has(out, "SCHED_FIFO (priority 80) refused: Operation not permitted")) << out;
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  // The sanitizers' runtimes intercept mlockall and make it a no-op that succeeds.
  std::printf("[ note ] sanitizer build: mlockall is intercepted, its refusal is not checked\n");
#else
  EXPECT_TRUE(Has(out, "memory lock refused")) << out;
#endif
}

}  // namespace
}  // namespace palpa::rt
