// fwref/vmath_f32.hpp -- scope: the host's fp32 vector math, bit-identical per element to the scalar
// code it replaces: tanh_approx / logistic_approx (fwref/numerics.hpp) on 8 floats per AVX2 vector,
// and y = W x with Eigen's lazyProduct reduction order, several rows per pass over x.
//
//   tanh_n(v, n), logistic_n(v, n)   v[i] = tanh_approx(v[i]) / logistic_approx(v[i]), in place
//   all_finite_n(x, n)               all_finite_f32(x, n), 8 floats per comparison
//   gemv_f32_eigen(w, rows, cols, x, y)
//                                    y[o] = map(W).lazyProduct(x)[o] bit for bit (fwref/linalg.hpp)
//
// Why bit-identical: each lane performs the scalar function's IEEE float32 operations in the same
// order. The clamps: the scalar `x < -9 ? -9 : x` is `(-9 > x) ? -9 : x`, which is exactly MAXPS with
// the constant as FIRST operand (MAXPS(a, b) = a > b ? a : b: a NaN x fails the comparison and comes
// back, as in the scalar); `x > 9 ? 9 : x` is MINPS(9, x). The Horner steps are _mm256_fmadd_ps (one
// rounding, as std::fma), the rest one MULPS / ADDPS / DIVPS each (correctly rounded, no contraction:
// -ffp-contract=off). MXCSR is left as the program starts (no FTZ/DAZ), the same for scalar and vector
// code, so denormals round identically. Checked by fwref_vmath (tests/test_vmath.py): the clamp edges,
// +-0, NaN, +-inf, denormals and a walk over the float32 bit patterns.
//
// The gemv: Eigen 3.4's coefficient-based product computes each y[o] as the redux of row o .* x
// (Redux.h, LinearVectorizedTraversal, NoUnrolling; the expression has no direct access, so no
// alignment peeling): with P = 8 lanes, r0 = w[0:8] x[0:8], r1 = w[8:16] x[8:16], then pairs of packets
// into r0 and r1, r0 = r0 + r1, one odd packet into r0, the horizontal sum ((lo + hi) then lanes
// (0 + 2) + (1 + 3)), then the last cols % 8 products one by one; fewer than 8 columns: a plain
// left-to-right sum starting from the first product. Here 4 rows share each load of x (Eigen's loop
// does one row, one product per coefficient call, with its per-row set-up); the same operations per
// row, so the same bits. Only where Eigen's float packet is 8 lanes (AVX without AVX-512): elsewhere
// gemv_f32_eigen is Eigen's own product, and tanh_n / logistic_n the scalar loop (the Cortex-M build
// keeps its own paths: fwref/kernels_f32.hpp, fwref/tanhq.hpp).
#pragma once

#include <cmath>
#include <limits>

#include "fwref/kernels_f32.hpp"
#include "fwref/linalg.hpp"
#include "fwref/numerics.hpp"

#if defined(__AVX2__) && defined(__FMA__) && !defined(FWREF_PORTABLE_KERNELS) && !defined(FWREF_LIBM_ACTIVATIONS)
#include <immintrin.h>
#define FWREF_VMATH_AVX2 1
#endif

