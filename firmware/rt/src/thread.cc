#include "palpa/rt/thread.h"

#include <sched.h>

namespace palpa::rt {

HelperThread::~HelperThread() { Join(); }

void* HelperThread::Trampoline(void* self) {
  auto* t = static_cast<HelperThread*>(self);
  t->body_(t->arg_);
  return nullptr;
}

int HelperThread::Start(const char* name, void (*body)(void*), void* arg, int avoid_cpu, std::size_t stack_bytes) {
  if (started_) return 0;
  body_ = body;
  arg_ = arg;
  pthread_attr_t attr;
  if (const int err = pthread_attr_init(&attr); err != 0) return err;
  int err = pthread_attr_setstacksize(&attr, stack_bytes);
  if (err == 0) err = pthread_attr_setinheritsched(&attr, PTHREAD_EXPLICIT_SCHED);
  if (err == 0) err = pthread_attr_setschedpolicy(&attr, SCHED_OTHER);
  sched_param param{};
  if (err == 0) err = pthread_attr_setschedparam(&attr, &param);
  cpu_set_t cpus;
  CPU_ZERO(&cpus);
  if (err == 0 && avoid_cpu >= 0 && avoid_cpu < CPU_SETSIZE && sched_getaffinity(0, sizeof cpus, &cpus) == 0) {
    CPU_CLR(static_cast<std::size_t>(avoid_cpu), &cpus);
    if (CPU_COUNT(&cpus) > 0) err = pthread_attr_setaffinity_np(&attr, sizeof cpus, &cpus);
  }
  if (err == 0) err = pthread_create(&thread_, &attr, &HelperThread::Trampoline, this);
  pthread_attr_destroy(&attr);
  if (err != 0) return err;
  started_ = true;
  (void)pthread_setname_np(thread_, name);  // cosmetic
  return 0;
}

void HelperThread::Join() {
  if (!started_) return;
  pthread_join(thread_, nullptr);
  started_ = false;
}

}  // namespace palpa::rt
