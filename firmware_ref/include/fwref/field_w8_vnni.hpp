// fwref/field_w8_vnni.hpp -- scope: one evaluation of the int8 CNODE's vector field in one call on an
// x86-64 host whose run-time int8 kernel is avx512vnni (src/cnode_w8.cpp's field; src/field_w8_vnni.cpp):
//
//   field_w8_avx512vnni(f, z, s_z, v, k)
//     zq   = quantize(z, s_z)                                           (L codes)
//     hq   = quantize(tanh_approx(f32(lin1_z zq) * f32(s_z * s_w1) + v), s_hidden)   (H codes)
//     k    = f32(lin2 hq) * mult2 + b2                                  (L floats)
//
// the operations of quantize_n, gemv_w8_codes (lin1_z), rescale_tanh_quantize_n, gemv_w8_codes (lin2)
// and rescale_bias_n (fwref/vmath_i8.hpp, fwref/kernels_w8_vnni.hpp) per element in the same order, on
// 16 lanes, with the codes, the accumulators and the hidden layer in registers: the products are
// exact integers, every float operation is the same IEEE float32 operation as there (VCVTDQ2PS,
// MULPS, ADDPS, vmath_f32's tanh8 on 16 lanes, DIVPS, the NaN -> +0 mask, MAXPS / MINPS with
// -128 / 127, VCVTPS2DQ in MXCSR's default round-to-nearest-even), so k is the same bits (checked by
// fwref_vmath against the separate steps for every H, L in 1..64). The weights are the packed int8
// copies of fwref/kernels_w8_vnni.hpp (the rows' -128 * sum corrections first); each product runs
// ``kChains`` chains of vpdpbusd per 16-row block over alternate column quads, summed at the end (an
// int32 sum: exact, any order). z and k may be the same array (z is read before k is written).
//
// H and L must be in 1..64 (the paper's 64 and 40), else false and nothing is written: the caller then
// runs the separate steps. Only where gemv_w8_kernel() is not null (the CPU runs AVX-512F + VNNI).
#pragma once

#include <cstdint>

#include "fwref/field_i8.hpp"
#include "fwref/kernels_w8_vnni.hpp"

namespace fwref {

#if defined(FWREF_HAS_W8_VNNI)
using FieldW8 = FieldI8<std::uint8_t>;  // lin1z, lin2w: pack_i8_w8 copies

bool field_w8_avx512vnni(const FieldW8& f, const float* z, float s_z, const float* v, float* k);
#endif

}  // namespace fwref
