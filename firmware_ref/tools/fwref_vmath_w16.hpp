// tools/fwref_vmath_w16.hpp -- scope: fwref_vmath's check of the int8 CNODE field in one call on AVX2
// (fwref/field_w16_avx2.hpp) against the separate steps src/cnode.cpp runs with FWREF_I8_KERNEL=avx2
// (quantize_n to int16 codes, gemv_w16_x16 on lin1_z's int16 copy, rescale_tanh_quantize_n, gemv_w16_x16 on
// lin2's, rescale_bias_n), bit for bit, for every H, L in 8, 16, .., 64, 6 draws each: random int8 weights in
// [-127, 127] (and every 7th draw all +-127, the extremes) expanded by expand_i8_to_i16, random row scales,
// round-half-even ties of z's codes and near-ties (every other draw), states that cross the codes' saturation
// bounds and tanh's clamp, a NaN, +-inf or a huge value mixed into z and v in some draws; the float after k
// must stay untouched, z == k (in place) must give the same bits; and every other H, L in 1..64 must be
// refused (false, nothing written). Run with the int8 kernel switched to avx2field for the check (and back),
// wherever the CPU runs it.
#pragma once

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "fwref/field_w16_avx2.hpp"
#include "fwref/kernels_i8.hpp"
#include "fwref/numerics.hpp"
#include "fwref/vmath_i8.hpp"
#include "fwref_vmath_check.hpp"

namespace vmath_w16_check {

#if defined(FWREF_HAS_FIELD_W16_AVX2)
// One draw of shape (H, L); returns the elements of k that differ (or guards overwritten).
inline long check_one(std::mt19937& rng, int H, int L, int draw) {
  std::normal_distribution<float> nd(0.0f, 1.0f);
  std::uniform_int_distribution<int> wd(-127, 127);
  const bool extremes = draw % 7 == 6;
  std::vector<std::int8_t> q1(H * L), q2(L * H);
  for (auto& q : q1) q = static_cast<std::int8_t>(extremes ? (wd(rng) < 0 ? -127 : 127) : wd(rng));
  for (auto& q : q2) q = static_cast<std::int8_t>(extremes ? (wd(rng) < 0 ? -127 : 127) : wd(rng));
  std::vector<std::int16_t> w1(H * fwref::w16_stride(L)), w2(L * fwref::w16_stride(H)), zq(64, 0), hq(64, 0);
  fwref::expand_i8_to_i16(q1.data(), H, L, w1.data());
  fwref::expand_i8_to_i16(q2.data(), L, H, w2.data());
  std::vector<std::int32_t> acc(64);
  std::vector<float> s_w1(H), v(H), mult2(L), b2(L), z(L), want(L);
  const bool ties = (H + L + draw) % 2 == 0;
  const float s_z = ties ? ((H + L) % 16 == 0 ? 0.015625f : 0.01f) : 0.02f * (1.0f + std::fabs(nd(rng)));
  const float s_hid = (H + L + draw) % 3 == 0 ? 0.0123f : 1.0f / 127.0f;
  for (int i = 0; i < H; ++i) s_w1[i] = (0.5f + std::fabs(nd(rng))) / (127.0f * L), v[i] = 2.0f * nd(rng);
  for (int i = 0; i < L; ++i) mult2[i] = s_hid * (0.01f * (0.5f + std::fabs(nd(rng)))), b2[i] = nd(rng);
  for (int i = 0; i < L; ++i) z[i] = 2.0f * nd(rng);  // z / s_z up to ~300: saturated codes too
  for (int i = 0; ties && i < L; i += 3) z[i] = (static_cast<float>(wd(rng)) + 0.5f) * s_z;
  if ((H * 64 + L + draw) % 5 == 0) z[(H + L + draw) % L] = vmath_check::kOdd[(H + L + draw) % 4];
  if ((H * 64 + L + draw) % 7 == 0) v[(H * L + draw) % H] = vmath_check::kOdd[(H * 3 + L + draw) % 4];
  fwref::quantize_n(z.data(), L, s_z, zq.data());
  fwref::gemv_w16_x16(w1.data(), H, L, zq.data(), acc.data());
  fwref::rescale_tanh_quantize_n(acc.data(), s_z, s_w1.data(), v.data(), s_hid, H, hq.data());
  fwref::gemv_w16_x16(w2.data(), L, H, hq.data(), acc.data());
  fwref::rescale_bias_n(acc.data(), mult2.data(), b2.data(), L, want.data());
  const fwref::FieldW16 f{w1.data(), w2.data(), H, L, s_w1.data(), s_hid, mult2.data(), b2.data()};
  const long bad = vmath_check::compare_one_call([&](const float* zz, float* k) {
    return fwref::field_w16_avx2(f, zz, s_z, v.data(), k);
  }, z, want);
  return bad < 0 ? L + 1 : bad;
}

// Elements of k that differ (or guards overwritten, or a shape wrongly taken or refused) over all shapes;
// -1 when the CPU does not run avx2field.
inline long check_field(long* compared) {
  const char* const was = fwref::gemv_i8_kernel_name();
  if (!fwref::gemv_i8_select("avx2field")) return -1;
  std::mt19937 rng(79);
  long bad = 0;
  for (int H = 1; H <= 64; ++H) {
    for (int L = 1; L <= 64; ++L) {
      if (H % 8 != 0 || L % 8 != 0) {  // refused, nothing written
        std::vector<float> z(L, 0.5f), v(H, 0.0f), s(64, 1.0f), k(L, 7.0f);
        const std::int16_t w[1] = {0};
        const fwref::FieldW16 f{w, w, H, L, s.data(), 1.0f / 127.0f, s.data(), s.data()};
        bad += fwref::field_w16_avx2(f, z.data(), 0.01f, v.data(), k.data()) || k[0] != 7.0f;
        continue;
      }
      for (int draw = 0; draw < 6; ++draw) bad += check_one(rng, H, L, draw);
      *compared += 6L * L;
    }
  }
  fwref::gemv_i8_select(was);
  return bad;
}
#endif

}  // namespace vmath_w16_check
