// tools/fwref_period.cpp -- scope: holds fwref/period.hpp's PeriodGate (Stream::push's timestamp
// step without a division) to the division it replaces, for tests/test_stream_period.py:
//
//   fwref_period DT [DT ...]        (each a sample period in s, strtod syntax: 0.04, 0x1p-10, inf)
//
// For each DT, one line: "dt=<%a> fast=<0|1> lo=<%a> hi=<%a> tight=<0|1> checked=<n> mismatches=<m>".
// fast: the gate found its one-period bounds; tight: they are the exact edges of the reference (one
// ulp below lo is refused, lo is one period, one ulp below hi is one period, hi is two). The steps d
// checked: both bounds and 4 ulps either side; 0, -0, +-inf, NaN, the smallest and largest doubles;
// 0.5, 1, 1.5, 2, 2.5 periods and 8 ulps either side; steps t - t_prev from timestamps around
// powers of two (where the ulp of t changes), from float32 timestamps k * float(DT), and 2e5
// pseudo-random steps near one period and near both bounds (a fixed xorshift seed). Exit 1 when any
// d differs or a usual period (0 < DT < 1e300, finite) gets no fast path or loose bounds.
#include <cinttypes>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <vector>

#include "fwref/period.hpp"

namespace {

std::uint64_t g_rng = 0x9E3779B97F4A7C15ull;
std::uint64_t next_u64() {
  g_rng ^= g_rng << 13;
  g_rng ^= g_rng >> 7;
  g_rng ^= g_rng << 17;
  return g_rng;
}

double step_ulps(double x, int n) {
  for (int i = 0; i < n; ++i) x = std::nextafter(x, INFINITY);
  for (int i = 0; i > n; --i) x = std::nextafter(x, -INFINITY);
  return x;
}

void around(std::vector<double>& out, double x, int ulps) {
  for (int i = -ulps; i <= ulps; ++i) out.push_back(step_ulps(x, i));
}

std::vector<double> steps_to_check(double dt, const fwref::PeriodGate& g) {
  std::vector<double> d = {0.0, -0.0, INFINITY, -INFINITY, NAN, std::numeric_limits<double>::denorm_min(),
                           -std::numeric_limits<double>::denorm_min(), std::numeric_limits<double>::max(),
                           std::numeric_limits<double>::lowest()};
  if (std::isfinite(g.lo)) around(d, g.lo, 4);
  if (std::isfinite(g.hi)) around(d, g.hi, 4);
  for (double c : {0.5, 1.0, 1.5, 2.0, 2.5, -1.0}) around(d, c * dt, 8);
  for (double base : {1.0, 2.0, 1024.0, 3600.0, 65536.0, 1048576.0}) {  // ulp of t changes at base
    for (double t0 : {step_ulps(base, -3), base, step_ulps(base - dt, 0), step_ulps(base - 0.5 * dt, 0)}) {
      for (double c : {0.5, 1.0, 1.5, 2.5}) {
        for (int u = -3; u <= 3; ++u) d.push_back(step_ulps(t0 + c * dt, u) - t0);
      }
    }
  }
  const float fdt = static_cast<float>(dt);
  for (int k = 0; k < 200000 && std::isfinite(fdt) && fdt > 0.0f; k += 997) {  // float32 timestamps
    const float t0 = static_cast<float>(k) * fdt, t1 = static_cast<float>(k + 1) * fdt;
    for (float t : {t1, std::nextafter(t1, INFINITY), std::nextafter(t1, -INFINITY), t0 + 0.5f * fdt}) {
      d.push_back(double(t) - double(t0));
    }
  }
  for (int i = 0; i < 200000; ++i) {
    const std::uint64_t r = next_u64();
    const double u = double(r >> 11) * 0x1p-53;  // [0, 1)
    if (i % 3 == 0) d.push_back(dt * (0.25 + 1.5 * u));
    else if (std::isfinite(g.lo)) d.push_back(step_ulps(i % 3 == 1 ? g.lo : g.hi, int(r % 41) - 20));
  }
  return d;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) return std::fprintf(stderr, "fwref_period: give one or more sample periods (s)\n"), 2;
  int bad = 0;
  for (int a = 1; a < argc; ++a) {
    char* end = nullptr;
    const double dt = std::strtod(argv[a], &end);
    if (end == argv[a] || *end != '\0' || !(dt > 0.0)) {
      return std::fprintf(stderr, "fwref_period: %s is not a positive period\n", argv[a]), 2;
    }
    fwref::PeriodGate g;
    g.init(dt);
    const bool fast = std::isfinite(g.lo) && std::isfinite(g.hi);
    const bool tight = fast && fwref::periods_reference(std::nextafter(g.lo, -INFINITY), dt) == -1 &&
                       fwref::periods_reference(g.lo, dt) == 1 &&
                       fwref::periods_reference(std::nextafter(g.hi, -INFINITY), dt) == 1 &&
                       fwref::periods_reference(g.hi, dt) == 2;
    const std::vector<double> ds = steps_to_check(dt, g);
    long mismatches = 0;
    for (double d : ds) {
      // the reference's llround is not defined past 2^63 periods (FE_INVALID): both sides call it there
      if (g.steps(d) != fwref::periods_reference(d, dt)) ++mismatches;
    }
    std::printf("dt=%a fast=%d lo=%a hi=%a tight=%d checked=%zu mismatches=%ld\n", dt, int(fast), g.lo, g.hi,
                int(tight), ds.size(), mismatches);
    const bool usual = std::isfinite(dt) && dt < 1e300;
    if (mismatches != 0 || (usual && !(fast && tight))) bad = 1;
  }
  return bad;
}
