// lab/cnode_f32_control_micro.cpp -- the fp32 CNODE's products on an AVX2 host timed alone (docs/firmware.md,
// "Host kernels"), all in L1, random weights of the paper's shapes:
//   lin1_u rows:  the 17 rows of U times lin1_u (64 x 23) + b1 by gemv_f32_fma, masked last packet (the path for C < 8)
//                 against the same on the zero-padded copies (64 x 24, U rows of 24: src/cnode_f32_t.hpp), and
//                 whether the two give the same bits;
//   field:        32 evaluations of field_f32_t_avx2 (64 x 40, tanh, 40 x 64) as a serial chain (each z the last
//                 k, as RK4's stages) against 32 independent ones (the same z each time): equal times say the
//                 field is bound by instruction throughput, not by its dependency chain.
// 21 rounds of 2,000 repetitions, interleaved; medians in ns per repetition.
//
//   g++ -O3 -std=c++17 -march=native -ffp-contract=off -fno-trapping-math -Ifirmware_ref/include \
//       -I/usr/include/eigen3 lab/cnode_f32_control_micro.cpp firmware_ref/src/kernels_f32_avx512.cpp \
//       firmware_ref/src/field_f32_avx2.cpp -o /tmp/cnode_f32_control_micro
//   taskset -c 1 /tmp/cnode_f32_control_micro
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <random>
#include <vector>

#include "fwref/field_f32_avx2.hpp"
#include "fwref/vmath_f32.hpp"

namespace {

using Clock = std::chrono::steady_clock;

struct alignas(64) Data {
  float w[64 * 23], wp[64 * 24], u[17 * 23 + 8], up[17 * 24], b[64], y[17 * 64], yp[17 * 64];
  alignas(64) float w1t[40 * 64];  // pack_f32_t copies: 32-byte aligned at least (fwref/field_f32_avx2.hpp)
  alignas(64) float w2t[64 * 48];
  float z[64], k[64], v[64], b2[64];
};

template <class F>
double ns_per_rep(F f) {
  const auto a = Clock::now();
  for (int i = 0; i < 2000; ++i) {
    f();
    __asm__ volatile("" ::: "memory");
  }
  return std::chrono::duration<double, std::nano>(Clock::now() - a).count() / 2000;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

}  // namespace

int main() {
#if defined(FWREF_HAS_F32_FIELD_AVX2)
  static Data d;
  std::mt19937 rng(1);
  std::normal_distribution<float> nd(0.0f, 0.3f);
  for (int o = 0; o < 64; ++o) {
    for (int c = 0; c < 24; ++c) d.wp[o * 24 + c] = c < 23 ? (d.w[o * 23 + c] = nd(rng)) : 0.0f;
  }
  for (int s = 0; s < 17; ++s) {
    for (int c = 0; c < 24; ++c) d.up[s * 24 + c] = c < 23 ? (d.u[s * 23 + c] = nd(rng)) : 0.0f;
  }
  std::vector<float> w1(64 * 40), w2(40 * 64);
  for (float& f : w1) f = nd(rng);
  for (float& f : w2) f = nd(rng);
  for (int i = 0; i < 64; ++i) d.b[i] = nd(rng), d.v[i] = nd(rng), d.b2[i] = nd(rng), d.z[i] = nd(rng);
  fwref::pack_f32_t(w1.data(), 64, 40, d.w1t);
  fwref::pack_f32_t(w2.data(), 40, 64, d.w2t);
  std::vector<double> masked, padded, chained, independent;
  for (int r = 0; r < 21; ++r) {
    masked.push_back(ns_per_rep([] { for (int s = 0; s < 17; ++s) fwref::gemv_f32_fma(d.w, 64, 23, d.u + s * 23, d.b, d.y + s * 64); }));
    padded.push_back(ns_per_rep([] { for (int s = 0; s < 17; ++s) fwref::gemv_f32_fma(d.wp, 64, 24, d.up + s * 24, d.b, d.yp + s * 64); }));
    std::memcpy(d.k, d.z, sizeof d.k);
    chained.push_back(ns_per_rep([] { for (int e = 0; e < 32; ++e) fwref::field_f32_t_avx2(d.w1t, d.w2t, 64, 40, d.k, d.v, d.b2, d.k); }));
    independent.push_back(ns_per_rep([] { for (int e = 0; e < 32; ++e) fwref::field_f32_t_avx2(d.w1t, d.w2t, 64, 40, d.z, d.v, d.b2, d.k); }));
  }
  std::printf("lin1_u rows (17 x 64 x 23): masked %.0f ns, zero-padded %.0f ns, same bits: %s\n", median(masked),
              median(padded), std::memcmp(d.y, d.yp, sizeof d.y) == 0 ? "yes" : "NO");
  std::printf("32 fields (64 x 40): chained %.0f ns, independent %.0f ns\n", median(chained), median(independent));
  return 0;
#else
  std::printf("cnode_f32_control_micro: needs AVX2 + FMA (the avx2field build)\n");
  return 1;
#endif
}
