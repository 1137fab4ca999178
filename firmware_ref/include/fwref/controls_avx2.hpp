// fwref/controls_avx2.hpp -- scope: one row of the int8 CNODE's quantized control samples on AVX2
// (src/controls_avx2.cpp), for the host int8 path whose run-time kernel is avx2field (cnode_controls.hpp):
//
//   control_row_avx2(p, W, x, C, mean, std, s_x, s_p, s_u, u, q)
//     acc[c] = sum over w with p[w] != 0 of p[w] * quantize(normalise(x[w][c], mean[c], std[c]), s_x[c])
//     u[c]   = rescale_i32(acc[c], s_p, s_x[c])   (u may be null)
//     q[c]   = quantize(u[c], s_u[c])             for c < C
//
// control_row_avx512's treatment (fwref/controls_avx512.hpp) on 8-lane vectors: the C <= 32 channels in up
// to four ymm registers, the int32 sums held there over the row's nonzero weights instead of read and
// written back per weight by accumulate_codes, whose last, overlapping vector (C = 23: lanes 15..22) re-read
// a vector just stored and waited for that store. Per lane the same float32 operations in the same order
// (SUBPS, DIVPS; vmath_i8.hpp's quantize8; VPMULLD and VPADDD on exact int32; VCVTDQ2PS, MULPS of
// f32(s_p * s_x), MULPS), so the same codes and floats (checked by fwref_vmath against the helpers). Lanes
// past C load zeros (maskload) and are never stored. Returns false, writing nothing, when C > 32.
#pragma once

#include <cstdint>

#include "fwref/vmath_f32.hpp"

namespace fwref {

#if defined(FWREF_VMATH_AVX2) && defined(__x86_64__)
#define FWREF_HAS_CONTROLS_AVX2 1
bool control_row_avx2(const std::int8_t* p, int window, const float* x, int channels, const float* mean,
                      const float* std_, const float* s_x, float s_p, const float* s_u, float* u, std::int8_t* q);
#endif

}  // namespace fwref
