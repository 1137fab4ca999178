// tools/fwref_vmath_w8.hpp -- scope: fwref_vmath's check of the int8 CNODE field in one call
// (fwref/field_w8_vnni.hpp) against the separate steps it replaces (src/cnode_w8.cpp before it: quantize_n,
// gemv_w8_codes on lin1_z, rescale_tanh_quantize_n, gemv_w8_codes on lin2, rescale_bias_n), bit for bit,
// for every H, L in 1..64: random int8 weights in [-127, 127] packed by pack_i8_w8, random row scales,
// round-half-even ties of z's codes and near-ties (every other shape), states that cross the codes'
// saturation bounds and tanh's clamp, with a NaN, +-inf or a huge value mixed into z and v in some
// cases; the float after k must stay untouched, and z == k (in place, as the micro-benchmark calls it)
// must give the same bits. Only where gemv_w8_kernel() is not null. (tanh16 is also the fp32 field's,
// which fwref_vmath compares with tanh8 bit for bit through field_t.)
// And control_row_avx512 (fwref/controls_avx512.hpp) against for_each_nonzero + accumulate_codes +
// rescale_quantize_row (fwref/vmath_i8.hpp), codes and floats bit for bit: every C in 1..32, windows of
// 1..100 samples with 0..4 nonzero weights per row and some dense rows, x near the codes' ties in some
// cases and with NaN / +-inf / huge values in others; the code and float after C must stay untouched.
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "fwref/controls_avx512.hpp"
#include "fwref/field_w8_vnni.hpp"
#include "fwref/kernels_w8_vnni.hpp"
#include "fwref/numerics.hpp"
#include "fwref/vmath_i8.hpp"

namespace vmath_w8_check {

#if defined(FWREF_HAS_W8_VNNI)
// Elements of k whose bits differ (or guards overwritten) over all H, L; -1 when the kernel is not run here.
inline long check_field(long* compared) {
  const fwref::GemvW8Fn fn = fwref::gemv_w8_kernel();
  if (fn == nullptr) return -1;
  std::mt19937 rng(77);
  std::normal_distribution<float> nd(0.0f, 1.0f);
  std::uniform_int_distribution<int> wd(-127, 127);
  const float odd[4] = {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(),
                        -std::numeric_limits<float>::infinity(), 3e38f};
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
      std::vector<float> s_w1(H), v(H), mult2(L), b2(L), z(L), want(L), got(L + 1, 7.0f);
      // every other shape: every third z is f32((k + 0.5) * s_z), with s_z = 2^-6 an exact round-half-even
      // tie, with s_z = 0.01 within an ulp of one (where x / s and x * (1 / s) can round apart)
      const bool ties = (H + L) % 2 == 0;
      const float s_z = ties ? ((H + L) % 4 == 0 ? 0.015625f : 0.01f) : 0.02f * (1.0f + std::fabs(nd(rng))), s_hid = (H + L) % 3 == 0 ? 0.0123f : 1.0f / 127.0f;
      for (int i = 0; i < H; ++i) s_w1[i] = (0.5f + std::fabs(nd(rng))) / (127.0f * L), v[i] = 2.0f * nd(rng);
      for (int i = 0; i < L; ++i) mult2[i] = s_hid * (0.01f * (0.5f + std::fabs(nd(rng)))), b2[i] = nd(rng);
      for (int i = 0; i < L; ++i) z[i] = 2.0f * nd(rng);  // z / s_z up to ~300: saturated codes too
      for (int i = 0; ties && i < L; i += 3) z[i] = (static_cast<float>(wd(rng)) + 0.5f) * s_z;
      if ((H * 64 + L) % 5 == 0) z[(H + L) % L] = odd[(H + L) % 4];
      if ((H * 64 + L) % 7 == 0) v[(H * L) % H] = odd[(H * 3 + L) % 4];
      fwref::quantize_n(z.data(), L, s_z, zq.data());
      fwref::gemv_w8_codes(fn, p1, H, L, zq.data(), acc.data());
      fwref::rescale_tanh_quantize_n(acc.data(), s_z, s_w1.data(), v.data(), s_hid, H, hq.data());
      fwref::gemv_w8_codes(fn, p2, L, H, hq.data(), acc.data());
      fwref::rescale_bias_n(acc.data(), mult2.data(), b2.data(), L, want.data());
      const fwref::FieldW8 f{p1, p2, H, L, s_w1.data(), s_hid, mult2.data(), b2.data()};
      if (!fwref::field_w8_avx512vnni(f, z.data(), s_z, v.data(), got.data())) return -1;
      std::vector<float> inplace(z);
      fwref::field_w8_avx512vnni(f, inplace.data(), s_z, v.data(), inplace.data());
      for (int o = 0; o < L; ++o) {
        bad += fwref::float_bits(want[o]) != fwref::float_bits(got[o]);
        bad += fwref::float_bits(want[o]) != fwref::float_bits(inplace[o]);
      }
      bad += got[L] != 7.0f;  // nothing written past k
      *compared += L;
    }
  }
  return bad;
}

