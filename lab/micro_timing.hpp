// lab/micro_timing.hpp -- scope: what the micro-benchmarks in lab/*_micro.cpp share (one place for it): the timing
// loop (200 warm-up calls, then the median of 2,000 timed calls of f, in ns per call), the paper CNODE field's shape
// (64 x 40 and 40 x 64, 4N = 32 evaluations per window) and the int8 benchmarks' random field (weights and scales
// that keep the state in the codes' range; the same draw for every int8 benchmark, so their figures compare).
#pragma once

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <random>
#include <utility>
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

constexpr int kH = 64, kL = 40, kE = 32;  // field hidden width, latent size, evaluations per window (N = 8)

// Median ns per field evaluation of f, one window's serial chain of kE evaluations.
template <class F>
double per_eval_ns(F f) {
  return median_call_ns(f) / kE;
}

// Two ways of one computation timed in `rounds` interleaved rounds (a shared machine's slow phases hit both
// alike): the medians of the rounds' per-evaluation figures, first a's, then b's.
template <class A, class B>
std::pair<double, double> interleaved_per_eval_ns(A a, B b, int rounds = 9) {
  std::vector<double> ta, tb;
  for (int r = 0; r < rounds; ++r) ta.push_back(per_eval_ns(a)), tb.push_back(per_eval_ns(b));
  std::sort(ta.begin(), ta.end());
  std::sort(tb.begin(), tb.end());
  return {ta[ta.size() / 2], tb[tb.size() / 2]};
}

// The int8 benchmarks' field: int8 weights of lin1_z (kH x kL) and lin2 (kL x kH), their per-row scales, the
// row of V, lin2's bias and folded multipliers, the stage scales and a starting state z, from one seeded draw.
struct I8Field {
  std::vector<std::int8_t> q1 = std::vector<std::int8_t>(kH * kL), q2 = std::vector<std::int8_t>(kL * kH);
  float s_w1[kH], s_w2[kH], mult2[kL], b2[kL], v[kH], s_z[kE], s_hid = 1.0f / 127.0f;
  alignas(64) float z[64] = {}, k[64] = {};  // the state and the field's output (fed back as the next state)
  alignas(64) std::int32_t acc[64];           // a product's accumulators

  I8Field() {
    std::mt19937 rng(1);
    std::uniform_int_distribution<int> wd(-127, 127);
    std::normal_distribution<float> nd(0.0f, 1.0f);
    for (auto& q : q1) q = static_cast<std::int8_t>(wd(rng));
    for (auto& q : q2) q = static_cast<std::int8_t>(wd(rng));
    for (int i = 0; i < kH; ++i) s_w1[i] = 0.01f / 127.0f, v[i] = 0.3f * nd(rng);
    for (int i = 0; i < kL; ++i) s_w2[i] = 0.02f / 127.0f, mult2[i] = s_hid * s_w2[i], b2[i] = 0.1f * nd(rng);
    for (int e = 0; e < kE; ++e) s_z[e] = 2.0f / 127.0f;
    for (int i = 0; i < kL; ++i) z[i] = nd(rng);
  }
};
