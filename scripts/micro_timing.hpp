// scripts/micro_timing.hpp -- scope: the timing loop of the micro-benchmarks in scripts/*_micro.cpp
// (one place for it): 200 warm-up calls, then the median of 2,000 timed calls of f, in ns per call.
#pragma once

#include <algorithm>
#include <chrono>
#include <vector>

template <class F>
double median_call_ns(F f) {
  std::vector<double> t;
  for (int r = 0; r < 200; ++r) f();
  for (int r = 0; r < 2000; ++r) {
    const auto a = std::chrono::steady_clock::now();
    f();
    t.push_back(std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - a).count());
  }
  std::sort(t.begin(), t.end());
  return t[t.size() / 2];
}
