// lab/cnode_w16_micro.cpp -- the int8 CNODE field on an AVX2 host timed alone (docs/firmware.md, "Host kernels"):
// the field as src/cnode.cpp evaluates it with FWREF_I8_KERNEL=avx2 (quantize z to int16 codes, lin1_z on the int16
// copy with gemv_w16_x16, rescale + V + tanh + requantize, lin2, rescale + bias: 64 x 40 and 40 x 64, the paper's
// shapes) as a serial chain of 32 evaluations, each part alone, and the fused call (field_w16_avx2), then the two
// interleaved over 9 rounds. Random weights and scales (lab/micro_timing.hpp's I8Field).
//
//   g++ -O3 -std=c++17 -march=native -ffp-contract=off -fno-trapping-math -DFWREF_CNODE_W_INT16 -Ifirmware_ref/include
//       -I/usr/include/eigen3 lab/cnode_w16_micro.cpp firmware_ref/src/kernels_i8.cpp
//       firmware_ref/src/field_w16_avx2.cpp -o /tmp/cnode_w16_micro
//   FWREF_I8_KERNEL=avx2field taskset -c 1 /tmp/cnode_w16_micro
#include <cstdio>
#include <cstring>

#include "fwref/field_w16_avx2.hpp"
#include "fwref/kernels_i8.hpp"
#include "fwref/vmath_i8.hpp"
#include "micro_timing.hpp"

int main() {
  if (!fwref::field_w16_avx2_active()) {
    std::printf("cnode_w16_micro: run with FWREF_I8_KERNEL=avx2field on an AVX2 + FMA CPU\n");
    return 1;
  }
  static I8Field m;
  alignas(64) static std::int16_t w1[kH * kL], w2[kL * kH];
  fwref::expand_i8_to_i16(m.q1.data(), kH, kL, w1);
  fwref::expand_i8_to_i16(m.q2.data(), kL, kH, w2);
  alignas(64) std::int16_t zq[64], hq[64];  // int16 codes, what the w16 products read
  auto quant = [&](int e) { fwref::quantize_n(m.z, kL, m.s_z[e], zq); };
  auto lin1 = [&] { fwref::gemv_w16_x16(w1, kH, kL, zq, m.acc); };
  auto act = [&](int e) { fwref::rescale_tanh_quantize_n(m.acc, m.s_z[e], m.s_w1, m.v, m.s_hid, kH, hq); };
  auto lin2 = [&] { fwref::gemv_w16_x16(w2, kL, kH, hq, m.acc); };
  auto out = [&] { fwref::rescale_bias_n(m.acc, m.mult2, m.b2, kL, m.k), std::memcpy(m.z, m.k, sizeof(float) * kL); };
  const auto separate = [&] {
    for (int e = 0; e < kE; ++e) quant(e), lin1(), act(e), lin2(), out();
  };
  const fwref::FieldW16 f{w1, w2, kH, kL, m.s_w1, m.s_hid, m.mult2, m.b2};
  const auto fused = [&] {
    for (int e = 0; e < kE; ++e) fwref::field_w16_avx2(f, m.z, m.s_z[e], m.v, m.z);
  };
  std::printf("separate steps, serial chain: %.1f ns per evaluation\n", per_eval_ns(separate));
  const double a0 = per_eval_ns([&] { for (int e = 0; e < kE; ++e) quant(e); });
  const double a1 = per_eval_ns([&] { for (int e = 0; e < kE; ++e) lin1(); });
  const double a2 = per_eval_ns([&] { for (int e = 0; e < kE; ++e) act(e); });
  const double a3 = per_eval_ns([&] { for (int e = 0; e < kE; ++e) lin2(); });
  const double a4 = per_eval_ns([&] { for (int e = 0; e < kE; ++e) out(); });
  std::printf("  alone: quantize %.1f, lin1_z %.1f, rescale+tanh+requantize %.1f, lin2 %.1f, rescale+bias %.1f ns\n",
              a0, a1, a2, a3, a4);
  std::printf("fused call, serial chain: %.1f ns per evaluation\n", per_eval_ns(fused));
  const auto [sep, one] = interleaved_per_eval_ns(separate, fused);
  std::printf("interleaved, 9 rounds: separate steps %.1f ns, fused call %.1f ns per evaluation (medians)\n", sep, one);
  return 0;
}
