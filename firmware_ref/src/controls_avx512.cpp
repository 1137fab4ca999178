// src/controls_avx512.cpp -- scope: one row of the int8 CNODE's control codes on AVX-512F
// (fwref/controls_avx512.hpp), compiled with a target attribute.
#include "fwref/controls_avx512.hpp"

#if defined(FWREF_HAS_CONTROLS_AVX512)

#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"  // GCC bug 105593, as in src/kernels_f32_avx512.cpp
#pragma GCC diagnostic ignored "-Wuninitialized"
#include <immintrin.h>

#include "fwref/vmath_i8.hpp"

namespace fwref {

namespace {

#define FWREF_C16 __attribute__((target("avx2,avx512f"), always_inline)) inline

FWREF_C16 __mmask16 lanes(int n) { return static_cast<__mmask16>(n >= 16 ? 0xffffu : n <= 0 ? 0u : (1u << n) - 1u); }

// fwref/vmath_i8.hpp's quantize8 on 16 lanes: the codes as int32.
FWREF_C16 __m512i quantize16(__m512 x, __m512 scale) {
  __m512 v = _mm512_div_ps(x, scale);
  v = _mm512_maskz_mov_ps(_mm512_cmp_ps_mask(v, v, _CMP_ORD_Q), v);
  v = _mm512_max_ps(v, _mm512_set1_ps(-128.0f));
  v = _mm512_min_ps(v, _mm512_set1_ps(127.0f));
  return _mm512_cvtps_epi32(v);
}

// The per-channel vectors of one half (lanes 16h .. 16h + 15 of the C channels).
struct Half {
  __mmask16 m;
  __m512 mean, std_, s_x;
  __m512i acc;
};

FWREF_C16 void add_sample(Half& h, const float* xw, __m512i pv) {
  const __m512 y = _mm512_div_ps(_mm512_sub_ps(_mm512_maskz_loadu_ps(h.m, xw), h.mean), h.std_);  // normalise
  h.acc = _mm512_add_epi32(h.acc, _mm512_mullo_epi32(pv, quantize16(y, h.s_x)));
}

// Sample w of the window (interpolation weight pw) into both halves' sums.
FWREF_C16 void sample(Half* h, bool two, const float* xw, std::int32_t pw) {
  const __m512i pv = _mm512_set1_epi32(pw);
  add_sample(h[0], xw, pv);
  if (two) add_sample(h[1], xw + 16, pv);
}

FWREF_C16 void finish(const Half& h, __m512 sp, const float* s_u, float* u, std::int8_t* q) {
  const __m512 uv = _mm512_mul_ps(_mm512_cvtepi32_ps(h.acc), _mm512_mul_ps(sp, h.s_x));  // rescale_i32(acc, s_p, s_x)
  if (u != nullptr) _mm512_mask_storeu_ps(u, h.m, uv);
  _mm512_mask_cvtepi32_storeu_epi8(q, h.m, quantize16(uv, _mm512_maskz_loadu_ps(h.m, s_u)));
}

}  // namespace

__attribute__((target("avx2,avx512f"))) bool control_row_avx512(const std::int8_t* p, int window, const float* x,
                                                               int channels, const float* mean, const float* std_,
                                                               const float* s_x, float s_p, const float* s_u, float* u,
                                                               std::int8_t* q) {
  if (channels < 1 || channels > 32) return false;
  Half h[2];
  for (int i = 0; i < 2; ++i) {  // lanes past C: mean 0, std 0, s_x 0 (their NaN codes are 0; never stored)
    h[i].m = lanes(channels - 16 * i);
    h[i].mean = _mm512_maskz_loadu_ps(h[i].m, mean + 16 * i);
    h[i].std_ = _mm512_maskz_loadu_ps(h[i].m, std_ + 16 * i);
    h[i].s_x = _mm512_maskz_loadu_ps(h[i].m, s_x + 16 * i);
    h[i].acc = _mm512_setzero_si512();
  }
  const bool two = channels > 16;
  for_each_nonzero_avx2(p, window, [&](int w, std::int32_t pw) __attribute__((target("avx2,avx512f"))) {
    sample(h, two, x + long(w) * channels, pw);
  });
  const __m512 sp = _mm512_set1_ps(s_p);
  finish(h[0], sp, s_u, u, q);
  if (two) finish(h[1], sp, s_u + 16, u != nullptr ? u + 16 : nullptr, q + 16);
  return true;
}

#undef FWREF_C16

}  // namespace fwref

#endif
