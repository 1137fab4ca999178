// lab/gemv_f32_micro.cpp -- the fp32 host kernels' parts timed alone (docs/firmware.md, "Host
// kernels"): the GRU's 240 x 80 recurrent product from L2 in one pass order and alternating, the
// same work held in L1, and the CNODE's fused field (64 x 40, tanh, 40 x 64) as a serial chain. Medians
// of 2,000 timed calls (std::chrono::steady_clock) after 200 warm-up calls; random weights.
//
//   g++ -O3 -std=c++17 -march=native -ffp-contract=off -fno-trapping-math -Ifirmware_ref/include \
//       -I/usr/include/eigen3 lab/gemv_f32_micro.cpp firmware_ref/src/kernels_f32_avx512.cpp firmware_ref/src/field_f32_avx2.cpp -o /tmp/gemv_f32_micro
//   taskset -c 1 /tmp/gemv_f32_micro
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <random>
#include <vector>

#include "fwref/kernels_f32_avx512.hpp"
#include "fwref/vmath_f32.hpp"
#include "micro_timing.hpp"

int main() {
  if (!fwref::gemv_f32_select("avx512")) {
    std::printf("gemv_f32_micro: this CPU has no AVX-512F\n");
    return 1;
  }
  std::mt19937 rng(1);
  std::normal_distribution<float> nd(0.0f, 0.1f);
  alignas(64) static float whh[240 * 80], x[80], b[240], y[240], w1[64 * 40], w2[40 * 64], z[64], v[64], b2[64];
  alignas(64) static float t1[40 * 64], t2[64 * 48];
  for (float* a : {whh, x, b, w1, w2, z, v, b2}) {
    const int n = a == whh ? 240 * 80 : a == w1 || a == w2 ? 64 * 40 : a == b ? 240 : 64;
    for (int i = 0; i < n; ++i) a[i] = nd(rng);
  }
  const double fwd = median_call_ns([&] { fwref::gemv_f32_avx512(whh, 240, 80, x, b, y, false); });
  long step = 0;
  const double alt = median_call_ns([&] { fwref::gemv_f32_avx512(whh, 240, 80, x, b, y, (step++ & 1) != 0); });
  const double l1 = median_call_ns([&] { for (int k = 0; k < 5; ++k) fwref::gemv_f32_avx512(whh, 48, 80, x, b, y, false); });
  std::printf("gru W_hh 240x80 from L2: one order %.0f ns, alternating %.0f ns; 5 x 48 rows held in L1 %.0f ns\n",
              fwd, alt, l1);
  fwref::pack_f32_t(w1, 64, 40, t1);
  fwref::pack_f32_t(w2, 40, 64, t2);
  const double field = median_call_ns([&] {
    for (int e = 0; e < 32; ++e) fwref::field_f32_t_avx512(t1, t2, 64, 40, z, v, b2, z);
  }) / 32;
  std::printf("cnode field (64 x 40, tanh, 40 x 64), serial chain: %.1f ns per evaluation\n", field);
  return 0;
}
