// fwref/vmath_gru_i8.hpp -- scope: the host's per-element int8 work of one GRU time step on 8 lanes
// per AVX2 vector, bit-identical per element to the scalar code it replaces (src/gru.cpp's portable
// path: linear_i8_folded / linear_i8_tensor's rescale, gru_cell, quantize of fwref/numerics.hpp):
//
//   normalise_quantize_row(x, mean, std, s_x, n, xn, q)
//       xn[i] = normalise(x[i], mean[i], std[i]) (xn may be null), q[i] = quantize(xn[i], s_x[i])
//   gru_gates_i8(g, hidden, h, hq)     for j < hidden, gate rows r = j, z = H + j, n = 2H + j:
//       gx[o] = f32(acc_x[o]) * s_wx[o] + b_ih[o]                (pattern B: linear_i8_folded)
//       gh[o] = f32(acc_h[o]) * f32(s_h * s_wh[o]) + b_hh[o]     (pattern A: linear_i8_tensor)
//       r = logistic(gx_r + gh_r), z = logistic(gx_z + gh_z), n = tanh(gx_n + gh_n * r)
//       h[j] = (h[j] - n) * z + n,  hq[j] = quantize(h[j], s_h)  (the next step's codes)
//   (q, hq int8 or int16: the int16 codes feed the packed int16 kernel without a widening pass.)
//
// Why bit-identical, lane by lane (the same argument as fwref/vmath_i8.hpp): every MULPS / ADDPS /
// SUBPS / DIVPS is the scalar expression's one IEEE float32 operation in its order (-ffp-contract=off,
// no FMA where the scalar has none; f32(s_h * s_wh) formed as broadcast(s_h) * s_wh, IEEE products
// commute); int32 -> float by VCVTDQ2PS in MXCSR's mode as the scalar conversion; tanh8 / logistic8
// are vmath_f32.hpp's; quantize is vmath_i8.hpp's quantize8 (per-lane scales here for x). Tails:
// normalise_quantize_row (n >= 8) ends with the last 8 elements, overlapping the previous vector (the
// shared lanes computed and stored again: the same values); gru_gates_i8 ends with the scalar
// expressions. Nothing is read or written outside [0, n) / the gate rows [0, 3H).
// Checked by fwref_vmath (tests/test_vmath.py, tools/fwref_vmath_gru.hpp) on edge inputs.
#pragma once

#include <cstdint>

#include "fwref/numerics.hpp"
#include "fwref/vmath_f32.hpp"
#include "fwref/vmath_i8.hpp"

