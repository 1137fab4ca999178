// tools/fwref_vmath_w8.hpp -- scope: fwref_vmath's check of the int8 CNODE field in one call
// (fwref/field_w8_vnni.hpp) against the separate steps it replaces (src/cnode_w8.cpp before it: quantize_n,
// gemv_w8_codes on lin1_z, rescale_tanh_quantize_n, gemv_w8_codes on lin2, rescale_bias_n), bit for bit,
// for every H, L in 1..64: random int8 weights in [-127, 127] packed by pack_i8_w8, random row scales,
// round-half-even ties of z's codes and near-ties (every other shape), states that cross the codes'
// saturation bounds and tanh's clamp, with a NaN, +-inf or a huge value mixed into z and v in some
// cases; the float after k must stay untouched, and z == k (in place, as the micro-benchmark calls it)
// must give the same bits. Only where gemv_w8_kernel() is not null. (tanh16 is also the fp32 field's,
// which fwref_vmath compares with tanh8 bit for bit through field_t.) control_row_avx512 is checked by
// tools/fwref_vmath_check.hpp's check_control_row on the same CPUs.
#pragma once

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "fwref/field_w8_vnni.hpp"
#include "fwref/kernels_w8_vnni.hpp"
#include "fwref/numerics.hpp"
#include "fwref/vmath_i8.hpp"
#include "fwref_vmath_check.hpp"

namespace vmath_w8_check {

#if defined(FWREF_HAS_W8_VNNI)
// Elements of k whose bits differ (or guards overwritten) over all H, L; -1 when the kernel is not run here.
inline long check_field(long* compared) {
  const fwref::GemvW8Fn fn = fwref::gemv_w8_kernel();
  if (fn == nullptr) return -1;
  std::mt19937 rng(77);
  std::normal_distribution<float> nd(0.0f, 1.0f);
  std::uniform_int_distribution<int> wd(-127, 127);
  long bad = 0;
  for (int H = 1; H <= 64; ++H) {
    for (int L = 1; L <= 64; ++L) {
      std::vector<std::int8_t> q1(H * L), q2(L * H), zq(L), hq(H);
      for (auto& q : q1) q = static_cast<std::int8_t>(wd(rng));
      for (auto& q : q2) q = static_cast<std::int8_t>(wd(rng));
      std::vector<std::int32_t> w1((fwref::w8_bytes(H, L) + 3) / 4), w2((fwref::w8_bytes(L, H) + 3) / 4), acc(64);
      std::uint8_t* const p1 = reinterpret_cast<std::uint8_t*>(w1.data());
      std::uint8_t* const p2 = reinterpret_cast<std::uint8_t*>(w2.data());
      fwref::pack_i8_w8(q1.data(), H, L, p1);
      fwref::pack_i8_w8(q2.data(), L, H, p2);
      std::vector<float> s_w1(H), v(H), mult2(L), b2(L), z(L), want(L);
      // every other shape: every third z is f32((k + 0.5) * s_z), with s_z = 2^-6 an exact round-half-even
      // tie, with s_z = 0.01 within an ulp of one (where x / s and x * (1 / s) can round apart)
      const bool ties = (H + L) % 2 == 0;
      const float s_z = ties ? ((H + L) % 4 == 0 ? 0.015625f : 0.01f) : 0.02f * (1.0f + std::fabs(nd(rng))), s_hid = (H + L) % 3 == 0 ? 0.0123f : 1.0f / 127.0f;
      for (int i = 0; i < H; ++i) s_w1[i] = (0.5f + std::fabs(nd(rng))) / (127.0f * L), v[i] = 2.0f * nd(rng);
      for (int i = 0; i < L; ++i) mult2[i] = s_hid * (0.01f * (0.5f + std::fabs(nd(rng)))), b2[i] = nd(rng);
      for (int i = 0; i < L; ++i) z[i] = 2.0f * nd(rng);  // z / s_z up to ~300: saturated codes too
      for (int i = 0; ties && i < L; i += 3) z[i] = (static_cast<float>(wd(rng)) + 0.5f) * s_z;
      if ((H * 64 + L) % 5 == 0) z[(H + L) % L] = vmath_check::kOdd[(H + L) % 4];
      if ((H * 64 + L) % 7 == 0) v[(H * L) % H] = vmath_check::kOdd[(H * 3 + L) % 4];
      fwref::quantize_n(z.data(), L, s_z, zq.data());
      fwref::gemv_w8_codes(fn, p1, H, L, zq.data(), acc.data());
      fwref::rescale_tanh_quantize_n(acc.data(), s_z, s_w1.data(), v.data(), s_hid, H, hq.data());
      fwref::gemv_w8_codes(fn, p2, L, H, hq.data(), acc.data());
      fwref::rescale_bias_n(acc.data(), mult2.data(), b2.data(), L, want.data());
      const fwref::FieldW8 f{p1, p2, H, L, s_w1.data(), s_hid, mult2.data(), b2.data()};
      const long b = vmath_check::compare_one_call([&](const float* zz, float* k) {
        return fwref::field_w8_avx512vnni(f, zz, s_z, v.data(), k);
      }, z, want);
      if (b < 0) return -1;
      bad += b;
      *compared += L;
    }
  }
  return bad;
}
#endif

}  // namespace vmath_w8_check
