// tools/fwref_vmath_ctl2.hpp -- scope: fwref_vmath's check of control_row_avx2 (fwref/controls_avx2.hpp)
// against for_each_nonzero + accumulate_codes + rescale_quantize_row (fwref/vmath_i8.hpp), codes and floats
// bit for bit: every C in 1..32, windows of 1..100 samples with 0..4 nonzero weights per row and some dense
// rows, x near the codes' ties in some cases and with NaN / +-inf / huge values in others; the code and
// float after C must stay untouched (the same cases as tools/fwref_vmath_w8.hpp's control_row_avx512 check).
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include "fwref/controls_avx2.hpp"
#include "fwref/numerics.hpp"
#include "fwref/vmath_i8.hpp"

namespace vmath_ctl2_check {

#if defined(FWREF_HAS_CONTROLS_AVX2)
// Codes and floats that differ (or guards overwritten) over all cases.
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
      if (!fwref::control_row_avx2(p.data(), W, x.data(), C, mean.data(), sd.data(), s_x.data(), s_p, s_u.data(),
                                     got_u.data(), got_q.data())) {
        return -1;
      }
      std::vector<std::int8_t> q_no_u(C, 9);  // without the float row (u null): the same codes
      fwref::control_row_avx2(p.data(), W, x.data(), C, mean.data(), sd.data(), s_x.data(), s_p, s_u.data(), nullptr,
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

}  // namespace vmath_ctl2_check
