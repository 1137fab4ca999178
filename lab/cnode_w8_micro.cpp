// lab/cnode_w8_micro.cpp -- the int8 CNODE field on the host VNNI path timed alone (docs/firmware.md, "Host
// kernels"): the field as five separate steps (quantize z, lin1_z on the packed int8 copy, rescale + V + tanh +
// requantize, lin2, rescale + bias: 64 x 40 and 40 x 64, the paper's shapes) as a serial chain of 32 evaluations,
// the same chain with one step left out, each step alone, and the fused call (field_w8_avx512vnni). Random weights
// and scales (lab/micro_timing.hpp's I8Field).
//
//   g++ -O3 -std=c++17 -march=native -ffp-contract=off -fno-trapping-math -Ifirmware_ref/include -I/usr/include/eigen3
//       lab/cnode_w8_micro.cpp firmware_ref/src/kernels_w8_vnni.cpp firmware_ref/src/kernels_i8.cpp
//       firmware_ref/src/field_w8_vnni.cpp -o /tmp/cnode_w8_micro
//   taskset -c 1 /tmp/cnode_w8_micro
#include <cstdio>
#include <cstring>

#include "fwref/field_w8_vnni.hpp"
#include "fwref/kernels_w8_vnni.hpp"
#include "fwref/vmath_i8.hpp"
#include "micro_timing.hpp"

int main() {
  fwref::GemvW8Fn fn = fwref::gemv_w8_kernel();
  if (fn == nullptr) {
    std::printf("cnode_w8_micro: the int8 kernel here is not avx512vnni\n");
    return 1;
  }
  static I8Field m;
  alignas(64) static std::uint8_t w1[fwref::w8_bytes(kH, kL)], w2[fwref::w8_bytes(kL, kH)];
  fwref::pack_i8_w8(m.q1.data(), kH, kL, w1);
  fwref::pack_i8_w8(m.q2.data(), kL, kH, w2);
  alignas(64) std::int8_t codes[2][64];  // z's and the hidden layer's int8 codes, what the w8 products read
  // the steps of one evaluation; each chain feeds k back as the next z (the RK4 loop's dependency)
  const auto steps = [&](int e, int skip) {
    if (skip != 0) fwref::quantize_n(m.z, kL, m.s_z[e], codes[0]);
    if (skip != 1) fwref::gemv_w8_codes(fn, w1, kH, kL, codes[0], m.acc);
    if (skip != 2) fwref::rescale_tanh_quantize_n(m.acc, m.s_z[e], m.s_w1, m.v, m.s_hid, kH, codes[1]);
    if (skip != 3) fwref::gemv_w8_codes(fn, w2, kL, kH, codes[1], m.acc);
    if (skip != 4) fwref::rescale_bias_n(m.acc, m.mult2, m.b2, kL, m.k), std::memcpy(m.z, m.k, sizeof(float) * kL);
  };
  const double full = per_eval_ns([&] {
    for (int e = 0; e < kE; ++e) steps(e, -1);
  });
  std::printf("separate steps, serial chain: %.1f ns per evaluation\n", full);
  const char* names[5] = {"quantize z", "lin1_z product", "rescale+V+tanh+requantize", "lin2 product", "rescale+bias"};
  for (int skip = 0; skip < 5; ++skip) {
    const double t = per_eval_ns([&] {
      for (int e = 0; e < kE; ++e) steps(e, skip);
    });
    std::printf("  without %-26s %.1f ns (its share %.1f ns)\n", names[skip], t, full - t);
  }
  const fwref::FieldW8 f{w1, w2, kH, kL, m.s_w1, m.s_hid, m.mult2, m.b2};
  const double fused = per_eval_ns([&] {
    for (int e = 0; e < kE; ++e) fwref::field_w8_avx512vnni(f, m.z, m.s_z[e], m.v, m.z);
  });
  std::printf("fused call, serial chain: %.1f ns per evaluation\n", fused);
  return 0;
}