namespace fwref {

#if defined(FWREF_VMATH_AVX2)

inline const char* vmath_f32_kernel_name() { return "avx2-fma"; }

// tanh_approx on 8 lanes: the same constants and operations as numerics.hpp.
inline __m256 tanh8(__m256 x) {
  x = _mm256_max_ps(_mm256_set1_ps(-9.0f), x);  // (-9 > x) ? -9 : x, NaN kept
  x = _mm256_min_ps(_mm256_set1_ps(9.0f), x);   // (9 < x) ? 9 : x, NaN kept
  const __m256 x2 = _mm256_mul_ps(x, x);
  __m256 p = _mm256_fmadd_ps(x2, _mm256_set1_ps(-2.76076847742355e-16f), _mm256_set1_ps(2.00018790482477e-13f));
  p = _mm256_fmadd_ps(p, x2, _mm256_set1_ps(-8.60467152213735e-11f));
  p = _mm256_fmadd_ps(p, x2, _mm256_set1_ps(5.12229709037114e-08f));
  p = _mm256_fmadd_ps(p, x2, _mm256_set1_ps(1.48572235717979e-05f));
  p = _mm256_fmadd_ps(p, x2, _mm256_set1_ps(6.37261928875436e-04f));
  p = _mm256_fmadd_ps(p, x2, _mm256_set1_ps(4.89352455891786e-03f));
  p = _mm256_mul_ps(p, x);
  __m256 q = _mm256_fmadd_ps(x2, _mm256_set1_ps(1.19825839466702e-06f), _mm256_set1_ps(1.18534705686654e-04f));
  q = _mm256_fmadd_ps(q, x2, _mm256_set1_ps(2.26843463243900e-03f));
  q = _mm256_fmadd_ps(q, x2, _mm256_set1_ps(4.89352518554385e-03f));
  return _mm256_div_ps(p, q);
}

// logistic_approx on 8 lanes, its final clamp `r < 0 ? 0 : r` as MAXPS(0, r).
inline __m256 logistic8(__m256 x) {
  x = _mm256_max_ps(_mm256_set1_ps(-18.0f), x);
  x = _mm256_min_ps(_mm256_set1_ps(18.0f), x);
  const __m256 x2 = _mm256_mul_ps(x, x);
  __m256 p = _mm256_fmadd_ps(x2, _mm256_set1_ps(4.37031012579801e-11f), _mm256_set1_ps(1.15627324459942e-07f));
  p = _mm256_fmadd_ps(p, x2, _mm256_set1_ps(6.08574864600143e-05f));
  p = _mm256_fmadd_ps(p, x2, _mm256_set1_ps(8.51377133304701e-03f));
  p = _mm256_fmadd_ps(p, x2, _mm256_set1_ps(2.48287947061529e-01f));
  p = _mm256_mul_ps(p, x);
  __m256 q = _mm256_fmadd_ps(x2, _mm256_set1_ps(6.10247389755681e-13f), _mm256_set1_ps(5.76102136993427e-09f));
  q = _mm256_fmadd_ps(q, x2, _mm256_set1_ps(6.29106785017040e-06f));
  q = _mm256_fmadd_ps(q, x2, _mm256_set1_ps(1.70198817374094e-03f));
  q = _mm256_fmadd_ps(q, x2, _mm256_set1_ps(1.16817656904453e-01f));
  q = _mm256_fmadd_ps(q, x2, _mm256_set1_ps(9.93151921023180e-01f));
  const __m256 r = _mm256_add_ps(_mm256_div_ps(p, q), _mm256_set1_ps(0.5f));
  return _mm256_max_ps(_mm256_setzero_ps(), r);  // (0 > r) ? 0 : r
}

inline void tanh_n(float* v, int n) {
  int i = 0;
  for (; i + 8 <= n; i += 8) _mm256_storeu_ps(v + i, tanh8(_mm256_loadu_ps(v + i)));
  for (; i < n; ++i) v[i] = tanh_approx(v[i]);
}

inline void logistic_n(float* v, int n) {
  int i = 0;
  for (; i + 8 <= n; i += 8) _mm256_storeu_ps(v + i, logistic8(_mm256_loadu_ps(v + i)));
  for (; i < n; ++i) v[i] = logistic_approx(v[i]);
}

// all_finite_f32 (fwref/kernels_f32.hpp) 8 floats at a time: |x| < inf is false for an infinity
// and (ordered comparison) for a NaN, so the answer is the same.
inline bool all_finite_n(const float* x, int n) {
  const __m256 abs_mask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff));
  const __m256 inf = _mm256_set1_ps(std::numeric_limits<float>::infinity());
  int i = 0;
  for (; i + 8 <= n; i += 8) {
    const __m256 a = _mm256_and_ps(_mm256_loadu_ps(x + i), abs_mask);
    if (_mm256_movemask_ps(_mm256_cmp_ps(a, inf, _CMP_LT_OQ)) != 0xff) return false;
  }
  for (; i < n; ++i) {
    if (!std::isfinite(x[i])) return false;
  }
  return true;
}

#else

inline bool all_finite_n(const float* x, int n) { return all_finite_f32(x, n); }
inline const char* vmath_f32_kernel_name() { return "scalar"; }
inline void tanh_n(float* v, int n) {
  for (int i = 0; i < n; ++i) v[i] = tanh_approx(v[i]);
}
inline void logistic_n(float* v, int n) {
  for (int i = 0; i < n; ++i) v[i] = logistic_approx(v[i]);
}

#endif

