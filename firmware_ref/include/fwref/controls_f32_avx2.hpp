// fwref/controls_f32_avx2.hpp -- scope: the fp32 CNODE's control rows U on AVX2 + FMA (src/controls_f32_avx2.cpp),
// for the host fp32 path whose run-time choice is avx2field (src/cnode_f32_t.hpp):
//
//   control_rows_f32_avx2(p, S, W, x, C, mean, std, u, up)
//     u[s * up + c] = sum over w with p[s][w] != 0, in increasing w, of p[s][w] * normalise(x[w][c], mean[c], std[c])
//                     (from +0.0f), for s < S, c < C;   u[s * up + c] = +0.0f for C <= c < up
//     up = (C + 7) & ~7 (the rows' stride: U with zero columns up to a whole 8-float packet)
//
// interp_row_f32's operations (src/cnode.cpp) with the C <= 32 channels of a row in up to four ymm registers
// over the row's nonzero weights, instead of a load and store of u per weight: per lane SUBPS, DIVPS, MULPS by
// p, ADDPS, as add_scaled_normalised_n (fwref/vmath_f32.hpp), so the same bits (checked by fwref_vmath
// against interp_row_f32's statement). A sample is read as whole vectors (the lanes past C, the next sample's
// channels, are cleared before the store), or, where those would reach past the window's end, its last packet
// through a masked load.
// Returns false, writing nothing, when C is not in 1..32 or up is not C rounded up to 8.
#pragma once

#include "fwref/field_f32_avx2.hpp"

namespace fwref {

#if defined(FWREF_HAS_F32_FIELD_AVX2)
#define FWREF_HAS_CONTROLS_F32_AVX2 1
bool control_rows_f32_avx2(const float* p, int S, int window, const float* x, int channels, const float* mean,
                           const float* std_, float* u, int up);
#endif

}  // namespace fwref
