// fwref/vmath_f32.hpp -- scope: the host's fp32 vector math: tanh_approx / logistic_approx
// (fwref/numerics.hpp) on 8 floats per AVX2 vector, bit-identical per element to the scalar code, and
// y = W x (+ b) with FMA chains, 8 rows per pass over x.
//
//   tanh_n(v, n), logistic_n(v, n)   v[i] = tanh_approx(v[i]) / logistic_approx(v[i]), in place
//   all_finite_n(x, n)               all_finite_f32(x, n), 8 floats per comparison
//   gemv_f32_fma(w, rows, cols, x, b, y)
//                                    y = W x (+ b), the summation order stated above its definition
//   matvec_f32(w, x, y), matvec_bias_f32(w, x, b, y)   the models' products (Eigen vectors in, out)
//
// Why tanh / logistic are bit-identical: each lane performs the scalar function's IEEE float32 operations in the same
// order. The clamps: the scalar `x < -9 ? -9 : x` is `(-9 > x) ? -9 : x`, which is exactly MAXPS with
// the constant as FIRST operand (MAXPS(a, b) = a > b ? a : b: a NaN x fails the comparison and comes
// back, as in the scalar); `x > 9 ? 9 : x` is MINPS(9, x). The Horner steps are _mm256_fmadd_ps (one
// rounding, as std::fma), the rest one MULPS / ADDPS / DIVPS each (correctly rounded, no contraction:
// -ffp-contract=off). MXCSR is left as the program starts (no FTZ/DAZ), the same for scalar and vector
// code, so denormals round identically. Checked by fwref_vmath (tests/test_vmath.py): the clamp edges,
// +-0, NaN, +-inf, denormals and a walk over the float32 bit patterns.
//
// The gemv is NOT Eigen's order (Eigen's lazyProduct has no fused
// multiply-add and pays a horizontal sum per row, on the CNODE's short rows of 23, 40 and 64 columns):
// per row 8 FMA chains, one per lane, and one tree of additions, the horizontal sums of 8 rows done
// together (sum8). Its roundings differ from Eigen's and from ONNX Runtime's MLAS, within the fp32
// tolerance (core/contracts.py FP32_CPP_REL_TOL; `quadfdi parity`); it is deterministic: the same
// inputs give the same bits on every AVX2 host (no dependence on alignment or on rows % 8). On a CPU
// with AVX-512F the products run fwref/kernels_f32_avx512.hpp's kernel instead (chosen at run time,
// 16 lanes: its own stated order, the same bits on every AVX-512F host; FWREF_F32_KERNEL=avx2 keeps
// this one). Hosts without AVX2 + FMA keep Eigen's product (matvec_fast), and tanh_n / logistic_n the
// scalar loop (the Cortex-M build keeps its own paths: fwref/kernels_f32.hpp, fwref/tanhq.hpp).
#pragma once

#include <cmath>
#include <limits>

#include "fwref/kernels_f32.hpp"
#include "fwref/kernels_f32_avx512.hpp"
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
  using T = TanhRational;
  const __m256 x2 = _mm256_mul_ps(x, x);
  __m256 p = _mm256_fmadd_ps(x2, _mm256_set1_ps(T::p[0]), _mm256_set1_ps(T::p[1]));
  p = _mm256_fmadd_ps(p, x2, _mm256_set1_ps(T::p[2]));
  p = _mm256_fmadd_ps(p, x2, _mm256_set1_ps(T::p[3]));
  p = _mm256_fmadd_ps(p, x2, _mm256_set1_ps(T::p[4]));
  p = _mm256_fmadd_ps(p, x2, _mm256_set1_ps(T::p[5]));
  p = _mm256_fmadd_ps(p, x2, _mm256_set1_ps(T::p[6]));
  p = _mm256_mul_ps(p, x);
  __m256 q = _mm256_fmadd_ps(x2, _mm256_set1_ps(T::q[0]), _mm256_set1_ps(T::q[1]));
  q = _mm256_fmadd_ps(q, x2, _mm256_set1_ps(T::q[2]));
  q = _mm256_fmadd_ps(q, x2, _mm256_set1_ps(T::q[3]));
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