// Eigen's float packet is 8 lanes exactly when it vectorises with AVX and not AVX-512.
#if defined(FWREF_VMATH_AVX2) && defined(EIGEN_VECTORIZE_AVX) && !defined(EIGEN_VECTORIZE_AVX512)
#define FWREF_GEMV_EIGEN_ORDER 1

namespace vmath_detail {

// The row kernels' parts inlined into one loop body (GCC otherwise calls finish_rows with the packet
// sums passed through memory).
#define FWREF_VMATH_INLINE inline __attribute__((always_inline))

// Eigen's predux<Packet8f>: lo + hi, then tmp = a + movehl(a), then tmp[0] + tmp[1].
inline float predux8(__m256 v) {
  const __m128 a = _mm_add_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps(v, 1));
  const __m128 t = _mm_add_ps(a, _mm_movehl_ps(a, a));
  return _mm_cvtss_f32(_mm_add_ss(t, _mm_shuffle_ps(t, t, 1)));
}

// s (4 rows in its lanes) + the rows' last T products, one column at a time in increasing column
// order: s = s + w[r][i] * x[i] per lane, i = cols - T .. cols - 1. The columns come from the rows'
// last 8 floats (in bounds: cols >= 8), transposed (4x4 twice), instead of 4 scalar loads per column.
template <int T>
FWREF_VMATH_INLINE __m128 tail4(__m128 s, const float* w, int cols, const float* x) {
  const float* e = w + cols - 8;
  const __m256 t0 = _mm256_loadu_ps(e), t1 = _mm256_loadu_ps(e + cols);
  const __m256 t2 = _mm256_loadu_ps(e + 2 * cols), t3 = _mm256_loadu_ps(e + 3 * cols);
  __m128 c0 = _mm256_castps256_ps128(t0), c1 = _mm256_castps256_ps128(t1);
  __m128 c2 = _mm256_castps256_ps128(t2), c3 = _mm256_castps256_ps128(t3);
  __m128 c4 = _mm256_extractf128_ps(t0, 1), c5 = _mm256_extractf128_ps(t1, 1);
  __m128 c6 = _mm256_extractf128_ps(t2, 1), c7 = _mm256_extractf128_ps(t3, 1);
  _MM_TRANSPOSE4_PS(c0, c1, c2, c3);  // c_k = column cols - 8 + k of the 4 rows
  _MM_TRANSPOSE4_PS(c4, c5, c6, c7);
  const __m128 col[8] = {c0, c1, c2, c3, c4, c5, c6, c7};
  const float* xe = x + cols - 8;
  for (int k = 8 - T; k < 8; ++k) s = _mm_add_ps(s, _mm_mul_ps(col[k], _mm_set1_ps(xe[k])));
  return s;
}

// The packet sums r0[0..R) of R rows -> Eigen's redux result per row (predux8, then the tail
// products one by one), with 4 rows in the lanes of one SSE vector when R = 4: the lanes hold the
// rows, so each row sees exactly predux8's additions ((a0 + a2) + (a1 + a3), a = lo + hi) and then
// s = s + w[i] * x[i] for i = n8 .. cols - 1, in order.
template <int R>
FWREF_VMATH_INLINE void finish_rows(const __m256* r0, const float* w, int cols, int n8, const float* x, float* y) {
  if (R != 4) {
    for (int r = 0; r < R; ++r) {
      float s = predux8(r0[r]);
      const float* wr = w + r * cols;
      for (int i = n8; i < cols; ++i) s = s + wr[i] * x[i];
      y[r] = s;
    }
    return;
  }
  __m128 a0 = _mm_add_ps(_mm256_castps256_ps128(r0[0]), _mm256_extractf128_ps(r0[0], 1));
  __m128 a1 = _mm_add_ps(_mm256_castps256_ps128(r0[1]), _mm256_extractf128_ps(r0[1], 1));
  __m128 a2 = _mm_add_ps(_mm256_castps256_ps128(r0[2]), _mm256_extractf128_ps(r0[2], 1));
  __m128 a3 = _mm_add_ps(_mm256_castps256_ps128(r0[3]), _mm256_extractf128_ps(r0[3], 1));
  _MM_TRANSPOSE4_PS(a0, a1, a2, a3);  // a_j = lane j of every row
  __m128 s = _mm_add_ps(_mm_add_ps(a0, a2), _mm_add_ps(a1, a3));
  switch (cols - n8) {  // the tail's length as a constant, so that tail4 unrolls
    case 1: s = tail4<1>(s, w, cols, x); break;
    case 2: s = tail4<2>(s, w, cols, x); break;
    case 3: s = tail4<3>(s, w, cols, x); break;
    case 4: s = tail4<4>(s, w, cols, x); break;
    case 5: s = tail4<5>(s, w, cols, x); break;
    case 6: s = tail4<6>(s, w, cols, x); break;
    case 7: s = tail4<7>(s, w, cols, x); break;
    default: break;
  }
  _mm_storeu_ps(y, s);
}

