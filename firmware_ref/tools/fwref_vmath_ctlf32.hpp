// tools/fwref_vmath_ctlf32.hpp -- scope: fwref_vmath's checks of the fp32 CNODE's control path on avx2field
// (src/cnode_f32_t.hpp's control_path_avx2), bit for bit:
//   rows:   control_rows_f32_avx2 (fwref/controls_f32_avx2.hpp) against interp_row_f32's scalar statement,
//           u[c] = 0, then u[c] + p * ((x - mean) / std) per nonzero weight in increasing w; every C in 1..32,
//           windows of 1..100 samples, 1..3 rows of 0..4 nonzero weights (-0 among the zeros) and some dense
//           rows, NaN / +-inf / huge x in some cases; the padded columns must hold +0, the float after the
//           rows must stay untouched, and C = 33 or a wrong stride must be refused with nothing written;
//   padded: gemv_f32_fma on rows zero-padded to a multiple of 8 columns (x padded with +0) against
//           gemv_f32_fma on the unpadded rows (the masked last packet), every cols in 8..40, rows 1..17,
//           with rows whose every product is -0 and biases of -0, so that the sign of a zero sum is exercised
//           (padding x with -0 instead of +0 makes this check fail).
#pragma once

#include <cmath>
#include <random>
#include <vector>

#include "fwref/controls_f32_avx2.hpp"
#include "fwref/numerics.hpp"
#include "fwref/vmath_f32.hpp"
#include "fwref_vmath_check.hpp"

namespace vmath_ctlf32_check {

#if defined(FWREF_HAS_CONTROLS_F32_AVX2)
// Floats that differ (or guards overwritten, or a refusal that wrote) over all cases.
inline long check_rows(long* compared) {
  std::mt19937 rng(79);
  std::normal_distribution<float> nd(0.0f, 1.0f);
  long bad = 0;
  for (int C = 1; C <= 32; ++C) {
    const int up = (C + 7) & ~7;
    for (int W = 1; W <= 100; W += (W < 40 ? 1 : 7)) {
      const int S = 1 + (C + W) % 3;
      std::vector<float> p(S * W, 0.0f), x(W * C), mean(C), sd(C), want(S * up + 1, 0.0f), got(S * up + 1, 7.0f);
      for (int s = 0; s < S; ++s) {
        const int nz = (C + W + s) % 9 == 0 ? W : (C * W + s) % 5;  // dense rows now and then, else 0..4 weights
        for (int i = 0; i < nz; ++i) p[s * W + (i * 37 + C + s) % W] = nd(rng);
        if (W > 2) p[s * W + (C + s) % W] = p[s * W + (C + s) % W] == 0.0f ? -0.0f : p[s * W + (C + s) % W];
      }
      for (float& f : x) f = 3.0f * nd(rng);
      for (int c = 0; c < C; ++c) mean[c] = 0.3f * nd(rng), sd[c] = 0.5f + std::fabs(nd(rng));
      if ((C + W) % 4 == 0) x[(C * 7 + W) % (W * C)] = vmath_check::kOdd[(C + W) % 16 / 4];
      for (int s = 0; s < S; ++s) {
        for (int c = 0; c < C; ++c) {
          float u = 0.0f;
          for (int w = 0; w < W; ++w) {
            const float pw = p[s * W + w];
            if (pw != 0.0f) u = u + pw * ((x[w * C + c] - mean[c]) / sd[c]);
          }
          want[s * up + c] = u;
        }
      }
      want[S * up] = 7.0f;
      if (!fwref::control_rows_f32_avx2(p.data(), S, W, x.data(), C, mean.data(), sd.data(), got.data(), up)) return -1;
      for (int i = 0; i <= S * up; ++i) bad += fwref::float_bits(want[i]) != fwref::float_bits(got[i]);
      *compared += S * C;
    }
  }
  std::vector<float> p(4, 1.0f), x(4 * 33, 1.0f), ones(33, 1.0f), u(4 * 40, 7.0f);
  bad += fwref::control_rows_f32_avx2(p.data(), 1, 4, x.data(), 33, ones.data(), ones.data(), u.data(), 40);
  bad += fwref::control_rows_f32_avx2(p.data(), 1, 4, x.data(), 23, ones.data(), ones.data(), u.data(), 23);
  for (float f : u) bad += f != 7.0f;
  return bad;
}

// Outputs of the padded product that differ from the unpadded one.
inline long check_padded(long* compared) {
  std::mt19937 rng(80);
  std::normal_distribution<float> nd(0.0f, 1.0f);
  long bad = 0;
  for (int cols = 8; cols <= 40; ++cols) {
    const int cp = (cols + 7) & ~7;
    for (int rows = 1; rows <= 17; ++rows) {
      std::vector<float> w(rows * cols), x(cols), b(rows), wp(rows * cp, 0.0f), xp(cp, 0.0f), want(rows), got(rows);
      for (float& f : w) f = nd(rng);
      for (int i = 0; i < cols; ++i) x[i] = (i + rows) % 5 == 0 ? ((i & 1) ? -0.0f : 0.0f) : nd(rng);
      for (float& f : b) f = (rows + cols) % 3 == 0 ? -0.0f : nd(rng);
      for (int o = 0; o < rows; o += 3) {  // every third row: every product -0, so each lane's chain ends at -0 and
        for (int i = 0; i < cols; ++i) w[o * cols + i] = std::signbit(x[i]) ? 0.0f : -0.0f;  // a masked lane's +0 shows
      }
      for (int o = 0; o < rows; ++o) {
        for (int i = 0; i < cols; ++i) wp[o * cp + i] = w[o * cols + i];
      }
      for (int i = 0; i < cols; ++i) xp[i] = x[i];
      fwref::gemv_f32_fma(w.data(), rows, cols, x.data(), b.data(), want.data());
      fwref::gemv_f32_fma(wp.data(), rows, cp, xp.data(), b.data(), got.data());
      for (int o = 0; o < rows; ++o) bad += fwref::float_bits(want[o]) != fwref::float_bits(got[o]);
      *compared += rows;
    }
  }
  return bad;
}
#endif

}  // namespace vmath_ctlf32_check
