#include "palpa/hil/timing.h"

#include "palpa/record/latency_histogram.h"

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
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (auto row = record::ParseTimingRow(line)) rows.push_back(*row);
  }
  return rows;
}

Percentiles Figures(std::vector<std::int64_t> ns) {
  Percentiles p;
  std::erase_if(ns, [](std::int64_t v) { return v < 0; });
  if (ns.empty()) return p;
  // The run record's nearest rank (record::PercentileOfSamples), in µs.
  const auto us = [&](double q) { return static_cast<double>(record::PercentileOfSamples(ns, q)) / 1e3; };
  p.count = ns.size();
  p.p50 = us(0.5);
  p.p99 = us(0.99);
  p.p999 = us(0.999);
  p.max = static_cast<double>(*std::max_element(ns.begin(), ns.end())) / 1e3;
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
