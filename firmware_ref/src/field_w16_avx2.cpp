// src/field_w16_avx2.cpp -- scope: the int8 CNODE field in one call on AVX2 (fwref/field_w16_avx2.hpp),
// run only where the run-time int8 kernel is avx2field (field_w16_avx2_active()).
#include "fwref/field_w16_avx2.hpp"

#if defined(FWREF_HAS_FIELD_W16_AVX2)

#include <immintrin.h>

#include <cstring>

#include "fwref/vmath_i8.hpp"
#include "w16_product_avx2.hpp"

namespace fwref {

namespace {

#define FWREF_W16F inline __attribute__((always_inline))

using vmath_i8_detail::pack16;
using vmath_i8_detail::quantize8;
using w16_avx2_detail::product;

// The hidden layer: hq = quantize(tanh8(f32(acc) * (s_z * s_w1) + v), s_hidden) for NBH blocks of 8, from
// the L = LC (or f.latent) codes zq: rescale_tanh_quantize_n's operations in its order.
template <int NBH, int LC>
FWREF_W16F void hidden(const FieldW16& f, const std::int16_t* zq, __m256 sz, const float* v, std::int16_t* hq) {
  __m256i acc[NBH];
  product<NBH, LC>(f.lin1z, f.latent, zq, acc);
  const __m256 sh = _mm256_set1_ps(f.s_hidden);
  for (int j = 0; j < NBH; ++j) {
    const __m256 m = _mm256_mul_ps(sz, _mm256_loadu_ps(f.s_w1 + 8 * j));  // rescale_i32's f32(s_a * s_w)
    const __m256 y = _mm256_add_ps(_mm256_mul_ps(_mm256_cvtepi32_ps(acc[j]), m), _mm256_loadu_ps(v + 8 * j));
    _mm_store_si128(reinterpret_cast<__m128i*>(hq + 8 * j), pack16(quantize8(tanh8(y), sh)));
  }
}

// k = f32(lin2 hq) * mult2 + b2 for NBL blocks of 8 (rescale_bias_n's operations), H = HC (or f.hidden).
template <int NBL, int HC>
FWREF_W16F void output(const FieldW16& f, const std::int16_t* hq, float* k) {
  __m256i acc[NBL];
  product<NBL, HC>(f.lin2w, f.hidden, hq, acc);
  for (int j = 0; j < NBL; ++j) {
    const __m256 y = _mm256_add_ps(_mm256_mul_ps(_mm256_cvtepi32_ps(acc[j]), _mm256_loadu_ps(f.mult2 + 8 * j)),
                                   _mm256_loadu_ps(f.b2 + 8 * j));
    _mm256_storeu_ps(k + 8 * j, y);
  }
}

// z's codes as int16 (quantize_n's operations), 8 per vector.
FWREF_W16F void quantize_z(const float* z, int L, float s_z, std::int16_t* zq) {
  const __m256 sz = _mm256_set1_ps(s_z);
  for (int i = 0; i < L; i += 8) _mm_store_si128(reinterpret_cast<__m128i*>(zq + i), pack16(quantize8(_mm256_loadu_ps(z + i), sz)));
}

// The paper's shape (H = 64, L = 40) with both products' column counts constant, in one body. (Feeding lin2
// each block of 8 hidden codes as soon as it is quantized, to overlap the next block's tanh, was tried: the
// 8 + 5 accumulators and tanh's temporaries exceed the 16 ymm registers, and the spills made it slower.)
void field_64_40(const FieldW16& f, const float* z, float s_z, const float* v, float* k) {
  alignas(16) std::int16_t zq[40], hq[64];
  quantize_z(z, 40, s_z, zq);
  hidden<8, 40>(f, zq, _mm256_set1_ps(s_z), v, hq);
  output<5, 64>(f, hq, k);
}

template <int NBH>
void hidden_any(const FieldW16& f, const std::int16_t* zq, float s_z, const float* v, std::int16_t* hq) {
  hidden<NBH, 0>(f, zq, _mm256_set1_ps(s_z), v, hq);
}
template <int NBL>
void output_any(const FieldW16& f, const std::int16_t* hq, float* k) {
  output<NBL, 0>(f, hq, k);
}

using HiddenFn = void (*)(const FieldW16&, const std::int16_t*, float, const float*, std::int16_t*);
using OutputFn = void (*)(const FieldW16&, const std::int16_t*, float*);
constexpr HiddenFn kHidden[8] = {hidden_any<1>, hidden_any<2>, hidden_any<3>, hidden_any<4>,
                                 hidden_any<5>, hidden_any<6>, hidden_any<7>, hidden_any<8>};
constexpr OutputFn kOutput[8] = {output_any<1>, output_any<2>, output_any<3>, output_any<4>,
                                 output_any<5>, output_any<6>, output_any<7>, output_any<8>};

#undef FWREF_W16F

}  // namespace

bool field_w16_avx2(const FieldW16& f, const float* z, float s_z, const float* v, float* k) {
  const int H = f.hidden, L = f.latent;
  if (H < 8 || L < 8 || H > 64 || L > 64 || H % 8 != 0 || L % 8 != 0) return false;
  if (H == 64 && L == 40) return field_64_40(f, z, s_z, v, k), true;
  alignas(16) std::int16_t zq[64], hq[64];
  quantize_z(z, L, s_z, zq);
  kHidden[H / 8 - 1](f, zq, s_z, v, hq);
  kOutput[L / 8 - 1](f, hq, k);
  return true;
}

}  // namespace fwref

#endif
