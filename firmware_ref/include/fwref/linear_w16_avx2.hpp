// fwref/linear_w16_avx2.hpp -- scope: a folded int8 linear layer (pattern B) applied to several int8 code
// vectors in one call on AVX2, on the layer's packed int16 copy (fwref/kernels_i8.hpp's x86-64 layout), for
// the int8 CNODE's control path on a host whose run-time int8 kernel is avx2field (src/cnode.cpp's
// lin1_u_rows: V[s] = lin1_u uq[s] + b1 for the S stage times; src/linear_w16_avx2.cpp):
//
//   linear_folded_w16_avx2(w16, rows, cols, x, n, s_w, b, y)
//     y[s][o] = (f32(sum_c W[o][c] * x[s][c]) * s_w[o]) + b[o]        for s < n, o < rows
//
// linear_i8_folded's operations (fwref/numerics.hpp) per element in its order: the sum exact in int32
// (vpmaddwd on the sign-extended codes and weights, as gemv_w16_avx2; |acc| < 2^24, fwref/config.hpp), then
// VCVTDQ2PS, MULPS, ADDPS (no FMA), so y is the same bits as linear_i8_folded with any int8 kernel. What it
// saves against that path: per vector the codes widened by two VPMOVSXBW instead of a scalar loop, the
// accumulators kept in ymm registers (no store and reload), the rescale done on them, and no indirect call.
// rows must be a multiple of 8 in 8..64 and cols in 1..32, else false and nothing is written (the caller
// then runs linear_i8_folded). x is (n, cols) row-major int8, y (n, rows) row-major float32.
#pragma once

#include <cstdint>

#include "fwref/field_w16_avx2.hpp"

namespace fwref {

#if defined(FWREF_HAS_FIELD_W16_AVX2)
#define FWREF_HAS_LINEAR_W16_AVX2 1
bool linear_folded_w16_avx2(const std::int16_t* w16, int rows, int cols, const std::int8_t* x, int n,
                            const float* s_w, const float* b, float* y);
#endif

}  // namespace fwref
