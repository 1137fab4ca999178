// fwref/vmath_i8.hpp -- scope: the host's per-element int8 work of the CNODE (rescale, tanh,
// QuantizeLinear) on 8 lanes per AVX2 vector, bit-identical per element to the scalar code of
// fwref/numerics.hpp it replaces; the scalar loop elsewhere (the Cortex-M build keeps its own paths in
// src/cnode.cpp: fwref/tanhq.hpp's table, VCVTR + SSAT).
//
//   quantize_n(x, n, s, q)                     q[i] = quantize(x[i], s)           (q int8 or int16)
//   rescale_tanh_quantize_n(acc, s_a, s_w, v, s_q, n, q)
//                                              q[i] = quantize(tanh_approx(rescale_i32(acc[i], s_a,
//                                                     s_w[i]) + v[i]), s_q)
//   rescale_bias_n(acc, mult, b, n, y)         y[i] = f32(acc[i]) * mult[i] + b[i]
//   accumulate_codes(x, mean, std, s_x, n, p, acc)
//                                              acc[i] += p * quantize(normalise(x[i], mean[i], std[i]), s_x[i])
//   rescale_quantize_row(acc, s_p, s_x, s_u, n, u, q)
//                                              u[i] = rescale_i32(acc[i], s_p, s_x[i]) (u may be null),
//                                              q[i] = quantize(u[i], s_u[i])
//   for_each_nonzero(p, n, f)                  f(i, p[i]) for each int8 p[i] != 0, increasing i
//
// Why bit-identical, lane by lane:
// - int32 -> float: VCVTDQ2PS rounds in MXCSR's mode, as the scalar static_cast (VCVTSI2SS) does, so
//   the two agree for every int32 (the accumulators are exact integers below 2^24 anyway,
//   fwref/config.hpp, where both conversions are exact).
// - each MULPS / ADDPS / SUBPS / DIVPS is the scalar expression's one IEEE float32 operation, in the
//   scalar's order (-ffp-contract=off: no FMA where the scalar has none); IEEE multiplication is
//   commutative, so s_a * s_w[i] may be formed as broadcast(s_a) * s_w-vector.
// - tanh: vmath_f32.hpp's tanh8 (the same operations as tanh_approx).
// - quantize: v = x / s (DIVPS); a NaN v -> +0 (CMPORDPS + ANDPS), as the scalar `if (!(v == v)) v = 0`;
//   clamp to [-128, 127] (MAXPS / MINPS: no NaN is left, so their operand order does not matter, and
//   -0 vs +0 both end as code 0); then VCVTPS2DQ, which rounds in MXCSR's mode: round to nearest
//   even by default, the mode in which the scalar's 1.5 * 2^23 trick rounds too (for |v| <= 128 both
//   give rne(v) exactly; nothing here changes MXCSR). The codes are packed with signed saturation,
//   a no-op in [-128, 127].
// - tails: quantize_n, rescale_tanh_quantize_n and rescale_bias_n finish with the scalar function;
//   accumulate_codes and rescale_quantize_row (n >= 8) with the last 8 elements, overlapping the
//   previous vector (see there); no load or store outside [0, n).
// Checked by fwref_vmath (tests/test_vmath.py): round-half-even ties, the saturation bounds and
// their neighbouring floats, +-0, +-inf, NaNs, denormals, a walk over the float32 bit patterns, and
// random rows of every length 1..70.
#pragma once

#include <cstdint>
#include <cstring>

#include "fwref/numerics.hpp"
#include "fwref/vmath_f32.hpp"

#if defined(__x86_64__) && !defined(FWREF_PORTABLE_KERNELS)
#include <immintrin.h>
#endif

