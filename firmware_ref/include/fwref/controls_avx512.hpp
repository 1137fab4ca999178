// fwref/controls_avx512.hpp -- scope: one row of the int8 CNODE's quantized control samples on AVX-512F
// (src/controls_avx512.cpp), for the host VNNI path (src/cnode_w8.cpp):
//
//   control_row_avx512(p, W, x, C, mean, std, s_x, s_p, s_u, u, q)
//     acc[c] = sum over w with p[w] != 0 of p[w] * quantize(normalise(x[w][c], mean[c], std[c]), s_x[c])
//     u[c]   = rescale_i32(acc[c], s_p, s_x[c])   (u may be null)
//     q[c]   = quantize(u[c], s_u[c])             for c < C
//
// what cnode_controls.hpp's quantize_stage_controls does per row with fwref/vmath_i8.hpp's
// for_each_nonzero, accumulate_codes and rescale_quantize_row, with the C <= 32 channels in two 16-lane
// registers (the int32 sums held there over the row's nonzero weights instead of read and written back
// per weight, and no overlapping last vector, whose partly overlapping reload of a just-stored vector
// waited for the store). Per lane the same float32 operations in the same order (SUBPS, DIVPS; the
// quantize of vmath_i8.hpp's quantize8: DIVPS, NaN -> +0, MAXPS / MINPS, VCVTPS2DQ; VPMULLD and VPADDD on
// exact int32; VCVTDQ2PS, MULPS of f32(s_p * s_x), MULPS), so the same codes and floats (checked by
// fwref_vmath against the AVX2 helpers). Returns false, writing nothing, when C > 32. Run only on a
// CPU with AVX-512F (the VNNI path's condition includes it).
#pragma once

#include <cstdint>

namespace fwref {

#if defined(__x86_64__) && !defined(FWREF_PORTABLE_KERNELS)
#define FWREF_HAS_CONTROLS_AVX512 1
bool control_row_avx512(const std::int8_t* p, int window, const float* x, int channels, const float* mean,
                        const float* std_, const float* s_x, float s_p, const float* s_u, float* u, std::int8_t* q);
#endif

}  // namespace fwref
