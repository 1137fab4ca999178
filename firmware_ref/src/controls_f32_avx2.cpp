// src/controls_f32_avx2.cpp -- scope: the fp32 CNODE's control rows U on AVX2 + FMA (fwref/controls_f32_avx2.hpp).
#include "fwref/controls_f32_avx2.hpp"

#if defined(FWREF_HAS_CONTROLS_F32_AVX2)

#include <immintrin.h>

namespace fwref {

namespace {

#define FWREF_CF inline __attribute__((always_inline))

// Lanes [0, n) of 8 (all lanes for n >= 8).
FWREF_CF __m256i lanes(int n) { return _mm256_cmpgt_epi32(_mm256_set1_epi32(n), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7)); }

// The per-channel constants of NQ packets: lanes past C have mean 0, std 1 (finite, never stored).
template <int NQ>
struct Norm {
  __m256i m[NQ];
  __m256 mean[NQ], sd[NQ];
};

// Sample xw (weight pv) into acc: acc = acc + pv * ((x - mean) / std). MASKED: the last packet through a masked
// load (a sample whose whole packets would reach past the window's end).
template <int NQ, bool MASKED>
FWREF_CF void add_sample(const Norm<NQ>& k, const float* xw, __m256 pv, __m256* acc) {
  for (int q = 0; q < NQ; ++q) {
    const __m256 xv = MASKED && q + 1 == NQ ? _mm256_maskload_ps(xw + 8 * q, k.m[q]) : _mm256_loadu_ps(xw + 8 * q);
    const __m256 xn = _mm256_div_ps(_mm256_sub_ps(xv, k.mean[q]), k.sd[q]);  // normalise
    acc[q] = _mm256_add_ps(acc[q], _mm256_mul_ps(pv, xn));                   // u[c] += p * normalise(...)
  }
}

template <int NQ>
void control_rows(const float* p, int S, int window, const float* x, int C, const float* mean, const float* std_,
                  float* u, int up) {
  Norm<NQ> k;
  for (int q = 0; q < NQ; ++q) {
    k.m[q] = lanes(C - 8 * q);
    k.mean[q] = _mm256_maskload_ps(mean + 8 * q, k.m[q]);
    k.sd[q] = _mm256_blendv_ps(_mm256_set1_ps(1.0f), _mm256_maskload_ps(std_ + 8 * q, k.m[q]), _mm256_castsi256_ps(k.m[q]));
  }
  const float* const end = x + long(window) * C;
  for (int s = 0; s < S; ++s) {
    const float* const ps = p + long(s) * window;
    __m256 acc[NQ];
    for (int q = 0; q < NQ; ++q) acc[q] = _mm256_setzero_ps();  // u[c] = 0.0f
    const auto sample = [&](int w) {
      const float* xw = x + long(w) * C;
      if (xw + 8 * NQ > end) return add_sample<NQ, true>(k, xw, _mm256_set1_ps(ps[w]), acc);  // the window's end
      add_sample<NQ, false>(k, xw, _mm256_set1_ps(ps[w]), acc);
    };
    int w0 = 0;
    for (; w0 + 8 <= window; w0 += 8) {
      for (unsigned nz = nonzero8(ps + w0); nz != 0; nz &= nz - 1) sample(w0 + __builtin_ctz(nz));  // increasing w
    }
    for (; w0 < window; ++w0) {
      if (ps[w0] != 0.0f) sample(w0);
    }
    for (int q = 0; q < NQ; ++q) {  // lanes past C: +0 (whatever the next sample's channels gave)
      _mm256_storeu_ps(u + long(s) * up + 8 * q, _mm256_and_ps(acc[q], _mm256_castsi256_ps(k.m[q])));
    }
  }
}

#undef FWREF_CF

}  // namespace

bool control_rows_f32_avx2(const float* p, int S, int window, const float* x, int channels, const float* mean,
                           const float* std_, float* u, int up) {
  if (channels < 1 || channels > 32 || up != ((channels + 7) & ~7)) return false;
  switch (up / 8) {
    case 1: return control_rows<1>(p, S, window, x, channels, mean, std_, u, up), true;
    case 2: return control_rows<2>(p, S, window, x, channels, mean, std_, u, up), true;
    case 3: return control_rows<3>(p, S, window, x, channels, mean, std_, u, up), true;
    default: return control_rows<4>(p, S, window, x, channels, mean, std_, u, up), true;
  }
}

}  // namespace fwref

#endif