namespace fwref {

// FWREF_VMATH_I8_AVX2: 1 where the vector code below is compiled (AVX2 + FMA, the activations
// MLAS's; the same condition as vmath_f32.hpp's tanh8), else 0. Test it with #if, not #ifdef.
#if defined(FWREF_VMATH_AVX2)
#define FWREF_VMATH_I8_AVX2 1

inline const char* vmath_i8_kernel_name() { return "avx2"; }

namespace vmath_i8_detail {

// quantize() on 8 lanes: the codes as int32 in [-128, 127].
inline __m256i quantize8(__m256 x, __m256 scale) {
  __m256 v = _mm256_div_ps(x, scale);
  v = _mm256_and_ps(v, _mm256_cmp_ps(v, v, _CMP_ORD_Q));  // NaN -> +0
  v = _mm256_max_ps(v, _mm256_set1_ps(-128.0f));
  v = _mm256_min_ps(v, _mm256_set1_ps(127.0f));
  return _mm256_cvtps_epi32(v);  // round to nearest even (MXCSR's default mode)
}

inline __m128i pack16(__m256i c) {
  return _mm_packs_epi32(_mm256_castsi256_si128(c), _mm256_extracti128_si256(c, 1));
}
inline void store8(std::int16_t* q, __m256i c) { _mm_storeu_si128(reinterpret_cast<__m128i*>(q), pack16(c)); }
inline void store8(std::int8_t* q, __m256i c) {
  const __m128i b = pack16(c);
  _mm_storel_epi64(reinterpret_cast<__m128i*>(q), _mm_packs_epi16(b, b));
}

// Lanes [0, n) of 8 set.
inline __m256i tail_mask(int n) {
  return _mm256_cmpgt_epi32(_mm256_set1_epi32(n), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
}

}  // namespace vmath_i8_detail

template <class Q>
inline void quantize_n(const float* x, int n, float s, Q* q) {
  const __m256 sv = _mm256_set1_ps(s);
  int i = 0;
  for (; i + 8 <= n; i += 8) vmath_i8_detail::store8(q + i, vmath_i8_detail::quantize8(_mm256_loadu_ps(x + i), sv));
  for (; i < n; ++i) q[i] = quantize(x[i], s);
}

template <class Q>
inline void rescale_tanh_quantize_n(const std::int32_t* acc, float s_a, const float* s_w, const float* v, float s_q,
                                    int n, Q* q) {
  const __m256 av = _mm256_set1_ps(s_a), qv = _mm256_set1_ps(s_q);
  int i = 0;
  for (; i + 8 <= n; i += 8) {
    const __m256 m = _mm256_mul_ps(av, _mm256_loadu_ps(s_w + i));  // rescale_i32's f32(s_a * s_w)
    const __m256 a = _mm256_cvtepi32_ps(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(acc + i)));
    const __m256 y = _mm256_add_ps(_mm256_mul_ps(a, m), _mm256_loadu_ps(v + i));
    vmath_i8_detail::store8(q + i, vmath_i8_detail::quantize8(tanh8(y), qv));
  }
  for (; i < n; ++i) q[i] = quantize(tanh_approx(rescale_i32(acc[i], s_a, s_w[i]) + v[i]), s_q);
}

inline void rescale_bias_n(const std::int32_t* acc, const float* mult, const float* b, int n, float* y) {
  int i = 0;
  for (; i + 8 <= n; i += 8) {
    const __m256 a = _mm256_cvtepi32_ps(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(acc + i)));
    _mm256_storeu_ps(y + i, _mm256_add_ps(_mm256_mul_ps(a, _mm256_loadu_ps(mult + i)), _mm256_loadu_ps(b + i)));
  }
  for (; i < n; ++i) y[i] = static_cast<float>(acc[i]) * mult[i] + b[i];
}

// When n % 8 != 0 the last vector is the last 8 elements, overlapping the previous one: there p is
// zeroed in the lanes already counted (they add p * 0), so every element is counted once.
inline void accumulate_codes(const float* x, const float* mean, const float* std_, const float* s_x, int n,
                             std::int32_t p, std::int32_t* acc) {
  if (n < 8) {
    for (int i = 0; i < n; ++i) acc[i] += p * quantize(normalise(x[i], mean[i], std_[i]), s_x[i]);
    return;
  }
  __m256i pv = _mm256_set1_epi32(p);
  for (int i = 0;;) {
    const __m256 y = _mm256_div_ps(_mm256_sub_ps(_mm256_loadu_ps(x + i), _mm256_loadu_ps(mean + i)),
                                   _mm256_loadu_ps(std_ + i));  // normalise
    const __m256i c = vmath_i8_detail::quantize8(y, _mm256_loadu_ps(s_x + i));
    __m256i* a = reinterpret_cast<__m256i*>(acc + i);
    _mm256_storeu_si256(a, _mm256_add_epi32(_mm256_loadu_si256(a), _mm256_mullo_epi32(pv, c)));
    if (i + 8 == n) return;
    if (i + 16 <= n) {
      i += 8;
      continue;
    }
    const int counted = i + 8 - (n - 8);  // lanes of the last vector already counted, 1..7
    pv = _mm256_andnot_si256(vmath_i8_detail::tail_mask(counted), pv);
    i = n - 8;
  }
}

