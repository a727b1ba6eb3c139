#include "palpa/io/temp_registry.h"

#include <unistd.h>

#include <atomic>
#include <cstring>

namespace palpa::io {
namespace {

enum SlotState : int { kFree = 0, kFilling = 1, kInUse = 2 };

struct Slot {
  std::atomic<int> state{kFree};
  char path[kTempRegistryPathBytes] = {};
};
static_assert(std::atomic<int>::is_always_lock_free);  // read from signal handlers

Slot g_slots[kTempRegistrySlots];

}  // namespace

int RegisterTempPath(const char* path) noexcept {
  const std::size_t n = std::strlen(path);
  if (n == 0 || n >= static_cast<std::size_t>(kTempRegistryPathBytes)) return -1;
  for (int i = 0; i < kTempRegistrySlots; ++i) {
    int expected = kFree;
    if (!g_slots[i].state.compare_exchange_strong(expected, kFilling, std::memory_order_acq_rel)) continue;
    std::memcpy(g_slots[i].path, path, n + 1);
    g_slots[i].state.store(kInUse, std::memory_order_release);
    return i;
  }
  return -1;
}

void UnregisterTempPath(int slot) noexcept {
  if (slot < 0 || slot >= kTempRegistrySlots) return;
  g_slots[slot].state.store(kFree, std::memory_order_release);
}

int UnlinkRegisteredTempPaths() noexcept {
  int unlinked = 0;
  for (Slot& s : g_slots) {
    if (s.state.load(std::memory_order_acquire) != kInUse) continue;
    if (unlink(s.path) == 0) ++unlinked;
  }
  return unlinked;
}

}  // namespace palpa::io
