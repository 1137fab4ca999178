// tools/fwref_vmath_f32t.hpp -- scope: fwref_vmath's check of the fp32 CNODE field in one call on AVX2
// (fwref/field_f32_avx2.hpp): bit for bit against a scalar statement of its order (the header's chains per
// row, C = chains(ceil(rows / 8)), then + bias, tanh_approx between the two products) and each product
// within its bound gamma(ceil(cols / C) + log2 C) * sum |w x| (+ the bias add's u |y|) of a double sum, for
// every H, L in 1..64 (z in [-3, 3] so tanh's clamp is crossed too); the float after k must stay untouched
// and z == k (in place) must give the same bits. Switched to the avx2field choice for the check (and back),
// wherever the CPU runs it.
#pragma once

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "fwref/field_f32_avx2.hpp"
#include "fwref/numerics.hpp"
#include "fwref_vmath_check.hpp"

namespace vmath_f32t_check {

#if defined(FWREF_HAS_F32_FIELD_AVX2)
// The stated order: y[o] for rows of W (rows, cols) row-major, chains C; ``bound`` gets the error bound.
inline float stated_row(const float* w, int cols, int C, const float* x, float b, int o, double* exact, double* mag) {
  float s[4] = {0.0f, 0.0f, 0.0f, 0.0f};
  *exact = 0.0, *mag = 0.0;
  for (int i = 0; i < cols; ++i) {
    const float wi = w[o * cols + i];
    s[i % C] = i < C ? wi * x[i] : std::fma(wi, x[i], s[i % C]);
    *exact += double(wi) * x[i], *mag += std::fabs(double(wi) * x[i]);
  }
  const float y = C == 1 ? s[0] : C == 2 ? s[0] + s[1] : (s[0] + s[1]) + (s[2] + s[3]);
  *exact += b;
  return y + b;
}

inline int chains(int rows) {
  const int nb = (rows + 7) / 8;
  return nb >= 6 ? 1 : nb >= 3 ? 2 : 4;
}

// Elements that differ from the stated order (or guards overwritten); ``bound_bad`` the products outside
// their bound, ``worst`` the largest error / bound. -1 when the CPU does not run the AVX2 field.
inline long check_field(long* compared, long* bound_bad, double* worst) {
  const bool was = fwref::field_f32_avx2_active();
  const bool was512 = fwref::gemv_f32_avx512_active();
  if (!fwref::gemv_f32_select("avx2field")) return -1;
  std::mt19937 rng(101);
  std::normal_distribution<float> nd(0.0f, 1.0f);
  const double u = std::ldexp(1.0, -24);
  long bad = 0;
  // y[o] of a product (rows, cols) in the stated order; its distance from the double sum counted against the bound.
  const auto stated = [&](const float* w, int cols, int rows, const float* x, float b, int o) {
    const int C = chains(rows);
    double exact, mag;
    const float y = stated_row(w, cols, C, x, b, o, &exact, &mag);
    const double n = (cols + C - 1) / C + (C == 4 ? 2 : C == 2 ? 1 : 0), g = n * u / (1.0 - n * u);
    const double bound = g * mag * (1.0 + u) + u * std::fabs(exact), err = std::fabs(double(y) - exact);
    *bound_bad += err > bound;
    if (bound > 0) *worst = std::max(*worst, err / bound);
    return y;
  };
  for (int H = 1; H <= 64; ++H) {
    for (int L = 1; L <= 64; ++L) {
      const vmath_check::FieldF32Case f(rng, nd, H, L);
      std::vector<float> a(H), want(L);
      for (int o = 0; o < H; ++o) a[o] = fwref::tanh_approx(stated(f.w1.data(), L, H, f.z.data(), f.v[o], o));
      for (int o = 0; o < L; ++o) want[o] = stated(f.w2.data(), H, L, a.data(), f.b2[o], o);
      const long b = vmath_check::compare_one_call([&](const float* z, float* k) {
        return fwref::field_f32_t_avx2(f.t1, f.t2, H, L, z, f.v.data(), f.b2.data(), k);
      }, f.z, want);
      if (b < 0) return -1;
      bad += b;
      *compared += L;
    }
  }
  fwref::gemv_f32_select(was512 ? "avx512" : was ? "avx2field" : "avx2");
  return bad;
}
#endif

}  // namespace vmath_f32t_check
