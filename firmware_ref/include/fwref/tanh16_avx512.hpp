// fwref/tanh16_avx512.hpp -- scope: tanh_approx (fwref/numerics.hpp) on 16 lanes for the host's AVX-512F
// kernels (src/kernels_f32_avx512.cpp's fp32 field, src/field_w8_vnni.cpp's int8 one): vmath_f32.hpp's
// tanh8, the same operations per lane, so the same bits (fwref_vmath's field_t check compares the fp32
// field, tanh16 included, with tanh8 bit for bit). Compiled through a target attribute: include it only
// in host code that runs it after a run-time check of the CPU.
#pragma once

#if defined(__x86_64__)
#include <immintrin.h>

#include "fwref/numerics.hpp"

namespace fwref {

__attribute__((target("avx512f"), always_inline)) inline __m512 tanh16(__m512 x) {
  x = _mm512_max_ps(_mm512_set1_ps(-9.0f), x);  // (-9 > x) ? -9 : x, NaN kept (MAXPS returns the 2nd operand)
  x = _mm512_min_ps(_mm512_set1_ps(9.0f), x);
  using T = TanhRational;  // numerics.hpp: the one coefficient table of tanh_approx
  const __m512 x2 = _mm512_mul_ps(x, x);
  __m512 p = _mm512_fmadd_ps(x2, _mm512_set1_ps(T::p[0]), _mm512_set1_ps(T::p[1]));
  p = _mm512_fmadd_ps(p, x2, _mm512_set1_ps(T::p[2]));
  p = _mm512_fmadd_ps(p, x2, _mm512_set1_ps(T::p[3]));
  p = _mm512_fmadd_ps(p, x2, _mm512_set1_ps(T::p[4]));
  p = _mm512_fmadd_ps(p, x2, _mm512_set1_ps(T::p[5]));
  p = _mm512_fmadd_ps(p, x2, _mm512_set1_ps(T::p[6]));
  p = _mm512_mul_ps(p, x);
  __m512 q = _mm512_fmadd_ps(x2, _mm512_set1_ps(T::q[0]), _mm512_set1_ps(T::q[1]));
  q = _mm512_fmadd_ps(q, x2, _mm512_set1_ps(T::q[2]));
  q = _mm512_fmadd_ps(q, x2, _mm512_set1_ps(T::q[3]));
  return _mm512_div_ps(p, q);
}

}  // namespace fwref
#endif
