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
#include <cstdint>
#include <random>
#include <vector>

#include "fwref/field_f32_avx2.hpp"
#include "fwref/numerics.hpp"

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
  const auto bound_of = [&](int cols, int C, double mag, double exact) {
    const double n = (cols + C - 1) / C + (C == 4 ? 2 : C == 2 ? 1 : 0), g = n * u / (1.0 - n * u);
    return g * mag * (1.0 + u) + u * std::fabs(exact);
  };
  for (int H = 1; H <= 64; ++H) {
    for (int L = 1; L <= 64; ++L) {
      std::vector<float> w1(H * L), w2(L * H), z(L), v(H), b2(L), a(H), want(L), got(L + 1, 7.0f);
      for (float& f : w1) f = nd(rng);
      for (float& f : w2) f = nd(rng);
      for (float& f : z) f = 3.0f * nd(rng) / std::sqrt(float(L));
      for (float& f : v) f = nd(rng);
      for (float& f : b2) f = nd(rng);
      std::vector<float> t1(std::size_t(L) * fwref::f32_t_stride(H) + 16), t2(std::size_t(H) * fwref::f32_t_stride(L) + 16);
      float* const p1 = t1.data() + ((64 - reinterpret_cast<std::uintptr_t>(t1.data()) % 64) % 64) / sizeof(float);
      float* const p2 = t2.data() + ((64 - reinterpret_cast<std::uintptr_t>(t2.data()) % 64) % 64) / sizeof(float);
      fwref::pack_f32_t(w1.data(), H, L, p1);
      fwref::pack_f32_t(w2.data(), L, H, p2);
      double exact, mag;
      for (int o = 0; o < H; ++o) {
        const float y = stated_row(w1.data(), L, chains(H), z.data(), v[o], o, &exact, &mag);
        const double b = bound_of(L, chains(H), mag, exact);
        *bound_bad += std::fabs(double(y) - exact) > b;
        if (b > 0) *worst = std::max(*worst, std::fabs(double(y) - exact) / b);
        a[o] = fwref::tanh_approx(y);
      }
      for (int o = 0; o < L; ++o) {
        want[o] = stated_row(w2.data(), H, chains(L), a.data(), b2[o], o, &exact, &mag);
        const double b = bound_of(H, chains(L), mag, exact);
        *bound_bad += std::fabs(double(want[o]) - exact) > b;
        if (b > 0) *worst = std::max(*worst, std::fabs(double(want[o]) - exact) / b);
      }
      if (!fwref::field_f32_t_avx2(p1, p2, H, L, z.data(), v.data(), b2.data(), got.data())) return -1;
      std::vector<float> inplace(z);
      fwref::field_f32_t_avx2(p1, p2, H, L, inplace.data(), v.data(), b2.data(), inplace.data());
      for (int o = 0; o < L; ++o) {
        bad += fwref::float_bits(want[o]) != fwref::float_bits(got[o]);
        bad += fwref::float_bits(want[o]) != fwref::float_bits(inplace[o]);
      }
      bad += got[L] != 7.0f;  // nothing written past k
      *compared += L;
    }
  }
  fwref::gemv_f32_select(was512 ? "avx512" : was ? "avx2field" : "avx2");
  return bad;
}
#endif

}  // namespace vmath_f32t_check