// Codes and floats that differ (or guards overwritten) over all cases. Call only where check_field ran.
inline long check_control(long* compared) {
  std::mt19937 rng(78);
  std::normal_distribution<float> nd(0.0f, 1.0f);
  std::uniform_int_distribution<int> pd(-127, 127);
  const float odd[4] = {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(),
                        -std::numeric_limits<float>::infinity(), 3e38f};
  long bad = 0;
  for (int C = 1; C <= 32; ++C) {
    for (int W = 1; W <= 100; W += (W < 40 ? 1 : 7)) {
      std::vector<std::int8_t> p(W, 0), want_q(C + 1, 5), got_q(C + 1, 5);
      const int nz = (C + W) % 9 == 0 ? W : (C * W) % 5;  // dense rows now and then, else 0..4 weights
      for (int i = 0; i < nz; ++i) p[(i * 37 + C) % W] = static_cast<std::int8_t>(pd(rng));
      std::vector<float> x(W * C), mean(C), sd(C), s_x(C), s_u(C), want_u(C + 1, 7.0f), got_u(C + 1, 7.0f);
      for (float& f : x) f = 3.0f * nd(rng);
      for (int c = 0; c < C; ++c) {
        mean[c] = 0.3f * nd(rng), sd[c] = 0.5f + std::fabs(nd(rng));
        s_x[c] = 0.02f * (0.5f + std::fabs(nd(rng))), s_u[c] = 0.03f * (0.5f + std::fabs(nd(rng)));
      }
      if ((C + W) % 3 == 0) {  // x / std within an ulp of a code's tie (k + 0.5) * s_x: mean 0, std 0.7, s_x 2^-6
        for (int c = 0; c < C; ++c) mean[c] = 0.0f, sd[c] = 0.7f, s_x[c] = 0.015625f;
        for (float& f : x) f = ((static_cast<float>(pd(rng)) + 0.5f) * 0.015625f) * 0.7f;
      }
      if ((C + W) % 4 == 0) x[(C * 7 + W) % (W * C)] = odd[(C + W) % 16 / 4];
      const float s_p = 1.0f / 127.0f;
      std::vector<std::int32_t> acc(C, 0);
      fwref::for_each_nonzero(p.data(), W, [&](int w, std::int32_t pw) {
        fwref::accumulate_codes(x.data() + w * C, mean.data(), sd.data(), s_x.data(), C, pw, acc.data());
      });
      fwref::rescale_quantize_row(acc.data(), s_p, s_x.data(), s_u.data(), C, want_u.data(), want_q.data());
      if (!fwref::control_row_avx512(p.data(), W, x.data(), C, mean.data(), sd.data(), s_x.data(), s_p, s_u.data(),
                                     got_u.data(), got_q.data())) {
        return -1;
      }
      std::vector<std::int8_t> q_no_u(C, 9);  // without the float row (u null): the same codes
      fwref::control_row_avx512(p.data(), W, x.data(), C, mean.data(), sd.data(), s_x.data(), s_p, s_u.data(), nullptr,
                                q_no_u.data());
      for (int c = 0; c <= C; ++c) {
        bad += want_q[c] != got_q[c];
        bad += fwref::float_bits(want_u[c]) != fwref::float_bits(got_u[c]);
        bad += c < C && q_no_u[c] != want_q[c];
      }
      *compared += C;
    }
  }
  return bad;
}
#endif

}  // namespace vmath_w8_check