// u[i] and q[i] for i in [0, n); when n % 8 != 0 the last vector is the last 8 elements (the lanes it
// shares with the previous one are computed and stored again, the same values).
inline void rescale_quantize_row(const std::int32_t* acc, float s_p, const float* s_x, const float* s_u, int n,
                                 float* u, std::int8_t* q) {
  if (n < 8) {
    for (int i = 0; i < n; ++i) {
      const float v = rescale_i32(acc[i], s_p, s_x[i]);
      if (u != nullptr) u[i] = v;
      q[i] = quantize(v, s_u[i]);
    }
    return;
  }
  const __m256 pv = _mm256_set1_ps(s_p);
  for (int i = 0;;) {
    const __m256 a = _mm256_cvtepi32_ps(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(acc + i)));
    const __m256 uv = _mm256_mul_ps(a, _mm256_mul_ps(pv, _mm256_loadu_ps(s_x + i)));  // rescale_i32(acc, s_p, s_x)
    if (u != nullptr) _mm256_storeu_ps(u + i, uv);
    vmath_i8_detail::store8(q + i, vmath_i8_detail::quantize8(uv, _mm256_loadu_ps(s_u + i)));
    if (i + 8 == n) return;
    i = i + 16 <= n ? i + 8 : n - 8;
  }
}

#else

inline const char* vmath_i8_kernel_name() { return "scalar"; }
#define FWREF_VMATH_I8_AVX2 0

template <class Q>
inline void quantize_n(const float* x, int n, float s, Q* q) {
  for (int i = 0; i < n; ++i) q[i] = quantize(x[i], s);
}

template <class Q>
inline void rescale_tanh_quantize_n(const std::int32_t* acc, float s_a, const float* s_w, const float* v, float s_q,
                                    int n, Q* q) {
  for (int i = 0; i < n; ++i) q[i] = quantize(tanh_approx(rescale_i32(acc[i], s_a, s_w[i]) + v[i]), s_q);
}

inline void rescale_bias_n(const std::int32_t* acc, const float* mult, const float* b, int n, float* y) {
  for (int i = 0; i < n; ++i) y[i] = static_cast<float>(acc[i]) * mult[i] + b[i];
}

inline void accumulate_codes(const float* x, const float* mean, const float* std_, const float* s_x, int n,
                             std::int32_t p, std::int32_t* acc) {
  for (int i = 0; i < n; ++i) acc[i] += p * quantize(normalise(x[i], mean[i], std_[i]), s_x[i]);
}

inline void rescale_quantize_row(const std::int32_t* acc, float s_p, const float* s_x, const float* s_u, int n,
                                 float* u, std::int8_t* q) {
  for (int i = 0; i < n; ++i) {
    const float v = rescale_i32(acc[i], s_p, s_x[i]);
    if (u != nullptr) u[i] = v;
    q[i] = quantize(v, s_u[i]);
  }
}

#endif

// The interpolation rows are mostly zeros (two weights per row): on AVX2 32 weights per comparison,
// then (and elsewhere throughout) 8 at a time past the zeros, one by one where a word is not zero.
namespace nonzero_detail {

template <class F>
inline void from(const std::int8_t* p, int w0, int n, F& f) {
  for (; w0 < n; w0 += 8) {
    std::uint64_t eight = 1;
    if (w0 + 8 <= n) std::memcpy(&eight, p + w0, 8);
    if (eight == 0) continue;
    for (int w = w0; w < n && w < w0 + 8; ++w) {
      const std::int32_t pw = p[w];
      if (pw != 0) f(w, pw);
    }
  }
}

}  // namespace nonzero_detail

#if defined(__x86_64__) && !defined(FWREF_PORTABLE_KERNELS)
#define FWREF_HAS_NONZERO_AVX2 1
// for_each_nonzero's AVX2 walk however this file is built (a target attribute), for the AVX2 and AVX-512
// control rows (src/controls_avx2.cpp, src/controls_avx512.cpp): call it on an AVX2 CPU only. A caller
// compiled with a target attribute gives its lambda the same attribute, so that f is inlined into the walk.
template <class F>
__attribute__((target("avx2"), always_inline)) inline void for_each_nonzero_avx2(const std::int8_t* p, int n, F&& f) {
  int w0 = 0;
  for (; w0 + 32 <= n; w0 += 32) {
    const __m256i v = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(p + w0));
    std::uint32_t nz = ~static_cast<std::uint32_t>(_mm256_movemask_epi8(_mm256_cmpeq_epi8(v, _mm256_setzero_si256())));
    for (; nz != 0; nz &= nz - 1) {
      const int w = w0 + __builtin_ctz(nz);
      f(w, static_cast<std::int32_t>(p[w]));
    }
  }
  nonzero_detail::from(p, w0, n, f);
}
#endif

template <class F>
inline void for_each_nonzero(const std::int8_t* p, int n, F&& f) {
#if FWREF_VMATH_I8_AVX2 && defined(FWREF_HAS_NONZERO_AVX2)
  for_each_nonzero_avx2(p, n, f);
#else
  nonzero_detail::from(p, 0, n, f);
#endif
}

}  // namespace fwref
