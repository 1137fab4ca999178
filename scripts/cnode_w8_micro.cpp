// scripts/cnode_w8_micro.cpp -- the int8 CNODE field's parts on the host VNNI path timed alone (docs/bench.md,
// "The CNODE int8 field in one call"): the field as src/cnode_w8.cpp evaluated it before the fused call (quantize z,
// lin1_z on the packed int8 copy, rescale + V + tanh + requantize, lin2, rescale + bias: 64 x 40 and 40 x 64, the
// paper's shapes) as a serial chain of 32 evaluations, the same chain with one part left out, each part
// alone, and the fused call (field_w8_avx512vnni). Medians of 2,000 timed chains (std::chrono::steady_clock)
// after 200 warm-up ones; random weights and scales that keep the state in the codes' range.
//
//   g++ -O3 -std=c++17 -march=native -ffp-contract=off -fno-trapping-math -Ifirmware_ref/include -I/usr/include/eigen3
//       scripts/cnode_w8_micro.cpp firmware_ref/src/kernels_w8_vnni.cpp firmware_ref/src/kernels_i8.cpp
//       firmware_ref/src/field_w8_vnni.cpp -o /tmp/cnode_w8_micro
//   taskset -c 1 /tmp/cnode_w8_micro
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <random>
#include <vector>

#include "fwref/field_w8_vnni.hpp"
#include "fwref/kernels_w8_vnni.hpp"
#include "fwref/vmath_i8.hpp"
#include "micro_timing.hpp"

namespace {

constexpr int H = 64, L = 40, E = 32;

template <class F>
double median_ns(F f) {
  return median_call_ns(f) / E;  // per evaluation
}

struct Model {
  alignas(64) std::uint8_t w1[fwref::w8_bytes(H, L)], w2[fwref::w8_bytes(L, H)];
  float s_w1[H], s_w2[H], mult2[L], b2[L], v[H], s_z[E], s_hid = 1.0f / 127.0f;
};

}  // namespace

int main() {
  fwref::GemvW8Fn fn = fwref::gemv_w8_kernel();
  if (fn == nullptr) {
    std::printf("cnode_w8_micro: the int8 kernel here is not avx512vnni\n");
    return 1;
  }
  std::mt19937 rng(1);
  std::uniform_int_distribution<int> wd(-127, 127);
  std::normal_distribution<float> nd(0.0f, 1.0f);
  static Model m;
  std::vector<std::int8_t> q1(H * L), q2(L * H);
  for (auto& q : q1) q = static_cast<std::int8_t>(wd(rng));
  for (auto& q : q2) q = static_cast<std::int8_t>(wd(rng));
  fwref::pack_i8_w8(q1.data(), H, L, m.w1);
  fwref::pack_i8_w8(q2.data(), L, H, m.w2);
  for (int i = 0; i < H; ++i) m.s_w1[i] = 0.01f / 127.0f, m.v[i] = 0.3f * nd(rng);
  for (int i = 0; i < L; ++i) m.s_w2[i] = 0.02f / 127.0f, m.mult2[i] = m.s_hid * m.s_w2[i], m.b2[i] = 0.1f * nd(rng);
  for (int e = 0; e < E; ++e) m.s_z[e] = 2.0f / 127.0f;
  alignas(64) float z[64] = {}, k[64] = {};
  alignas(64) std::int8_t zq[64], hq[64];
  alignas(64) std::int32_t acc[64];
  for (int i = 0; i < L; ++i) z[i] = nd(rng);
  // the parts of one evaluation; each chain feeds k back as the next z (the RK4 loop's dependency)
  auto quant = [&](int e) { fwref::quantize_n(z, L, m.s_z[e], zq); };
  auto lin1 = [&] { fwref::gemv_w8_codes(fn, m.w1, H, L, zq, acc); };
  auto act = [&](int e) { fwref::rescale_tanh_quantize_n(acc, m.s_z[e], m.s_w1, m.v, m.s_hid, H, hq); };
  auto lin2 = [&] { fwref::gemv_w8_codes(fn, m.w2, L, H, hq, acc); };
  auto out = [&] { fwref::rescale_bias_n(acc, m.mult2, m.b2, L, k), std::memcpy(z, k, sizeof(float) * L); };
  const double full = median_ns([&] {
    for (int e = 0; e < E; ++e) quant(e), lin1(), act(e), lin2(), out();
  });
  std::printf("separate steps, serial chain: %.1f ns per evaluation\n", full);
  const char* names[5] = {"quantize z", "lin1_z product", "rescale+V+tanh+requantize", "lin2 product", "rescale+bias"};
  for (int skip = 0; skip < 5; ++skip) {
    const double t = median_ns([&] {
      for (int e = 0; e < E; ++e) {
        if (skip != 0) quant(e);
        if (skip != 1) lin1();
        if (skip != 2) act(e);
        if (skip != 3) lin2();
        if (skip != 4) out();
      }
    });
    std::printf("  without %-26s %.1f ns (its share %.1f ns)\n", names[skip], t, full - t);
  }
  const double a0 = median_ns([&] { for (int e = 0; e < E; ++e) quant(e); });
  const double a1 = median_ns([&] { for (int e = 0; e < E; ++e) lin1(); });
  const double a2 = median_ns([&] { for (int e = 0; e < E; ++e) act(e); });
  const double a3 = median_ns([&] { for (int e = 0; e < E; ++e) lin2(); });
  const double a4 = median_ns([&] { for (int e = 0; e < E; ++e) out(); });
  std::printf("  alone: %.1f, %.1f, %.1f, %.1f, %.1f ns\n", a0, a1, a2, a3, a4);
  const fwref::FieldW8 f{m.w1, m.w2, H, L, m.s_w1, m.s_hid, m.mult2, m.b2};
  const double fused = median_ns([&] {
    for (int e = 0; e < E; ++e) fwref::field_w8_avx512vnni(f, z, m.s_z[e], m.v, z);
  });
  std::printf("fused call, serial chain: %.1f ns per evaluation\n", fused);
  return 0;
}
