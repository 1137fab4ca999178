// fwref/field_w16_avx2.hpp -- scope: one evaluation of the int8 CNODE's vector field in one call on an
// x86-64 host whose run-time int8 kernel is avx2field (the best choice of an AVX2 CPU without AVX-512
// VNNI; src/field_w16_avx2.cpp), on the int16 copies of lin1_z and lin2 that src/cnode.cpp's int8 path
// already makes (fwref/kernels_i8.hpp's x86-64 layout, FWREF_CNODE_W_INT16):
//
//   field_w16_avx2(f, z, s_z, v, k)
//     zq   = quantize(z, s_z)                                                        (L codes)
//     hq   = quantize(tanh_approx(f32(lin1_z zq) * f32(s_z * s_w1) + v), s_hidden)   (H codes)
//     k    = f32(lin2 hq) * mult2 + b2                                               (L floats)
//
// the operations of src/cnode.cpp's field with FWREF_I8_KERNEL=avx2 (quantize_n, gemv_w16_avx2 on lin1_z,
// rescale_tanh_quantize_n, gemv_w16_avx2 on lin2, rescale_bias_n: fwref/vmath_i8.hpp) per element in the
// same order, on 8 lanes, with the accumulators and the hidden layer in ymm registers and the codes in
// two 128-byte stack buffers (one vpbroadcastd per column pair serves every 8-row block). The products are
// exact: vpmaddwd multiplies the sign-extended int16 codes and weights and adds each pair in int32, as
// gemv_w16_avx2 does (|acc| < 2^24, fwref/config.hpp). Every float operation is the same IEEE float32
// operation as there (VCVTDQ2PS, MULPS, ADDPS, vmath_f32's tanh8, quantize8: DIVPS, the NaN -> +0 mask,
// MAXPS / MINPS with -128 / 127, VCVTPS2DQ in MXCSR's default round-to-nearest-even), so k is the same
// bits (checked by fwref_vmath against the separate steps for every H, L multiple of 8 up to 64, and by
// tests/test_firmware.py on whole models). z and k may be the same array (z is read before k is written).
//
// H and L must be multiples of 8 in 8..64 (the paper's 64 and 40; the int16 copy keeps rows past the last
// whole block of 8 row-major), else false and nothing is written: the caller then runs the separate steps.
// Only in a build whose vector math is AVX2 + FMA (FWREF_VMATH_AVX2) with the int16 copies; chosen at run
// time by fwref/kernels_i8.hpp's dispatch (field_w16_avx2_active(); FWREF_I8_KERNEL=avx2 keeps the
// separate steps, portable the reference loops).
#pragma once

#include <cstdint>

#include "fwref/field_i8.hpp"
#include "fwref/kernels_i8.hpp"
#include "fwref/vmath_f32.hpp"

namespace fwref {

#if defined(__x86_64__) && defined(FWREF_VMATH_AVX2) && defined(FWREF_HAS_W16_KERNEL) && \
    defined(FWREF_CNODE_W_INT16) && !defined(FWREF_PORTABLE_KERNELS)
#define FWREF_HAS_FIELD_W16_AVX2 1
using FieldW16 = FieldI8<std::int16_t>;  // lin1z, lin2w: expand_i8_to_i16 copies

bool field_w16_avx2(const FieldW16& f, const float* z, float s_z, const float* v, float* k);
// True when the run-time int8 kernel is avx2field (src/kernels_i8.cpp).
bool field_w16_avx2_active();
#endif

}  // namespace fwref
