// fwref/numerics.hpp -- scope: the scalar numerics both models share, written to reproduce ONNX
// Runtime's CPU kernels operation by operation: tanh and the logistic sigmoid (MLAS's rational
// approximations), QuantizeLinear (float32 division, round half to even, saturation), and the int8
// products with int32 accumulation and the documented float rescale order
// (docs/formats.md, "int8 arithmetic"). Compile with -ffp-contract=off: every expression
// below is one IEEE float32 operation per operator, in the order written; the only fused
// multiply-adds are the explicit std::fma calls, which are what MLAS's FMA3 kernels execute.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>

#include "fwref/kernels_i8.hpp"

#if defined(__ARM_FEATURE_SIMD32) || defined(__ARM_FEATURE_SAT)
#include <arm_acle.h>
#endif

namespace fwref {

// A float's bit pattern and back (std::bit_cast is C++20): for checks and tools that walk the floats.
inline std::uint32_t float_bits(float f) {
  std::uint32_t u;
  std::memcpy(&u, &f, 4);
  return u;
}
inline float bits_float(std::uint32_t u) {
  float f;
  std::memcpy(&f, &u, 4);
  return f;
}

// ---------------------------------------------------------------------------------------------
// Activations. ONNX Runtime's Tanh and Sigmoid (and its GRU operator) call MLAS, which evaluates
// Eigen's rational approximations p(x)/q(x) on x clamped to [-9, 9] (tanh) or [-18, 18]
// (logistic, p/q + 1/2); on an x86-64 CPU with FMA3 each Horner step is one fused multiply-add.
// With std::fma here the results are bit-identical to ONNX Runtime 1.32 on such a CPU (0
// mismatches on 40.7 million inputs, docs/firmware.md), so the int8 paths reproduce ORT's integer
// sums exactly. The
// approximation error against the exact function is a few float32 ulps, far below the fp32 parity
// tolerance. On a Cortex-M4F/M7 std::fma is one VFMA.F32 instruction (correctly rounded, as on x86).

// tanh_approx's rational function p(x)/q(x), Horner order (highest power of x^2 first): one table for
// the scalar form below and the 8- and 16-lane forms (vmath_f32.hpp tanh8, kernels_f32_avx512.cpp
// tanh16), so the three cannot drift apart.
struct TanhRational {
  static constexpr float p[7] = {-2.76076847742355e-16f, 2.00018790482477e-13f, -8.60467152213735e-11f,
                                 5.12229709037114e-08f,  1.48572235717979e-05f, 6.37261928875436e-04f,
                                 4.89352455891786e-03f};
  static constexpr float q[4] = {1.19825839466702e-06f, 1.18534705686654e-04f, 2.26843463243900e-03f,
                                 4.89352518554385e-03f};
};

#ifdef FWREF_LIBM_ACTIVATIONS
// Measurement only (cmake -DFWREF_LIBM_ACTIVATIONS=ON): libm's functions, which differ from ONNX
// Runtime's by an ulp at times; docs/firmware.md uses this build to show what such a difference
// does to the int8 results, the reason for the int8 tolerance.
inline float tanh_approx(float x) { return std::tanh(x); }
inline float logistic_approx(float x) { return 1.0f / (1.0f + std::exp(-x)); }
inline float tanh_core(float x) { return tanh_approx(x); }
inline float logistic_core(float x) { return logistic_approx(x); }
#else
// tanh_core / logistic_core: the approximations on an x already inside the clamp range ([-9, 9],
// [-18, 18]), where the clamps are no-ops: the same float operations as *_approx below, which call
// them after clamping. A caller that knows the range cheaply (src/gru_step.cpp tests |x| on its
// bits) skips the two compare-and-branch pairs.
inline float tanh_core(float x) {
  using T = TanhRational;
  const float x2 = x * x;
  float p = std::fma(x2, T::p[0], T::p[1]);
  p = std::fma(p, x2, T::p[2]);
  p = std::fma(p, x2, T::p[3]);
  p = std::fma(p, x2, T::p[4]);
  p = std::fma(p, x2, T::p[5]);
  p = std::fma(p, x2, T::p[6]);
  p = p * x;
  float q = std::fma(x2, T::q[0], T::q[1]);
  q = std::fma(q, x2, T::q[2]);
  q = std::fma(q, x2, T::q[3]);
  return p / q;
}

inline float tanh_approx(float x) {
  x = x < -9.0f ? -9.0f : x;  // NaN propagates (MLAS's two-step clamp)
  x = x > 9.0f ? 9.0f : x;
  return tanh_core(x);
}

inline float logistic_core(float x) {
  const float x2 = x * x;
  float p = std::fma(x2, 4.37031012579801e-11f, 1.15627324459942e-07f);
  p = std::fma(p, x2, 6.08574864600143e-05f);
  p = std::fma(p, x2, 8.51377133304701e-03f);
  p = std::fma(p, x2, 2.48287947061529e-01f);
  p = p * x;
  float q = std::fma(x2, 6.10247389755681e-13f, 5.76102136993427e-09f);
  q = std::fma(q, x2, 6.29106785017040e-06f);
  q = std::fma(q, x2, 1.70198817374094e-03f);
  q = std::fma(q, x2, 1.16817656904453e-01f);
  q = std::fma(q, x2, 9.93151921023180e-01f);
  // Clamped below at 0 only, as MLAS's FMA3 kernel (the one ONNX Runtime runs on such CPUs) does:
  // it returns 1.0000001 near x = 18 (its generic C++ kernel clamps to [0, 1]; measured, see
  // tests/test_firmware.py::test_activations_match_onnx_runtime).
  const float r = p / q + 0.5f;
  return r < 0.0f ? 0.0f : r;
}

inline float logistic_approx(float x) {
  x = x < -18.0f ? -18.0f : x;
  x = x > 18.0f ? 18.0f : x;
  return logistic_core(x);
}
#endif

// ---------------------------------------------------------------------------------------------
// QuantizeLinear with zero point 0: q = clamp(rne(x / s), -128, 127). The division is a float32
// DIVISION (x * (1/s) differs at ties). Clamping before rounding gives the same integer as
// rounding first (the bounds are integers). Round half to even by the 1.5 * 2^23 trick: for
// |v| <= 2^22 the sum's ulp is 1, so the addition rounds v to an integer in the current (default,
// nearest-even) mode; no libm call and no VRINT needed, identical on x86 and Cortex-M. A NaN maps
// to 0 so that the conversion to int is always defined (inputs are checked finite; this only
// guards the int conversion).
#if defined(__ARM_FEATURE_SAT) && defined(__ARM_FP) && !defined(FWREF_PORTABLE_KERNELS)
// Cortex-M4F/M7: the same integer in four instructions. VCVTR.S32.F32 rounds in the FPSCR's mode,
// round to nearest even (the reset value; nothing here changes it), exactly for every float (no
// 2^22 limit), maps NaN to 0 and saturates out-of-range values to the int32 range; SSAT then
// clamps to [-128, 127]. Rounding then clamping equals clamping then rounding because the bounds
// are integers and rounding is monotonic, so q = clamp(rne(x / s), -128, 127) as below, NaN -> 0.
// The division stays a float32 division (x * (1/s) differs at ties).
// quantize_code: the code as an int32 in [-128, 127] (a caller storing it wider, e.g. the CNODE's int16
// stage codes, skips the SXTB that the cast through int8 costs).
inline std::int32_t quantize_code(float x, float scale) {
  const float v = x / scale;
  float r;
  __asm__("vcvtr.s32.f32 %0, %1" : "=t"(r) : "t"(v));
  std::int32_t i;
  std::memcpy(&i, &r, 4);
  return __ssat(i, 8);
}
inline std::int8_t quantize(float x, float scale) { return static_cast<std::int8_t>(quantize_code(x, scale)); }
#else
inline std::int8_t quantize(float x, float scale) {
  float v = x / scale;
  if (!(v == v)) v = 0.0f;
  v = v < -128.0f ? -128.0f : v;
  v = v > 127.0f ? 127.0f : v;
  const float magic = 12582912.0f;  // 1.5 * 2^23
  v = (v + magic) - magic;
  return static_cast<std::int8_t>(static_cast<int>(v));
}
#endif

// sum_i a[i] * b[i] over int8 in int32 (exact: |sum| < 2^24 by fwref/config.hpp's limits, so the
// order of the additions does not matter and every variant below gives the same integer).
#if defined(__ARM_FEATURE_SIMD32)
// Cortex-M4/M7 DSP extension: one 32-bit load brings four int8; SXTB16 sign-extends bytes 0 and 2
// (and, rotated by 8, bytes 1 and 3) into two int16 lanes; SMLAD multiplies both lane pairs and adds
// them to the accumulator: 4 MACs in 8 instructions instead of about 16.
inline std::int32_t dot_i8(const std::int8_t* a, const std::int8_t* b, int n) {
  std::int32_t acc = 0;
  int i = 0;
  for (; i + 4 <= n; i += 4) {
    std::uint32_t wa, wb;
    std::memcpy(&wa, a + i, 4);  // an unaligned LDR (allowed on ARMv7-M)
    std::memcpy(&wb, b + i, 4);
    acc = __smlad(__sxtb16(wa), __sxtb16(wb), acc);
    acc = __smlad(__sxtb16((wa >> 8) | (wa << 24)), __sxtb16((wb >> 8) | (wb << 24)), acc);
  }
  for (; i < n; ++i) acc += static_cast<std::int32_t>(a[i]) * static_cast<std::int32_t>(b[i]);
  return acc;
}
#else
inline std::int32_t dot_i8(const std::int8_t* a, const std::int8_t* b, int n) {
  std::int32_t acc = 0;
  for (int i = 0; i < n; ++i) acc += static_cast<std::int32_t>(a[i]) * static_cast<std::int32_t>(b[i]);
  return acc;
}
#endif

// The one int32 -> float rescale order (docs/formats.md, "int8 arithmetic"), ONNX Runtime's
// com.microsoft.MatMulIntegerToFloat: f32(acc) * f32(s_a * s_w), the multiplier formed first.
inline float rescale_i32(std::int32_t acc, float s_a, float s_w) {
  const float m = s_a * s_w;
  return static_cast<float>(acc) * m;
}

// The linear layers below take the int32 accumulators from gemv_i8 (fwref/kernels_i8.hpp: the
// SIMD kernels, several rows per pass) in blocks of kGemvRowBlock rows, then rescale them here.
constexpr int kGemvRowBlock = 64;

// Pattern A (per-tensor activation scale s_a): y[o] = (f32(acc[o]) * f32(s_a * s_w[o])) + b[o], the
// order of ONNX Runtime's com.microsoft.MatMulIntegerToFloat (the multiplier f32(s_a * s_w[o]) is
// formed first, then one multiply and one add, no FMA). The multiplier is one float32 product,
// so forming it here per row gives the same bits as precomputing it at load.
// ``w`` is (rows, cols) int8 row-major, ``s_w`` (rows,), ``bias`` (rows,), ``x`` (cols,) int8.
// uint8 activations with zero point 128 reach here as their int8 codes q - 128: the integer sum is
// the same. ``w16``: optionally the same weights sign-extended to int16 (Cortex-M builds with
// FWREF_GRU_WHH_INT16, fwref/kernels_i8.hpp), the same accumulators from a faster kernel.
inline void linear_i8_tensor(const std::int8_t* w, const float* s_w, int rows, int cols, const std::int8_t* x,
                             float s_a, const float* bias, float* y, const std::int16_t* w16 = nullptr) {
  std::int32_t acc_i[kGemvRowBlock];
  for (int o0 = 0; o0 < rows; o0 += kGemvRowBlock) {
    const int o1 = rows - o0 < kGemvRowBlock ? rows : o0 + kGemvRowBlock;
    gemv_i8_any(w, w16, o0, o1 - o0, cols, x, acc_i);  // int32 accumulators (fwref/kernels_i8.hpp)
    for (int o = o0; o < o1; ++o) {
      y[o] = rescale_i32(acc_i[o - o0], s_a, s_w[o]) + bias[o];
    }
  }
}

// Pattern B (per-channel activation scales folded into the weight): y[o] = (f32(acc[o]) * s_w'[o]) + b[o]
// (MatMulIntegerToFloat with s_a = 1: f32(1 * s_w') = s_w').
inline void linear_i8_folded(const std::int8_t* w, const float* s_w, int rows, int cols, const std::int8_t* x,
                             const float* bias, float* y, const std::int16_t* w16 = nullptr) {
  std::int32_t acc_i[kGemvRowBlock];
  for (int o0 = 0; o0 < rows; o0 += kGemvRowBlock) {
    const int o1 = rows - o0 < kGemvRowBlock ? rows : o0 + kGemvRowBlock;
    gemv_i8_any(w, w16, o0, o1 - o0, cols, x, acc_i);  // int32 accumulators (fwref/kernels_i8.hpp)
    for (int o = o0; o < o1; ++o) {
      const float acc = static_cast<float>(acc_i[o - o0]);
      y[o] = (acc * s_w[o]) + bias[o];
    }
  }
}

// The normalisation inside every graph: x_norm = (x - mean) / std, a Sub then a Div.
inline float normalise(float x, float mean, float std_) { return (x - mean) / std_; }

}  // namespace fwref
