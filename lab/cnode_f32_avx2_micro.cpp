// lab/cnode_f32_avx2_micro.cpp -- the fp32 CNODE field on an AVX2 host timed alone (docs/firmware.md, "Host
// kernels"): the field as src/cnode.cpp evaluates it with FWREF_F32_KERNEL=avx2 (gemv_f32_fma on
// lin1_z with V as bias, tanh_n, gemv_f32_fma on lin2 with its bias: 64 x 40 and 40 x 64, the paper's shapes)
// against the fused call (field_f32_t_avx2 on the column-major copies), each as a serial chain of 32
// evaluations (k fed back as the next z), interleaved over 9 rounds; per round the median of 2,000 timed
// chains (std::chrono::steady_clock) after 200 warm-up ones; printed: the medians of the rounds.
//
//   g++ -O3 -std=c++17 -march=native -ffp-contract=off -fno-trapping-math -Ifirmware_ref/include -I/usr/include/eigen3
//       lab/cnode_f32_avx2_micro.cpp firmware_ref/src/field_f32_avx2.cpp firmware_ref/src/kernels_f32_avx512.cpp
//       -o /tmp/cnode_f32_avx2_micro
//   taskset -c 1 /tmp/cnode_f32_avx2_micro
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <random>
#include <vector>

#include "fwref/field_f32_avx2.hpp"
#include "fwref/vmath_f32.hpp"
#include "micro_timing.hpp"

constexpr int H = kH, L = kL, E = kE;

int main() {
  std::mt19937 rng(1);
  std::normal_distribution<float> nd(0.0f, 1.0f);
  static float w1[H * L], w2[L * H];
  alignas(64) static float w1t[L * fwref::f32_t_stride(H)], w2t[H * fwref::f32_t_stride(L)];
  for (float& f : w1) f = 0.3f * nd(rng) / 6.0f;
  for (float& f : w2) f = 0.3f * nd(rng) / 8.0f;
  fwref::pack_f32_t(w1, H, L, w1t);
  fwref::pack_f32_t(w2, L, H, w2t);
  alignas(64) float z[64] = {}, a[64] = {}, v[64], b2[64];
  for (int i = 0; i < H; ++i) v[i] = 0.3f * nd(rng);
  for (int i = 0; i < L; ++i) b2[i] = 0.1f * nd(rng), z[i] = nd(rng);
  const auto separate = [&] {
    for (int e = 0; e < E; ++e) {
      fwref::gemv_f32_fma(w1, H, L, z, v, a);
      fwref::tanh_n(a, H);
      fwref::gemv_f32_fma(w2, L, H, a, b2, z);
    }
  };
  const auto fused = [&] {
    for (int e = 0; e < E; ++e) fwref::field_f32_t_avx2(w1t, w2t, H, L, z, v, b2, z);
  };
  const auto [sep, one] = interleaved_per_eval_ns(separate, fused);
  std::printf("interleaved, 9 rounds: separate steps %.1f ns, fused call %.1f ns per evaluation (medians)\n", sep, one);
  return 0;
}
