// fwref/field_f32_avx2.hpp -- scope: the fp32 CNODE's vector field in one call on an x86-64 host whose fp32
// choice is avx2field (the default of an AVX2 + FMA CPU without AVX-512F; src/field_f32_avx2.cpp), on the
// column-major copies of lin1_z and lin2 (pack_f32_t, fwref/kernels_f32_avx512.hpp: column i at
// wt + i * f32_t_stride(rows), rows padded with zeros to a multiple of 16, 32-byte aligned at least):
//
//   field_f32_t_avx2(w1t, w2t, H, L, z, v, b2, k)
//     a = tanh_approx(lin1_z z + v)      (H, the hidden vector in ymm registers, then a 256-byte buffer)
//     k = lin2 a + b2                    (L)
//
// 8 rows per ymm block (nb = ceil(rows / 8) blocks per product), each column's x[i] broadcast to the nb
// blocks, C = chains(nb) FMA chains per row (1 when nb >= 6, 2 when nb is 3..5, else 4: enough independent
// chains to cover the FMA latency without more accumulators than the 16 ymm registers hold). Summation
// order of each product (checked bit for bit by fwref_vmath against a scalar statement of it):
//   s_p = fma(w[o][i], x[i], s_p) for i = p + C, p + 2C, ... < cols, from s_p = w[o][p] x[p] (p < cols;
//   s_p = +0 for p >= cols); y[o] = s_0 (C = 1), s_0 + s_1 (C = 2), (s_0 + s_1) + (s_2 + s_3) (C = 4);
//   then y[o] + b[o] (b = v for lin1_z, b2 for lin2); tanh_approx is vmath_f32.hpp's tanh8 (bit-identical).
// Error: |y[o] - sum_i w[o][i] x[i]| <= gamma(ceil(cols / C) + log2 C) * sum_i |w[o][i] x[i]|. The order
// differs from gemv_f32_fma's (8 lanes, 3 folds, what FWREF_F32_KERNEL=avx2 runs) in the last bits, within
// the fp32 tolerance (core/contracts.py FP32_CPP_REL_TOL; `quadfdi parity`); it depends only on the
// shape, so every AVX2 + FMA host gives the same bits. H, L in 1..64 (the paper's 64 and 40), else false
// and nothing written. z and k may be the same array (z is read before k is written).
//
//   field_f32_avx2_active()   true when src/cnode.cpp's fp32 field runs it: the CPU has AVX2 + FMA and
//                             FWREF_F32_KERNEL is "avx2field", or is neither "avx2" nor a chosen "avx512"
//                             (AVX-512F CPUs default to the 16-lane field); switched by gemv_f32_select
#pragma once

#include "fwref/kernels_f32_avx512.hpp"
#include "fwref/vmath_f32.hpp"

#if defined(FWREF_HAS_F32_AVX512) && defined(FWREF_VMATH_AVX2)
#define FWREF_HAS_F32_FIELD_AVX2 1

namespace fwref {

bool field_f32_t_avx2(const float* w1t, const float* w2t, int H, int L, const float* z, const float* v,
                      const float* b2, float* k);
bool field_f32_avx2_active();

namespace detail {
// gemv_f32_select's switch (src/kernels_f32_avx512.cpp): on only where the CPU runs it; returns the state.
bool field_f32_avx2_set(bool on);
}  // namespace detail

}  // namespace fwref
#endif