// R rows (R = 1 or 4) starting at w, each exactly as Eigen's redux (see the header comment); cols >= 8.
template <int R>
FWREF_VMATH_INLINE void rows_eigen_order(const float* w, int cols, const float* x, float* y) {
  const int n8 = cols & ~7, n16 = cols & ~15;
  __m256 r0[R], r1[R];
  if (n8 > 8) {
    const __m256 x0 = _mm256_loadu_ps(x), x1 = _mm256_loadu_ps(x + 8);
    for (int r = 0; r < R; ++r) {
      r0[r] = _mm256_mul_ps(_mm256_loadu_ps(w + r * cols), x0);
      r1[r] = _mm256_mul_ps(_mm256_loadu_ps(w + r * cols + 8), x1);
    }
    for (int i = 16; i < n16; i += 16) {
      const __m256 xa = _mm256_loadu_ps(x + i), xb = _mm256_loadu_ps(x + i + 8);
      for (int r = 0; r < R; ++r) {
        r0[r] = _mm256_add_ps(r0[r], _mm256_mul_ps(_mm256_loadu_ps(w + r * cols + i), xa));
        r1[r] = _mm256_add_ps(r1[r], _mm256_mul_ps(_mm256_loadu_ps(w + r * cols + i + 8), xb));
      }
    }
    for (int r = 0; r < R; ++r) r0[r] = _mm256_add_ps(r0[r], r1[r]);
    if (n8 > n16) {
      const __m256 xc = _mm256_loadu_ps(x + n16);
      for (int r = 0; r < R; ++r) r0[r] = _mm256_add_ps(r0[r], _mm256_mul_ps(_mm256_loadu_ps(w + r * cols + n16), xc));
    }
  } else {
    const __m256 x0 = _mm256_loadu_ps(x);
    for (int r = 0; r < R; ++r) r0[r] = _mm256_mul_ps(_mm256_loadu_ps(w + r * cols), x0);
  }
  finish_rows<R>(r0, w, cols, n8, x, y);
}

#undef FWREF_VMATH_INLINE
}  // namespace vmath_detail

inline void gemv_f32_eigen(const float* w, int rows, int cols, const float* x, float* y) {
  if (cols < 8) {  // Eigen: "too small to vectorize anything", res = coeff(0), then + coeff(i)
    for (int o = 0; o < rows; ++o) {
      const float* r = w + o * cols;
      float s = r[0] * x[0];
      for (int i = 1; i < cols; ++i) s = s + r[i] * x[i];
      y[o] = s;
    }
    return;
  }
  int o = 0;
  for (; o + 4 <= rows; o += 4) vmath_detail::rows_eigen_order<4>(w + o * cols, cols, x, y + o);
  for (; o < rows; ++o) vmath_detail::rows_eigen_order<1>(w + o * cols, cols, x, y + o);
}

#else

inline void gemv_f32_eigen(const float* w, int rows, int cols, const float* x, float* y) {
  MapVec out(y, rows);
  matvec(MatF{w, rows, cols}, ConstMapVec(x, cols), out);
}

#endif

// y = W x for the fp32 models' Eigen vectors: gemv_f32_eigen where it reproduces Eigen's order,
// else matvec_fast (Eigen's product on a host, the VFP kernel on Cortex-M). ``y`` is resized to W's
// rows (a Map must already have that size); x and y are contiguous and do not alias.
template <class Dst, class Src>
inline void matvec_f32(const MatF& w, const Src& x, Dst&& y) {
#if defined(FWREF_GEMV_EIGEN_ORDER)
  y.resize(w.rows);
  gemv_f32_eigen(w.data, w.rows, w.cols, x.data(), y.data());
#else
  matvec_fast(w, x, y);
#endif
}

}  // namespace fwref
