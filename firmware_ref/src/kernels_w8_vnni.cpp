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

// NB whole blocks of 16 rows (block j's quads at p + j * 16 * c4, 64 bytes each) and, when TAIL, the last
// nr < 16 rows after them (their quads at p + NB * 16 * c4, 4 * nr bytes each: masked loads, nothing read
// past the block, and a masked store), so that the tail's chain of vpdpbusd runs beside the blocks'
// instead of after them (the CNODE's 40-row lin2 and encoder: two blocks and a tail). Per column quad one
// broadcast of xu's 4 bytes serves every block, the accumulators starting at the rows' corrections.
template <int NB, bool TAIL>
__attribute__((target("avx512f,avx512vnni"))) inline void w8_panel(const std::uint8_t* p, const std::int32_t* corr,
                                                                    int nr, const std::uint8_t* xu, int c4,
                                                                    std::int32_t* acc) {
  const __mmask16 m = TAIL ? static_cast<__mmask16>((1u << nr) - 1) : 0;
  const std::uint8_t* pt = p + 16L * NB * c4;
  __m512i a[NB > 0 ? NB : 1], t = _mm512_setzero_si512();
  for (int j = 0; j < NB; ++j) a[j] = _mm512_loadu_si512(corr + 16 * j);
  if (TAIL) t = _mm512_maskz_loadu_epi32(m, corr + 16 * NB);
  for (int k = 0; k < c4; k += 4) {
    std::int32_t xq;
    std::memcpy(&xq, xu + k, 4);
    const __m512i xb = _mm512_set1_epi32(xq);
    for (int j = 0; j < NB; ++j) a[j] = _mm512_dpbusd_epi32(a[j], xb, _mm512_loadu_si512(p + 16L * j * c4 + 16 * k));
    if (TAIL) t = _mm512_dpbusd_epi32(t, xb, _mm512_maskz_loadu_epi32(m, pt + k * nr));
  }
  for (int j = 0; j < NB; ++j) _mm512_storeu_si512(acc + 16 * j, a[j]);
  if (TAIL) _mm512_mask_storeu_epi32(acc + 16 * NB, m, t);
}

}  // namespace

// Panels of 4 whole blocks, then the last 0..3 whole blocks together with the tail rows, if any.
__attribute__((target("avx512f,avx512vnni"))) void gemv_w8_avx512vnni(const std::uint8_t* w8, int rows, int cols,
                                                                       const std::uint8_t* xu, std::int32_t* acc) {
  const int c4 = w8_cols(cols), blocks = rows / 16, nr = rows % 16;
  const std::int32_t* corr = reinterpret_cast<const std::int32_t*>(w8);
  const std::uint8_t* p = w8 + 4L * rows;
  int b = 0;
  for (; b + 4 <= blocks; b += 4) w8_panel<4, false>(p + 16L * b * c4, corr + 16 * b, 0, xu, c4, acc + 16 * b);
  p += 16L * b * c4, corr += 16 * b, acc += 16 * b;
  switch (4 * (blocks - b) + (nr != 0 ? 1 : 0)) {
    case 13: w8_panel<3, true>(p, corr, nr, xu, c4, acc); break;
    case 12: w8_panel<3, false>(p, corr, nr, xu, c4, acc); break;
    case 9: w8_panel<2, true>(p, corr, nr, xu, c4, acc); break;
    case 8: w8_panel<2, false>(p, corr, nr, xu, c4, acc); break;
    case 5: w8_panel<1, true>(p, corr, nr, xu, c4, acc); break;
    case 4: w8_panel<1, false>(p, corr, nr, xu, c4, acc); break;
    case 1: w8_panel<0, true>(p, corr, nr, xu, c4, acc); break;
    default: break;
  }
}

GemvW8Fn gemv_w8_kernel() {
  return std::strcmp(gemv_i8_kernel_name(), "avx512vnni") == 0 ? gemv_w8_avx512vnni : nullptr;
}

}  // namespace fwref

#endif
