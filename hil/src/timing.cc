#include "palpa/hil/timing.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <string>

namespace palpa::hil {

std::vector<TimingRow> ReadTiming(const std::filesystem::path& p) {
  std::vector<TimingRow> rows;
  std::ifstream in(p);
  std::string line;
  std::getline(in, line);  // header
  while (std::getline(in, line)) {
    unsigned long long tick = 0;
    double t = 0;
    long long w = 0, c = 0, tot = 0;
    unsigned flags = 0;
    if (std::sscanf(line.c_str(), "%llu,%lf,%lld,%lld,%lld,%u", &tick, &t, &w, &c, &tot, &flags) == 6)
      rows.push_back({w, c, tot, flags});
  }
  return rows;
}

Percentiles Figures(std::vector<std::int64_t> ns) {
  Percentiles p;
  std::erase_if(ns, [](std::int64_t v) { return v < 0; });
  if (ns.empty()) return p;
  std::sort(ns.begin(), ns.end());
  auto rank = [&](double q) {  // nearest rank
    const auto r = static_cast<std::size_t>(std::ceil(q * static_cast<double>(ns.size())));
    return static_cast<double>(ns[std::min(ns.size(), std::max<std::size_t>(r, 1)) - 1]) / 1e3;
  };
  p.count = ns.size();
  p.p50 = rank(0.5);
  p.p99 = rank(0.99);
  p.p999 = rank(0.999);
  p.max = static_cast<double>(ns.back()) / 1e3;
  return p;
}

Latency Latency::Of(const std::vector<TimingRow>& rows) {
  Latency l;
  for (const TimingRow& r : rows) {
    l.wake_ns.push_back(r.wake_ns);
    l.compute_ns.push_back(r.compute_ns);
    l.total_ns.push_back(r.total_ns);
  }
  return l;
}

void Latency::Append(const Latency& other) {
  wake_ns.insert(wake_ns.end(), other.wake_ns.begin(), other.wake_ns.end());
  compute_ns.insert(compute_ns.end(), other.compute_ns.begin(), other.compute_ns.end());
  total_ns.insert(total_ns.end(), other.total_ns.begin(), other.total_ns.end());
}

}  // namespace palpa::hil
