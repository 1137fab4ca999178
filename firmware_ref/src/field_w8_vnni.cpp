// src/field_w8_vnni.cpp -- scope: the int8 CNODE field in one call on AVX-512F + VNNI
// (fwref/field_w8_vnni.hpp): compiled with a target attribute, run only where gemv_w8_kernel() is not null.
#include "fwref/field_w8_vnni.hpp"

#if defined(FWREF_HAS_W8_VNNI)

// GCC 12's false "may be used uninitialized" inside the intrinsics' headers (GCC bug 105593), as in
// src/kernels_f32_avx512.cpp: silenced for this file only.
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
#include <immintrin.h>

#include "fwref/tanh16_avx512.hpp"

#include <cstring>

namespace fwref {

namespace {

#define FWREF_W8F __attribute__((target("avx512f,avx512vnni"), always_inline)) inline

// Lanes [0, n) of 16 (n >= 16: all).
FWREF_W8F __mmask16 lanes(int n) { return static_cast<__mmask16>(n >= 16 ? 0xffffu : (1u << n) - 1u); }

// fwref/vmath_i8.hpp's quantize8 on 16 lanes: DIVPS, NaN -> +0, MAXPS -128, MINPS 127, VCVTPS2DQ (MXCSR's
// round to nearest even); then the code + 128 as the u8 vpdpbusd multiplies (16 bytes).
FWREF_W8F __m128i quantize_u8(__m512 x, __m512 scale) {
  __m512 v = _mm512_div_ps(x, scale);
  v = _mm512_maskz_mov_ps(_mm512_cmp_ps_mask(v, v, _CMP_ORD_Q), v);
  v = _mm512_max_ps(v, _mm512_set1_ps(-128.0f));
  v = _mm512_min_ps(v, _mm512_set1_ps(127.0f));
  return _mm512_cvtepi32_epi8(_mm512_add_epi32(_mm512_cvtps_epi32(v), _mm512_set1_epi32(128)));
}

// acc[j] (block j: rows 16j .. 16j + 15) = sum_c W[r][c] * (x[c] + 128) + corr[r] over the packed copy w8 of a
// (rows, cols) matrix (fwref/kernels_w8_vnni.hpp's layout; NB blocks, the last with rows - 16 (NB - 1) rows
// through masked loads), xu: the w8_cols(cols) offset codes. Two chains per block over even / odd column quads.
template <int NB, int COLS>
FWREF_W8F void product(const std::uint8_t* w8, int rows, int cols_rt, const std::uint8_t* xu, __m512i* acc) {
  const int cols = COLS > 0 ? COLS : cols_rt;
  const int c4 = w8_cols(cols), nr = rows - 16 * (NB - 1);
  const __mmask16 m = lanes(nr);
  const std::uint8_t* p = w8 + 4L * rows;
  const std::uint8_t* pt = p + 16L * (NB - 1) * c4;  // the last block: quads of 4 * nr bytes
  __m512i odd[NB];
  for (int j = 0; j < NB; ++j) odd[j] = _mm512_setzero_si512();
  for (int j = 0; j + 1 < NB; ++j) acc[j] = _mm512_loadu_si512(w8 + 64L * j);
  acc[NB - 1] = _mm512_maskz_loadu_epi32(m, w8 + 64L * (NB - 1));
  int k = 0;
  for (; k + 8 <= c4; k += 8) {
    std::int32_t x0, x1;
    std::memcpy(&x0, xu + k, 4);
    std::memcpy(&x1, xu + k + 4, 4);
    const __m512i b0 = _mm512_set1_epi32(x0), b1 = _mm512_set1_epi32(x1);
    for (int j = 0; j + 1 < NB; ++j) {
      acc[j] = _mm512_dpbusd_epi32(acc[j], b0, _mm512_loadu_si512(p + 16L * j * c4 + 16 * k));
      odd[j] = _mm512_dpbusd_epi32(odd[j], b1, _mm512_loadu_si512(p + 16L * j * c4 + 16 * k + 64));
    }
    acc[NB - 1] = _mm512_dpbusd_epi32(acc[NB - 1], b0, _mm512_maskz_loadu_epi32(m, pt + k * nr));
    odd[NB - 1] = _mm512_dpbusd_epi32(odd[NB - 1], b1, _mm512_maskz_loadu_epi32(m, pt + (k + 4) * nr));
  }
  if (k < c4) {
    std::int32_t x0;
    std::memcpy(&x0, xu + k, 4);
    const __m512i b0 = _mm512_set1_epi32(x0);
    for (int j = 0; j + 1 < NB; ++j) acc[j] = _mm512_dpbusd_epi32(acc[j], b0, _mm512_loadu_si512(p + 16L * j * c4 + 16 * k));
    acc[NB - 1] = _mm512_dpbusd_epi32(acc[NB - 1], b0, _mm512_maskz_loadu_epi32(m, pt + k * nr));
  }
  for (int j = 0; j < NB; ++j) acc[j] = _mm512_add_epi32(acc[j], odd[j]);
}

// NBL blocks of the latent (L) and NBH of the hidden layer (H).
template <int NBH, int NBL, int HC = 0, int LC = 0>
__attribute__((target("avx512f,avx512vnni"))) void field(const FieldW8& f, const float* z, float s_z, const float* v,
                                                         float* k) {
  const int H = HC > 0 ? HC : f.hidden, L = LC > 0 ? LC : f.latent;
  alignas(64) std::uint8_t xz[64], xh[64];  // the offset codes of z and of the hidden layer
  const __m512 sz = _mm512_set1_ps(s_z);
  for (int j = 0; j < NBL; ++j) {
    const __m512 x = _mm512_maskz_loadu_ps(lanes(L - 16 * j), z + 16 * j);  // lanes past L: code 0, zero weights
    _mm_store_si128(reinterpret_cast<__m128i*>(xz + 16 * j), quantize_u8(x, sz));
  }
  __m512i acc[NBH > NBL ? NBH : NBL];
  product<NBH, LC>(f.lin1z, H, L, xz, acc);
  const __m512 sh = _mm512_set1_ps(f.s_hidden);
  for (int j = 0; j < NBH; ++j) {
    const __mmask16 m = lanes(H - 16 * j);
    const __m512 mult = _mm512_mul_ps(sz, _mm512_maskz_loadu_ps(m, f.s_w1 + 16 * j));  // f32(s_z * s_w)
    const __m512 y = _mm512_add_ps(_mm512_mul_ps(_mm512_cvtepi32_ps(acc[j]), mult), _mm512_maskz_loadu_ps(m, v + 16 * j));
    _mm_store_si128(reinterpret_cast<__m128i*>(xh + 16 * j), quantize_u8(tanh16(y), sh));
  }
  product<NBL, HC>(f.lin2w, L, H, xh, acc);
  for (int j = 0; j < NBL; ++j) {
    const int left = L - 16 * j;
    const __mmask16 m = lanes(left);
    const __m512 y = _mm512_add_ps(_mm512_mul_ps(_mm512_cvtepi32_ps(acc[j]), _mm512_maskz_loadu_ps(m, f.mult2 + 16 * j)),
                                   _mm512_maskz_loadu_ps(m, f.b2 + 16 * j));
    if (left >= 16) {
      _mm512_storeu_ps(k + 16 * j, y);  // plain stores where whole (a masked store is not forwarded to a load)
    } else if (left == 8) {
      _mm256_storeu_ps(k + 16 * j, _mm512_castps512_ps256(y));
    } else {
      _mm512_mask_storeu_ps(k + 16 * j, m, y);
    }
  }
}

#undef FWREF_W8F

using FieldFn = void (*)(const FieldW8&, const float*, float, const float*, float*);
constexpr FieldFn kFields[4][4] = {{field<1, 1>, field<1, 2>, field<1, 3>, field<1, 4>},
                                   {field<2, 1>, field<2, 2>, field<2, 3>, field<2, 4>},
                                   {field<3, 1>, field<3, 2>, field<3, 3>, field<3, 4>},
                                   {field<4, 1>, field<4, 2>, field<4, 3>, field<4, 4>}};

}  // namespace

bool field_w8_avx512vnni(const FieldW8& f, const float* z, float s_z, const float* v, float* k) {
  if (f.hidden < 1 || f.latent < 1 || f.hidden > 64 || f.latent > 64) return false;
  if (f.hidden == 64 && f.latent == 40) return field<4, 3, 64, 40>(f, z, s_z, v, k), true;  // the paper's shape
  kFields[(f.hidden - 1) / 16][(f.latent - 1) / 16](f, z, s_z, v, k);
  return true;
}

}  // namespace fwref

#endif