// Bit k (k < 8) set iff !(p[k] == 0.0f): the scalar zero test (-0 is zero, a NaN is not), 8 at once.
inline unsigned nonzero8(const float* p) {
  return static_cast<unsigned>(_mm256_movemask_ps(_mm256_cmp_ps(_mm256_loadu_ps(p), _mm256_setzero_ps(), _CMP_NEQ_UQ)));
}

// u[c] = u[c] + p * normalise(x[c], mean[c], std_[c]) for c < n, 8 lanes at a time: per lane the
// scalar expression's SUBPS, DIVPS, MULPS, ADDPS (no FMA), so bit-identical to the scalar loop.
inline void add_scaled_normalised_n(float* u, float p, const float* x, const float* mean, const float* std_, int n) {
  const __m256 pv = _mm256_set1_ps(p);
  int c = 0;
  for (; c + 8 <= n; c += 8) {
    const __m256 xn = _mm256_div_ps(_mm256_sub_ps(_mm256_loadu_ps(x + c), _mm256_loadu_ps(mean + c)), _mm256_loadu_ps(std_ + c));
    _mm256_storeu_ps(u + c, _mm256_add_ps(_mm256_loadu_ps(u + c), _mm256_mul_ps(pv, xn)));
  }
  if (c < n) {  // the last n % 8 through masked loads and a masked store (the other lanes untouched)
    const __m256i m = _mm256_cmpgt_epi32(_mm256_set1_epi32(n - c), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
    const __m256 xn = _mm256_div_ps(_mm256_sub_ps(_mm256_maskload_ps(x + c, m), _mm256_maskload_ps(mean + c, m)),
                                    _mm256_maskload_ps(std_ + c, m));
    _mm256_maskstore_ps(u + c, m, _mm256_add_ps(_mm256_maskload_ps(u + c, m), _mm256_mul_ps(pv, xn)));
  }
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

#if defined(FWREF_VMATH_AVX2)
#define FWREF_GEMV_FMA 1

// What matvec_f32 / matvec_bias_f32 run: the AVX-512F kernel (fwref/kernels_f32_avx512.hpp) where the
// run-time choice is AVX-512, else gemv_f32_fma below.
inline const char* matvec_f32_kernel_name() {
  return gemv_f32_avx512_active() ? "fma-avx512-16row" : "fma-avx2-8row";
}

namespace vmath_detail {

// The row kernel's parts inlined into one loop body (GCC otherwise passes the accumulators through memory).
#define FWREF_VMATH_INLINE inline __attribute__((always_inline))

// Eight 8-lane accumulators -> one vector whose lane r is the sum of a[r]'s lanes l0..l7, as
// ((l0 + l1) + (l2 + l3)) + ((l4 + l5) + (l6 + l7)): 6 HADDPS, 2 VPERM2F128 and 1 ADDPS for 8 rows.
FWREF_VMATH_INLINE __m256 sum8(const __m256* a) {
  const __m256 t0 = _mm256_hadd_ps(a[0], a[1]);  // [a0 l0+l1, a0 l2+l3, a1 l0+l1, a1 l2+l3 | the same, l4..l7]
  const __m256 t1 = _mm256_hadd_ps(a[2], a[3]);
  const __m256 t2 = _mm256_hadd_ps(a[4], a[5]);
  const __m256 t3 = _mm256_hadd_ps(a[6], a[7]);
  const __m256 u0 = _mm256_hadd_ps(t0, t1);  // [a0..a3 (l0+l1)+(l2+l3) | a0..a3 (l4+l5)+(l6+l7)]
  const __m256 u1 = _mm256_hadd_ps(t2, t3);  // the same for a4..a7
  return _mm256_add_ps(_mm256_permute2f128_ps(u0, u1, 0x20), _mm256_permute2f128_ps(u0, u1, 0x31));
}

// R rows (R <= 8) starting at w: lane j of row r's accumulator is the FMA chain over the columns
// i = j, j + 8, j + 16, ... (the first packet a plain product, the last cols % 8 columns through masked
// loads, whose zero lanes add zeros), then sum8, then + b[r] when b is given; y[0..R) written.
// COLS > 0: cols as a compile-time constant (every weight address a fixed offset from w, the packet
// loop unrolled); 0: cols at run time.
template <int R, int COLS>
FWREF_VMATH_INLINE void rows_fma(const float* w, int cols_rt, const float* x, __m256i tail, const float* b, float* y) {
  const int cols = COLS > 0 ? COLS : cols_rt;
  const int n8 = cols & ~7;
  __m256 acc[8];
  for (int r = R; r < 8; ++r) acc[r] = _mm256_setzero_ps();
  int i = 0;
  if (n8 > 0) {
    const __m256 xv = _mm256_loadu_ps(x);
    for (int r = 0; r < R; ++r) acc[r] = _mm256_mul_ps(_mm256_loadu_ps(w + r * cols), xv);
    i = 8;
  } else {
    for (int r = 0; r < R; ++r) acc[r] = _mm256_setzero_ps();
  }
#pragma GCC unroll 16
  for (; i < n8; i += 8) {
    const __m256 xv = _mm256_loadu_ps(x + i);
    for (int r = 0; r < R; ++r) acc[r] = _mm256_fmadd_ps(_mm256_loadu_ps(w + r * cols + i), xv, acc[r]);
  }
  if (n8 < cols) {
    const __m256 xv = _mm256_maskload_ps(x + n8, tail);
    for (int r = 0; r < R; ++r) acc[r] = _mm256_fmadd_ps(_mm256_maskload_ps(w + r * cols + n8, tail), xv, acc[r]);
  }
  __m256 s = sum8(acc);
  if (R == 8) {
    if (b != nullptr) s = _mm256_add_ps(s, _mm256_loadu_ps(b));
    _mm256_storeu_ps(y, s);
  } else {
    const __m256i m = _mm256_cmpgt_epi32(_mm256_set1_epi32(R), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
    if (b != nullptr) s = _mm256_add_ps(s, _mm256_maskload_ps(b, m));
    _mm256_maskstore_ps(y, m, s);
  }
}

// All rows of W, COLS as rows_fma's.
template <int COLS>
void gemv_fma_cols(const float* w, int rows, int cols_rt, const float* x, const float* b, float* y) {
  const int cols = COLS > 0 ? COLS : cols_rt;
  const __m256i tail = _mm256_cmpgt_epi32(_mm256_set1_epi32(cols & 7), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
  int o = 0;
  for (; o + 8 <= rows; o += 8) rows_fma<8, COLS>(w + o * cols, cols, x, tail, b ? b + o : nullptr, y + o);
  if (o + 4 <= rows) rows_fma<4, COLS>(w + o * cols, cols, x, tail, b ? b + o : nullptr, y + o), o += 4;
  if (o + 2 <= rows) rows_fma<2, COLS>(w + o * cols, cols, x, tail, b ? b + o : nullptr, y + o), o += 2;
  if (o < rows) rows_fma<1, COLS>(w + o * cols, cols, x, tail, b ? b + o : nullptr, y + o);
}

#undef FWREF_VMATH_INLINE
}  // namespace vmath_detail

// y = W x (+ b when b is not null), W (rows, cols) row-major, any rows >= 1 and cols >= 1; x, b, y
// unaligned, y not aliasing x. 8 rows per pass share each load of x; the last rows % 8 in passes of
// 4, 2, 1. Each y[o] is computed in this order (fwref_vmath checks it bit for bit against a scalar
// statement of it, and against a double-precision sum within its error bound):
//   lane j (0..7): a_j = fma(w[o][i], x[i], a_j) for i = j + 8, j + 16, ... < cols, from a_j = w[o][j] * x[j]
//                  (a_j = 0 where j >= cols: the masked lanes contribute w = x = 0);
//   y[o] = ((a_0 + a_1) + (a_2 + a_3)) + ((a_4 + a_5) + (a_6 + a_7)), then y[o] + b[o].
// Error: |y[o] - sum_i w[o][i] x[i]| <= gamma(ceil(cols / 8) + 3) * sum_i |w[o][i] x[i]| (gamma(n) = n u / (1 - n u),
// u = 2^-24): each product meets at most ceil(cols / 8) roundings in its lane's chain and 3 in the tree.
// The column counts of the paper models' products (channels 23 and 25, and 24 and 32 for their zero-padded
// copies, src/cnode_f32_t.hpp; latent 40, hidden 64 and 80) are compiled with cols as a constant; any other
// count takes the run-time loop. Both perform the same operations in the same order, so the choice never
// changes a result.
inline void gemv_f32_fma(const float* w, int rows, int cols, const float* x, const float* b, float* y) {
  using vmath_detail::gemv_fma_cols;
  switch (cols) {
    case 23: return gemv_fma_cols<23>(w, rows, cols, x, b, y);
    case 24: return gemv_fma_cols<24>(w, rows, cols, x, b, y);  // 23 and 25 channels zero-padded
    case 25: return gemv_fma_cols<25>(w, rows, cols, x, b, y);
    case 32: return gemv_fma_cols<32>(w, rows, cols, x, b, y);
    case 40: return gemv_fma_cols<40>(w, rows, cols, x, b, y);
    case 64: return gemv_fma_cols<64>(w, rows, cols, x, b, y);
    case 80: return gemv_fma_cols<80>(w, rows, cols, x, b, y);
    default: return gemv_fma_cols<0>(w, rows, cols, x, b, y);
  }
}

// The host's product: the run-time choice between the two kernels (one predictable branch; the AVX2
// kernel stays inlined at its call sites). ``reverse`` (the AVX-512 kernel's pass order, see
// fwref/kernels_f32_avx512.hpp) changes no result.
inline void gemv_f32_host(const float* w, int rows, int cols, const float* x, const float* b, float* y,
                          bool reverse = false) {
  if (detail::g_f32_avx512) return gemv_f32_avx512(w, rows, cols, x, b, y, reverse);
  gemv_f32_fma(w, rows, cols, x, b, y);
}

#else

inline const char* matvec_f32_kernel_name() {
#if defined(FWREF_F32_KERNEL_M)
  return gemv_f32_kernel_name();  // matvec_fast's Cortex-M kernel
#else
  return "eigen";
#endif
}

#endif

// y = W x for the fp32 models' Eigen vectors: gemv_f32_host on an AVX2 host (AVX-512 or AVX2, chosen at
// run time), else matvec_fast (Eigen's
// product on a host, the VFP kernel on Cortex-M). ``y`` is resized to W's rows (a Map must already
// have that size); x and y are contiguous and do not alias.
template <class Dst, class Src>
inline void matvec_f32(const MatF& w, const Src& x, Dst&& y) {
#if defined(FWREF_GEMV_FMA)
  y.resize(w.rows);
  gemv_f32_host(w.data, w.rows, w.cols, x.data(), nullptr, y.data());
#else
  matvec_fast(w, x, y);
#endif
}

// y = W x + b (ONNX's MatMul then Add: the bias added to each finished sum, as y += b after matvec_f32).
template <class Dst, class Src>
inline void matvec_bias_f32(const MatF& w, const Src& x, const float* b, Dst&& y) {
#if defined(FWREF_GEMV_FMA)
  y.resize(w.rows);
  gemv_f32_host(w.data, w.rows, w.cols, x.data(), b, y.data());
#else
  matvec_fast(w, x, y);
  y += ConstMapVec(b, w.rows);
#endif
}

}  // namespace fwref
