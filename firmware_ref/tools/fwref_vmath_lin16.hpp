// tools/fwref_vmath_lin16.hpp -- scope: fwref_vmath's check of the folded int8 layer on several code vectors
// in one call on AVX2 (fwref/linear_w16_avx2.hpp, the int8 CNODE's lin1_u rows with avx2field) against
// linear_i8_folded (fwref/numerics.hpp) row by row, bit for bit: every rows in 8, 16, .., 64 and cols in
// 1..32, 1 to 3 code vectors, 2 draws each: random int8 weights in [-127, 127] (every other draw all +-127)
// expanded by expand_i8_to_i16, codes in [-128, 127] with the extremes forced in, random row scales and
// biases, a NaN, +-inf or huge bias in some draws; the float after y must stay untouched. Every other rows in
// 1..64 and cols 33..40 must be refused (false, nothing written).
#pragma once

#include <cmath>
#include <cstdint>
#include <random>
#include <vector>

#include "fwref/kernels_i8.hpp"
#include "fwref/linear_w16_avx2.hpp"
#include "fwref/numerics.hpp"
#include "fwref/vmath_i8.hpp"
#include "fwref_vmath_check.hpp"

namespace vmath_lin16_check {

#if defined(FWREF_HAS_LINEAR_W16_AVX2)
// One draw of (rows, cols, n); returns the elements of y that differ (or guards overwritten).
inline long check_one(std::mt19937& rng, int rows, int cols, int n, int draw) {
  std::normal_distribution<float> nd(0.0f, 1.0f);
  std::uniform_int_distribution<int> wd(-127, 127), xd(-128, 127);
  std::vector<std::int8_t> q(rows * cols), x(n * cols);
  for (auto& w : q) w = static_cast<std::int8_t>(draw % 2 == 1 ? (wd(rng) < 0 ? -127 : 127) : wd(rng));
  for (auto& c : x) c = static_cast<std::int8_t>(xd(rng));
  x[0] = -128, x[n * cols - 1] = 127;
  std::vector<std::int16_t> w16(rows * fwref::w16_stride(cols));
  fwref::expand_i8_to_i16(q.data(), rows, cols, w16.data());
  std::vector<float> s_w(rows), b(rows), want(n * rows), got(n * rows + 1, 7.0f);
  for (int o = 0; o < rows; ++o) s_w[o] = (0.5f + std::fabs(nd(rng))) * 1e-3f, b[o] = nd(rng);
  if ((rows + cols + draw) % 5 == 0) b[(cols + draw) % rows] = vmath_check::kOdd[(rows + cols) % 4];
  for (int s = 0; s < n; ++s) {
    fwref::linear_i8_folded(q.data(), s_w.data(), rows, cols, x.data() + s * cols, b.data(), want.data() + s * rows);
  }
  if (!fwref::linear_folded_w16_avx2(w16.data(), rows, cols, x.data(), n, s_w.data(), b.data(), got.data())) {
    return n * rows + 1;
  }
  long bad = got[n * rows] != 7.0f;  // nothing written past y
  for (int i = 0; i < n * rows; ++i) bad += fwref::float_bits(want[i]) != fwref::float_bits(got[i]);
  return bad;
}

// Elements that differ (or guards overwritten, or a shape wrongly taken or refused) over all shapes.
inline long check_linear(long* compared) {
  std::mt19937 rng(83);
  long bad = 0;
  for (int rows = 1; rows <= 64; ++rows) {
    for (int cols = 1; cols <= 40; ++cols) {
      if (rows % 8 != 0 || cols > 32) {  // refused, nothing written
        std::vector<float> y(1, 7.0f), s(64, 1.0f);
        const std::vector<std::int16_t> w(64 * 40, 0);
        const std::vector<std::int8_t> x(40, 1);
        bad += fwref::linear_folded_w16_avx2(w.data(), rows, cols, x.data(), 1, s.data(), s.data(), y.data()) ||
               y[0] != 7.0f;
        continue;
      }
      for (int draw = 0; draw < 2; ++draw) {
        const int n = 1 + (rows + cols + draw) % 3;
        bad += check_one(rng, rows, cols, n, draw);
        *compared += long(n) * rows;
      }
    }
  }
  return bad;
}
#endif

}  // namespace vmath_lin16_check
