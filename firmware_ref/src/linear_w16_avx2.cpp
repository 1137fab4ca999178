// src/linear_w16_avx2.cpp -- scope: a folded int8 linear layer on several code vectors in one call on AVX2
// (fwref/linear_w16_avx2.hpp).
#include "fwref/linear_w16_avx2.hpp"

#if defined(FWREF_HAS_LINEAR_W16_AVX2)

#include <immintrin.h>

#include <cstring>

#include "w16_product_avx2.hpp"

namespace fwref {

namespace {

// x16 = the cols (<= 32) codes of x sign-extended to int16, zero up to 32 (the copy's padding columns
// multiply these zeros; the product reads w16_stride(cols) of them).
inline void widen(const std::int8_t* x, int cols, std::int16_t* x16) {
  alignas(32) std::int8_t b[32] = {};
  std::memcpy(b, x, static_cast<std::size_t>(cols));
  const __m128i lo = _mm_load_si128(reinterpret_cast<const __m128i*>(b));
  const __m128i hi = _mm_load_si128(reinterpret_cast<const __m128i*>(b + 16));
  _mm256_store_si256(reinterpret_cast<__m256i*>(x16), _mm256_cvtepi8_epi16(lo));
  _mm256_store_si256(reinterpret_cast<__m256i*>(x16 + 16), _mm256_cvtepi8_epi16(hi));
}

// NB blocks of 8 rows, COLS the copy's stride (0: cols_rt's, at run time).
template <int NB, int COLS>
void rows_of(const std::int16_t* w16, int cols, const std::int8_t* x, int n, const float* s_w, const float* b,
             float* y) {
  const int stride = w16_stride(cols);
  alignas(32) std::int16_t x16[32];
  for (int s = 0; s < n; ++s, x += cols, y += 8 * NB) {
    widen(x, cols, x16);
    __m256i acc[NB];
    w16_avx2_detail::product<NB, COLS>(w16, stride, x16, acc);
    for (int j = 0; j < NB; ++j) {  // (f32(acc) * s_w) + b: linear_i8_folded's order
      const __m256 p = _mm256_mul_ps(_mm256_cvtepi32_ps(acc[j]), _mm256_loadu_ps(s_w + 8 * j));
      _mm256_storeu_ps(y + 8 * j, _mm256_add_ps(p, _mm256_loadu_ps(b + 8 * j)));
    }
  }
}

using RowsFn = void (*)(const std::int16_t*, int, const std::int8_t*, int, const float*, const float*, float*);
constexpr RowsFn kRows[8] = {rows_of<1, 0>, rows_of<2, 0>, rows_of<3, 0>, rows_of<4, 0>,
                             rows_of<5, 0>, rows_of<6, 0>, rows_of<7, 0>, rows_of<8, 0>};

}  // namespace

bool linear_folded_w16_avx2(const std::int16_t* w16, int rows, int cols, const std::int8_t* x, int n,
                            const float* s_w, const float* b, float* y) {
  if (rows < 8 || rows > 64 || rows % 8 != 0 || cols < 1 || cols > 32 || n < 0) return false;
  if (rows == 64 && w16_stride(cols) == 24) return rows_of<8, 24>(w16, cols, x, n, s_w, b, y), true;  // the paper's lin1_u
  kRows[rows / 8 - 1](w16, cols, x, n, s_w, b, y);
  return true;
}

}  // namespace fwref

#endif
