// src/kernels_w8_vnni.cpp -- scope: the packed int8 copy of fwref/kernels_w8_vnni.hpp, its
// AVX-512 VNNI kernel (compiled with a target attribute, run only when the run-time choice of
// src/kernels_i8.cpp is avx512vnni) and the layout's portable reference.
#include "fwref/kernels_w8_vnni.hpp"

#if defined(FWREF_HAS_W8_VNNI)

#include <immintrin.h>

#include <cstring>

#include "fwref/kernels_i8.hpp"

namespace fwref {

// Both walk the layout (fwref/kernels_w8_vnni.hpp) block by block: row i of the block at r0 is row
// r0 + i, its byte of column c at block + (c / 4) * 4 * nr + 4 * i + c % 4.
void pack_i8_w8(const std::int8_t* q, int rows, int cols, std::uint8_t* out) {
  const int c4 = w8_cols(cols);
  for (int r0 = 0; r0 < rows; r0 += 16) {
    const int nr = rows - r0 < 16 ? rows - r0 : 16;
    std::uint8_t* block = out + 4L * rows + long(r0) * c4;
    for (int i = 0; i < nr; ++i) {
      const std::int8_t* row = q + long(r0 + i) * cols;
      std::int32_t sum = 0;
      for (int c = 0; c < c4; ++c) {
        const std::int8_t v = c < cols ? row[c] : 0;
        sum += v;
        block[(c / 4) * 4 * nr + 4 * i + c % 4] = static_cast<std::uint8_t>(v);
      }
      const std::int32_t corr = -128 * sum;
      std::memcpy(out + 4L * (r0 + i), &corr, 4);
    }
  }
}

void gemv_w8_portable(const std::uint8_t* w8, int rows, int cols, const std::uint8_t* xu, std::int32_t* acc) {
  const int c4 = w8_cols(cols);
  for (int r0 = 0; r0 < rows; r0 += 16) {
    const int nr = rows - r0 < 16 ? rows - r0 : 16;
    const std::uint8_t* block = w8 + 4L * rows + long(r0) * c4;
    for (int i = 0; i < nr; ++i) {
      std::int32_t s;
      std::memcpy(&s, w8 + 4L * (r0 + i), 4);
      for (int c = 0; c < cols; ++c) {
        s += static_cast<std::int32_t>(static_cast<std::int8_t>(block[(c / 4) * 4 * nr + 4 * i + c % 4])) * xu[c];
      }
      acc[r0 + i] = s;
    }
  }
}

namespace {

// NB whole blocks of 16 rows (block j's quads at p + j * 16 * c4, 64 bytes each): per column quad one
// broadcast of xu's 4 bytes serves NB vpdpbusd, the NB accumulators starting at the rows' corrections.
template <int NB>
__attribute__((target("avx512f,avx512vnni"))) inline void w8_panel(const std::uint8_t* p, const std::int32_t* corr,
                                                                    const std::uint8_t* xu, int c4, std::int32_t* acc) {
  __m512i a[NB];
  for (int j = 0; j < NB; ++j) a[j] = _mm512_loadu_si512(corr + 16 * j);
  for (int k = 0; k < c4; k += 4) {
    std::int32_t xq;
    std::memcpy(&xq, xu + k, 4);
    const __m512i xb = _mm512_set1_epi32(xq);
    for (int j = 0; j < NB; ++j) a[j] = _mm512_dpbusd_epi32(a[j], xb, _mm512_loadu_si512(p + 16L * j * c4 + 16 * k));
  }
  for (int j = 0; j < NB; ++j) _mm512_storeu_si512(acc + 16 * j, a[j]);
}

// The last nr < 16 rows: masked loads (nothing read past the block) and a masked store.
__attribute__((target("avx512f,avx512vnni"))) void w8_tail(const std::uint8_t* p, const std::int32_t* corr, int nr,
                                                            const std::uint8_t* xu, int c4, std::int32_t* acc) {
  const __mmask16 m = static_cast<__mmask16>((1u << nr) - 1);
  __m512i a = _mm512_maskz_loadu_epi32(m, corr);
  for (int k = 0; k < c4; k += 4, p += 4 * nr) {
    std::int32_t xq;
    std::memcpy(&xq, xu + k, 4);
    a = _mm512_dpbusd_epi32(a, _mm512_set1_epi32(xq), _mm512_maskz_loadu_epi32(m, p));
  }
  _mm512_mask_storeu_epi32(acc, m, a);
}

}  // namespace

__attribute__((target("avx512f,avx512vnni"))) void gemv_w8_avx512vnni(const std::uint8_t* w8, int rows, int cols,
                                                                       const std::uint8_t* xu, std::int32_t* acc) {
  const int c4 = w8_cols(cols), blocks = rows / 16;
  const std::int32_t* corr = reinterpret_cast<const std::int32_t*>(w8);
  const std::uint8_t* p = w8 + 4L * rows;
  int b = 0;
  for (; b + 4 <= blocks; b += 4) w8_panel<4>(p + 16L * b * c4, corr + 16 * b, xu, c4, acc + 16 * b);
  switch (blocks - b) {
    case 3: w8_panel<3>(p + 16L * b * c4, corr + 16 * b, xu, c4, acc + 16 * b); break;
    case 2: w8_panel<2>(p + 16L * b * c4, corr + 16 * b, xu, c4, acc + 16 * b); break;
    case 1: w8_panel<1>(p + 16L * b * c4, corr + 16 * b, xu, c4, acc + 16 * b); break;
    default: break;
  }
  if (rows % 16 != 0) w8_tail(p + 16L * blocks * c4, corr + 16 * blocks, rows % 16, xu, c4, acc + 16 * blocks);
}

GemvW8Fn gemv_w8_kernel() {
  return std::strcmp(gemv_i8_kernel_name(), "avx512vnni") == 0 ? gemv_w8_avx512vnni : nullptr;
}

}  // namespace fwref

#endif
