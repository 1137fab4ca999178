// fwref/tanh16_avx512.hpp -- scope: tanh_approx (fwref/numerics.hpp) on 16 lanes for the host's AVX-512F
// kernels (src/kernels_f32_avx512.cpp's fp32 field, src/field_w8_vnni.cpp's int8 one): vmath_f32.hpp's
// tanh8, the same operations per lane, so the same bits (fwref_vmath's field_t check compares the fp32
// field, tanh16 included, with tanh8 bit for bit). Compiled through a target attribute: include it only
// in host code that runs it after a run-time check of the CPU.
#pragma once

#if defined(__x86_64__)
#include <immintrin.h>

namespace fwref {

__attribute__((target("avx512f"), always_inline)) inline __m512 tanh16(__m512 x) {
  x = _mm512_max_ps(_mm512_set1_ps(-9.0f), x);  // (-9 > x) ? -9 : x, NaN kept (MAXPS returns the 2nd operand)
  x = _mm512_min_ps(_mm512_set1_ps(9.0f), x);
  const __m512 x2 = _mm512_mul_ps(x, x);
  __m512 p = _mm512_fmadd_ps(x2, _mm512_set1_ps(-2.76076847742355e-16f), _mm512_set1_ps(2.00018790482477e-13f));
  p = _mm512_fmadd_ps(p, x2, _mm512_set1_ps(-8.60467152213735e-11f));
  p = _mm512_fmadd_ps(p, x2, _mm512_set1_ps(5.12229709037114e-08f));
  p = _mm512_fmadd_ps(p, x2, _mm512_set1_ps(1.48572235717979e-05f));
  p = _mm512_fmadd_ps(p, x2, _mm512_set1_ps(6.37261928875436e-04f));
  p = _mm512_fmadd_ps(p, x2, _mm512_set1_ps(4.89352455891786e-03f));
  p = _mm512_mul_ps(p, x);
  __m512 q = _mm512_fmadd_ps(x2, _mm512_set1_ps(1.19825839466702e-06f), _mm512_set1_ps(1.18534705686654e-04f));
  q = _mm512_fmadd_ps(q, x2, _mm512_set1_ps(2.26843463243900e-03f));
  q = _mm512_fmadd_ps(q, x2, _mm512_set1_ps(4.89352518554385e-03f));
  return _mm512_div_ps(p, q);
}

}  // namespace fwref
#endif
