// fwref/period.hpp -- scope: how many sample periods a timestamp step d = t - t_prev is, as
// Stream::push decides it (a refusal, one period, or a gap of g > 1), without the double division
// on the common path. On the Cortex-M4 (single-precision FPU) that division is soft-float: about
// 0.6k of the 1.45k instructions a push takes without this gate (docs/firmware.md "Streaming").
//
// The decision is defined by the division (the reference, ``periods_reference``):
//     q = fl(d / dt);  refused when !(q >= 0.5) (NaN included);  otherwise g = llround(q).
// The gate gives the SAME result for every double d (every t, t_prev), by this argument:
//   1. For dt > 0, d -> fl(d / dt) is non-decreasing over the doubles: d / dt is increasing over the
//      reals and IEEE round-to-nearest is monotone (the host's SSE2 division and the Cortex-M's
//      soft-float __aeabi_ddiv are both correctly rounded IEEE binary64).
//   2. So for a double c, {d : fl(d / dt) >= c} is all the doubles from one least element D(c) up.
//      ``least_at_least`` finds D(c) exactly: it evaluates the reference comparison itself, starting
//      from c * dt (within a few ulps of D(c)), and stops at a d where it holds and fails one ulp below.
//   3. lo = D(0.5), hi = D(1.5). For lo <= d < hi: 0.5 <= fl(d / dt) < 1.5 (step 2), so the reference
//      accepts and llround gives 1 (0.5 rounds away from zero to 1; below 1.5 rounds to 1): exactly
//      what ``steps`` returns without dividing. Every other d (d < lo, d >= hi, NaN) takes the
//      reference itself: a refusal, a gap (rare), or a non-finite step.
//   4. If the search does not settle (dt so large or so small that c * dt is not finite, or the
//      start is far off), lo = hi = NaN: every comparison is false and every d takes the reference.
// Computed once per dt (Stream::init). Tested at the edges by tools/fwref_period.cpp (tests/test_stream_period.py).
#pragma once

#include <cmath>
#include <cstdint>

namespace fwref {

// The reference: -1 for a refused step (not at least half a period, or NaN), else llround(d / dt);
// INT64_MAX for 2^62 periods or more (llround's result is unspecified past 2^63, and newlib's
// converts out of range: the stream refuses any step above kMaxGapPeriods anyway).
inline std::int64_t periods_reference(double d, double dt) {
  const double periods = d / dt;
  if (!(periods >= 0.5)) return -1;  // also NaN
  if (!(periods < 0x1p62)) return INT64_MAX;
  return static_cast<std::int64_t>(std::llround(periods));
}

// The least double d with fl(d / dt) >= c, by the reference's own comparison; false if not settled.
inline bool least_at_least(double dt, double c, double& out) {
  double d = c * dt;
  if (!std::isfinite(d)) return false;
  for (int i = 0; i < 64; ++i) {  // a handful of ulps from the start in practice
    if (d / dt >= c) {
      const double below = std::nextafter(d, -INFINITY);
      if (!(below / dt >= c)) {
        out = d;
        return true;
      }
      d = below;
    } else {
      d = std::nextafter(d, INFINITY);
    }
  }
  return false;
}

struct PeriodGate {
  double dt = 1.0;
  double lo = NAN, hi = NAN;  // one period: lo <= d < hi; NaN: no fast path

  void init(double sample_dt) {
    dt = sample_dt;
    double a = 0.0, b = 0.0;
    if (dt > 0.0 && least_at_least(dt, 0.5, a) && least_at_least(dt, 1.5, b) && a < b) {
      lo = a;
      hi = b;
    } else {
      lo = hi = NAN;
    }
  }
  // periods_reference(d, dt) for every d; no division when d is one period.
  std::int64_t steps(double d) const {
    if (d >= lo && d < hi) return 1;
    return periods_reference(d, dt);
  }
};

}  // namespace fwref
