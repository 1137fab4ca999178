// src/controls_avx2.cpp -- scope: one row of the int8 CNODE's control codes on AVX2 (fwref/controls_avx2.hpp).
#include "fwref/controls_avx2.hpp"

#if defined(FWREF_HAS_CONTROLS_AVX2)

#include <immintrin.h>

#include <cstring>

#include "fwref/vmath_i8.hpp"

namespace fwref {

namespace {

#define FWREF_C8 inline __attribute__((always_inline))

using vmath_i8_detail::quantize8;
using vmath_i8_detail::tail_mask;

// The per-channel vectors of one quarter (lanes 8i .. 8i + 7 of the C channels).
struct Quarter {
  __m256i m;
  __m256 mean, std_, s_x;
  __m256i acc;
};

FWREF_C8 void add_sample(Quarter& h, const float* xw, __m256i pv) {
  const __m256 y = _mm256_div_ps(_mm256_sub_ps(_mm256_maskload_ps(xw, h.m), h.mean), h.std_);  // normalise
  h.acc = _mm256_add_epi32(h.acc, _mm256_mullo_epi32(pv, quantize8(y, h.s_x)));
}

// Sample w (interpolation weight pw) into the NQ quarters' sums.
template <int NQ>
FWREF_C8 void sample(Quarter* h, const float* xw, std::int32_t pw) {
  const __m256i pv = _mm256_set1_epi32(pw);
  for (int i = 0; i < NQ; ++i) add_sample(h[i], xw + 8 * i, pv);
}

// u and q of lanes 8i .. 8i + n - 1 (n = 1..8).
FWREF_C8 void finish(const Quarter& h, int n, __m256 sp, const float* s_u, float* u, std::int8_t* q) {
  const __m256 uv = _mm256_mul_ps(_mm256_cvtepi32_ps(h.acc), _mm256_mul_ps(sp, h.s_x));  // rescale_i32(acc, s_p, s_x)
  if (u != nullptr) _mm256_maskstore_ps(u, h.m, uv);
  const __m128i c = vmath_i8_detail::pack16(quantize8(uv, _mm256_maskload_ps(s_u, h.m)));
  const std::uint64_t b = static_cast<std::uint64_t>(_mm_cvtsi128_si64(_mm_packs_epi16(c, c)));
  std::memcpy(q, &b, static_cast<std::size_t>(n));  // the n codes only
}

template <int NQ>
bool row(const std::int8_t* p, int window, const float* x, int C, const float* mean, const float* std_,
         const float* s_x, float s_p, const float* s_u, float* u, std::int8_t* q) {
  Quarter h[NQ];
  for (int i = 0; i < NQ; ++i) {  // lanes past C: mean 0, std 0, s_x 0 (their NaN codes are 0; never stored)
    h[i].m = tail_mask(C - 8 * i);
    h[i].mean = _mm256_maskload_ps(mean + 8 * i, h[i].m);
    h[i].std_ = _mm256_maskload_ps(std_ + 8 * i, h[i].m);
    h[i].s_x = _mm256_maskload_ps(s_x + 8 * i, h[i].m);
    h[i].acc = _mm256_setzero_si256();
  }
  for_each_nonzero_avx2(p, window, [&](int w, std::int32_t pw) { sample<NQ>(h, x + long(w) * C, pw); });
  const __m256 sp = _mm256_set1_ps(s_p);
  for (int i = 0; i < NQ; ++i) {
    const int n = C - 8 * i < 8 ? C - 8 * i : 8;
    finish(h[i], n, sp, s_u + 8 * i, u != nullptr ? u + 8 * i : nullptr, q + 8 * i);
  }
  return true;
}

#undef FWREF_C8

}  // namespace

bool control_row_avx2(const std::int8_t* p, int window, const float* x, int channels, const float* mean,
                      const float* std_, const float* s_x, float s_p, const float* s_u, float* u, std::int8_t* q) {
  switch ((channels + 7) / 8) {
    case 1: return channels >= 1 && row<1>(p, window, x, channels, mean, std_, s_x, s_p, s_u, u, q);
    case 2: return row<2>(p, window, x, channels, mean, std_, s_x, s_p, s_u, u, q);
    case 3: return row<3>(p, window, x, channels, mean, std_, s_x, s_p, s_u, u, q);
    case 4: return row<4>(p, window, x, channels, mean, std_, s_x, s_p, s_u, u, q);
    default: return false;
  }
}

}  // namespace fwref

#endif