namespace fwref {

// One step's gate inputs: the two products' int32 accumulators (3H rows each) and their rescale.
struct GruGateInputs {
  const std::int32_t* acc_x;  // W_ih' x_q      (3H)
  const float* s_wx;          // W_ih' scales, s_x folded in (3H)
  const float* b_ih;          // (3H)
  const std::int32_t* acc_h;  // W_hh h_q       (3H)
  float s_h;                  // act.h.scale
  const float* s_wh;          // W_hh scales (3H)
  const float* b_hh;          // (3H)
};

namespace vmath_gru_detail {

// The scalar expressions (the reference; also the tails of the vector code).
template <class Q>
inline void gate_unit(const GruGateInputs& g, int hidden, int j, float* h, Q* hq) {
  auto gx = [&](int o) { return (static_cast<float>(g.acc_x[o]) * g.s_wx[o]) + g.b_ih[o]; };
  auto gh = [&](int o) { return rescale_i32(g.acc_h[o], g.s_h, g.s_wh[o]) + g.b_hh[o]; };
  const float r = logistic_approx(gx(j) + gh(j));
  const float z = logistic_approx(gx(hidden + j) + gh(hidden + j));
  const float n = tanh_approx(gx(2 * hidden + j) + gh(2 * hidden + j) * r);
  h[j] = (h[j] - n) * z + n;
  hq[j] = quantize(h[j], g.s_h);
}

template <class Q>
inline void normalise_quantize_scalar(const float* x, const float* mean, const float* std_, const float* s_x, int i,
                                      float* xn, Q* q) {
  const float v = normalise(x[i], mean[i], std_[i]);
  if (xn != nullptr) xn[i] = v;
  q[i] = quantize(v, s_x[i]);
}

}  // namespace vmath_gru_detail

#if FWREF_VMATH_I8_AVX2

template <class Q>
inline void normalise_quantize_row(const float* x, const float* mean, const float* std_, const float* s_x, int n,
                                   float* xn, Q* q) {
  if (n < 8) {
    for (int i = 0; i < n; ++i) vmath_gru_detail::normalise_quantize_scalar(x, mean, std_, s_x, i, xn, q);
    return;
  }
  for (int i = 0;;) {
    const __m256 v = _mm256_div_ps(_mm256_sub_ps(_mm256_loadu_ps(x + i), _mm256_loadu_ps(mean + i)),
                                   _mm256_loadu_ps(std_ + i));  // normalise: Sub then Div
    if (xn != nullptr) _mm256_storeu_ps(xn + i, v);
    vmath_i8_detail::store8(q + i, vmath_i8_detail::quantize8(v, _mm256_loadu_ps(s_x + i)));
    if (i + 8 == n) return;
    i = i + 16 <= n ? i + 8 : n - 8;
  }
}

namespace vmath_gru_detail {
// gx (pattern B) and gh (pattern A) of gate rows [o, o + 8).
inline __m256 gx8(const GruGateInputs& g, int o) {
  const __m256 a = _mm256_cvtepi32_ps(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(g.acc_x + o)));
  return _mm256_add_ps(_mm256_mul_ps(a, _mm256_loadu_ps(g.s_wx + o)), _mm256_loadu_ps(g.b_ih + o));
}
inline __m256 gh8(const GruGateInputs& g, __m256 s_h, int o) {
  const __m256 a = _mm256_cvtepi32_ps(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(g.acc_h + o)));
  const __m256 m = _mm256_mul_ps(s_h, _mm256_loadu_ps(g.s_wh + o));  // rescale_i32's f32(s_h * s_wh)
  return _mm256_add_ps(_mm256_mul_ps(a, m), _mm256_loadu_ps(g.b_hh + o));
}
}  // namespace vmath_gru_detail

template <class Q>
inline void gru_gates_i8(const GruGateInputs& g, int hidden, float* h, Q* hq) {
  using namespace vmath_gru_detail;
  const __m256 sh = _mm256_set1_ps(g.s_h);
  int j = 0;
  for (; j + 8 <= hidden; j += 8) {
    const __m256 r = logistic8(_mm256_add_ps(gx8(g, j), gh8(g, sh, j)));
    const __m256 z = logistic8(_mm256_add_ps(gx8(g, hidden + j), gh8(g, sh, hidden + j)));
    const __m256 n = tanh8(_mm256_add_ps(gx8(g, 2 * hidden + j), _mm256_mul_ps(gh8(g, sh, 2 * hidden + j), r)));
    const __m256 hn = _mm256_add_ps(_mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(h + j), n), z), n);
    _mm256_storeu_ps(h + j, hn);
    vmath_i8_detail::store8(hq + j, vmath_i8_detail::quantize8(hn, sh));
  }
  for (; j < hidden; ++j) gate_unit(g, hidden, j, h, hq);
}

#else

template <class Q>
inline void normalise_quantize_row(const float* x, const float* mean, const float* std_, const float* s_x, int n,
                                   float* xn, Q* q) {
  for (int i = 0; i < n; ++i) vmath_gru_detail::normalise_quantize_scalar(x, mean, std_, s_x, i, xn, q);
}

template <class Q>
inline void gru_gates_i8(const GruGateInputs& g, int hidden, float* h, Q* hq) {
  for (int j = 0; j < hidden; ++j) vmath_gru_detail::gate_unit(g, hidden, j, h, hq);
}

#endif

}  // namespace fwref
