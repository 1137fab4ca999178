// src/w16_product_avx2.hpp -- scope: the product on fwref/kernels_i8.hpp's packed int16 copy with the
// accumulators in ymm registers, shared by the int8 CNODE's AVX2 field (src/field_w16_avx2.cpp) and its
// control rows' folded layers (src/linear_w16_avx2.cpp). Include only from a translation unit compiled for
// AVX2 (the host build whose vector math is AVX2, FWREF_VMATH_AVX2).
#pragma once

#include <immintrin.h>

#include <cstdint>
#include <cstring>

namespace fwref {
namespace w16_avx2_detail {

// acc[j] (rows 8j .. 8j + 7) = sum_c W[r][c] * x16[c] for the int16 copy ``w`` of an (8 NB, cols) matrix,
// cols a multiple of 8 (the copy's stride), NB <= 8: panel 0 holds blocks 0 .. min(NB, 4) - 1, panel 1 (at
// element 32 * cols) the rest; the vector of block j, column pair k of a panel of nb blocks at (k nb + j) * 16
// (fwref/kernels_i8.hpp). Per pair one broadcast of x16's two codes, then per block vpmaddwd + vpaddd.
template <int NB, int COLS>
inline __attribute__((always_inline)) void product(const std::int16_t* w, int cols_rt, const std::int16_t* x16,
                                                   __m256i* acc) {
  const int cols = COLS > 0 ? COLS : cols_rt;
  constexpr int nb0 = NB < 4 ? NB : 4, nb1 = NB - nb0;
  const std::int16_t* const p0 = w;
  const std::int16_t* const p1 = w + 32L * cols;
#pragma GCC unroll 8
  for (int j = 0; j < NB; ++j) acc[j] = _mm256_setzero_si256();  // (a loop GCC would turn into memset: unrolled)
#pragma GCC unroll 4  // (measured: 1 pair per iteration ~25 % slower, 4 and 10 alike)
  for (int k = 0; k < cols / 2; ++k) {
    std::int32_t xp;
    std::memcpy(&xp, x16 + 2 * k, 4);
    const __m256i xb = _mm256_set1_epi32(xp);
#pragma GCC unroll 4
    for (int j = 0; j < nb0; ++j) {
      const __m256i wv = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(p0 + (k * nb0 + j) * 16));
      acc[j] = _mm256_add_epi32(acc[j], _mm256_madd_epi16(xb, wv));
    }
#pragma GCC unroll 4
    for (int j = 0; j < nb1; ++j) {
      const __m256i wv = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(p1 + (k * nb1 + j) * 16));
      acc[nb0 + j] = _mm256_add_epi32(acc[nb0 + j], _mm256_madd_epi16(xb, wv));
    }
  }
}

}  // namespace w16_avx2_detail
}  // namespace fwref
