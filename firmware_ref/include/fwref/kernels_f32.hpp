// fwref/kernels_f32.hpp -- scope: the float32 matrix-vector product y = W x of the fp32 models
// (a (rows, cols) row-major matrix, PyTorch's (out, in) layout), and its Cortex-M kernel.
//
//   gemv_f32_portable   the reference: one row at a time, y[o] = ((w[o,0] x[0] + w[o,1] x[1]) + ...),
//                       every product rounded, then every sum (no fused multiply-add);
//   gemv_f32            on ARMv7E-M with a single-precision FPU (Cortex-M4F, M7; __ARM_ARCH_7EM__ and
//                       __ARM_FP): 4 rows per pass in inline assembly, 8 columns per iteration: one
//                       VLDM of 8 x values serves the 4 rows, one VLDM of 8 weights per row, 8 VMLA.F32
//                       per row into one accumulator register per row: 39 instructions for 32 MACs
//                       (1.22 per MAC; Eigen's coefficient loop compiled for the M4 took ~6.5). VMLA is
//                       the non-fused multiply-accumulate (the product is rounded before the addition,
//                       ARMv7-M ARM A7.7.245), so each row's result is exactly the portable loop's:
//                       the same products in the same order, bit for bit;
//                       elsewhere (the host) the portable loop; the host's models keep Eigen's matvec
//                       (fwref/linalg.hpp), see matvec_fast below.
// Cycles (the Cortex-M4 TRM, table 7-1; QEMU counts instructions, not cycles): VLDM of n registers
// takes 1 + n cycles and VMLA.F32 3 cycles, so the M4 spends about 4.4 cycles per MAC in this loop
// (docs/firmware.md, "fp32 kernel"); the Cortex-M7 pipelines VMLA.
#pragma once

#include <cmath>

#include "fwref/linalg.hpp"

#if defined(__ARM_ARCH_7EM__) && defined(__ARM_FP) && !defined(FWREF_PORTABLE_KERNELS)
#define FWREF_F32_KERNEL_M 1
#endif

namespace fwref {

inline void gemv_f32_portable(const float* w, int rows, int cols, const float* x, float* y) {
  for (int o = 0; o < rows; ++o) {
    const float* r = w + o * cols;
    float s = 0.0f;
    for (int i = 0; i < cols; ++i) {
      const float p = r[i] * x[i];  // rounded, then added (the Cortex-M VMLA's arithmetic)
      s = s + p;
    }
    y[o] = s;
  }
}

#if defined(FWREF_F32_KERNEL_M)

// One multiply-accumulate A += W * X, the product rounded before the addition either way:
// VMLA.F32 (default: one instruction, 3 cycles on the M4) or, with FWREF_F32_MUL_ADD, VMUL.F32 +
// VADD.F32 (two instructions, 2 cycles on the M4; W's register is the product's scratch).
#if defined(FWREF_F32_MUL_ADD)
#define FWREF_F32_MAC(A, W, X) "vmul.f32 " W ", " W ", " X "\n\tvadd.f32 %[" A "], %[" A "], " W "\n\t"
#else
#define FWREF_F32_MAC(A, W, X) "vmla.f32 %[" A "], " W ", " X "\n\t"
#endif
// One row's 8 (or 4) columns: its weights into s8.. by one VLDM (write-back), then a MAC into its
// accumulator against x in s0...
#define FWREF_F32_ROW8(P, A)                                                                        \
  "vldmia   %[" P "]!, {s8-s15}\n\t"                                                                \
  FWREF_F32_MAC(A, "s8", "s0")                                                                      \
  FWREF_F32_MAC(A, "s9", "s1")                                                                      \
  FWREF_F32_MAC(A, "s10", "s2")                                                                     \
  FWREF_F32_MAC(A, "s11", "s3")                                                                     \
  FWREF_F32_MAC(A, "s12", "s4")                                                                     \
  FWREF_F32_MAC(A, "s13", "s5")                                                                     \
  FWREF_F32_MAC(A, "s14", "s6")                                                                     \
  FWREF_F32_MAC(A, "s15", "s7")
#define FWREF_F32_ROW4(P, A)                                                                        \
  "vldmia   %[" P "]!, {s8-s11}\n\t"                                                                \
  FWREF_F32_MAC(A, "s8", "s0")                                                                      \
  FWREF_F32_MAC(A, "s9", "s1")                                                                      \
  FWREF_F32_MAC(A, "s10", "s2")                                                                     \
  FWREF_F32_MAC(A, "s11", "s3")
#define FWREF_F32_OPERANDS                                                                          \
  : [a0] "+t"(a0), [a1] "+t"(a1), [a2] "+t"(a2), [a3] "+t"(a3), [p0] "+&r"(p0), [p1] "+&r"(p1),      \
    [p2] "+&r"(p2), [p3] "+&r"(p3), [xp] "+&r"(xp)
#define FWREF_F32_CLOBBERS                                                                          \
  "s0", "s1", "s2", "s3", "s4", "s5", "s6", "s7", "s8", "s9", "s10", "s11", "s12", "s13", "s14", "s15", \
      "cc", "memory"

// Rows go 4 at a time (the last rows % 4 one at a time in C), columns 8 per loop iteration, then
// one 4-column step, then the last 1..3 columns in C: in every case each row's products are added
// in column order into one accumulator starting at 0, as in gemv_f32_portable.
inline void gemv_f32(const float* w, int rows, int cols, const float* x, float* y) {
  const int c8 = cols & ~7, c4 = cols & ~3;
  const float* const xend8 = x + c8;
  int o = 0;
  for (; o + 4 <= rows; o += 4) {
    const float* p0 = w + o * cols;
    const float* p1 = p0 + cols;
    const float* p2 = p1 + cols;
    const float* p3 = p2 + cols;
    const float* xp = x;
    // Fixed registers (callee-saved s16..s19: saved once per call): with free choice GCC gave each
    // of the three asm statements its own and moved the 4 sums between them (9 VMOV per block).
    register float a0 __asm__("s16") = 0.0f;
    register float a1 __asm__("s17") = 0.0f;
    register float a2 __asm__("s18") = 0.0f;
    register float a3 __asm__("s19") = 0.0f;
    if (c8 > 0) {
      __asm__ volatile("1:\n\t"
                       "vldmia   %[xp]!, {s0-s7}\n\t" FWREF_F32_ROW8("p0", "a0") FWREF_F32_ROW8("p1", "a1")
                           FWREF_F32_ROW8("p2", "a2") FWREF_F32_ROW8("p3", "a3")
                       "cmp      %[xp], %[end]\n\t"
                       "bne      1b\n\t" FWREF_F32_OPERANDS
                       : [end] "r"(xend8)
                       : FWREF_F32_CLOBBERS);
    }
    if (c4 > c8) {
      __asm__ volatile("vldmia   %[xp]!, {s0-s3}\n\t" FWREF_F32_ROW4("p0", "a0") FWREF_F32_ROW4("p1", "a1")
                           FWREF_F32_ROW4("p2", "a2") FWREF_F32_ROW4("p3", "a3") FWREF_F32_OPERANDS
                       :
                       : FWREF_F32_CLOBBERS);
    }
    for (int i = c4; i < cols; ++i) {  // p0..p3 point at column c4 of their rows
      const float xi = x[i];
      const int k = i - c4;
      a0 = a0 + p0[k] * xi, a1 = a1 + p1[k] * xi, a2 = a2 + p2[k] * xi, a3 = a3 + p3[k] * xi;
    }
    y[o] = a0, y[o + 1] = a1, y[o + 2] = a2, y[o + 3] = a3;
  }
  if (o < rows) gemv_f32_portable(w + o * cols, rows - o, cols, x, y + o);
}
#undef FWREF_F32_MAC
#undef FWREF_F32_ROW8
#undef FWREF_F32_ROW4
#undef FWREF_F32_OPERANDS
#undef FWREF_F32_CLOBBERS
inline const char* gemv_f32_kernel_name() { return "cortex-m-vfp-4row"; }

#else

inline void gemv_f32(const float* w, int rows, int cols, const float* x, float* y) {
  gemv_f32_portable(w, rows, cols, x, y);
}
inline const char* gemv_f32_kernel_name() { return "portable"; }

#endif

// True when every x[i] (i < n) is finite: the models' check of their input window, run at every
// inference. On the Cortex-M one VMLA per value, acc += x[i] * 0 (+-0 for a finite x; NaN for an
// infinity or a NaN, and a NaN stays NaN through every later addition), 8 values per VLDM: 11
// instructions per 8 values instead of about 8 per value for the std::isfinite loop (1,840 values
// per window for W = 80, C = 23). Elsewhere the std::isfinite loop.
#if defined(FWREF_F32_KERNEL_M)
inline bool all_finite_f32(const float* x, int n) {
  const int n8 = n & ~7;
  const float* p = x;
  const float* const end8 = x + n8;
  float acc = 0.0f;
  const float zero = 0.0f;
  if (n8 > 0) {
    __asm__ volatile(
        "1:\n\t"
        "vldmia   %[p]!, {s0-s7}\n\t"
        "vmla.f32 %[acc], s0, %[z]\n\t"
        "vmla.f32 %[acc], s1, %[z]\n\t"
        "vmla.f32 %[acc], s2, %[z]\n\t"
        "vmla.f32 %[acc], s3, %[z]\n\t"
        "vmla.f32 %[acc], s4, %[z]\n\t"
        "vmla.f32 %[acc], s5, %[z]\n\t"
        "vmla.f32 %[acc], s6, %[z]\n\t"
        "vmla.f32 %[acc], s7, %[z]\n\t"
        "cmp      %[p], %[end]\n\t"
        "bne      1b\n\t"
        : [acc] "+t"(acc), [p] "+&r"(p)
        : [z] "t"(zero), [end] "r"(end8)
        : "s0", "s1", "s2", "s3", "s4", "s5", "s6", "s7", "cc", "memory");
  }
  for (int i = n8; i < n; ++i) acc = acc + x[i] * zero;
  return acc == acc;
}
#else
inline bool all_finite_f32(const float* x, int n) {
  for (int i = 0; i < n; ++i) {
    if (!std::isfinite(x[i])) return false;
  }
  return true;
}
#endif

// y = W x for the models' Eigen vectors: the Cortex-M kernel above on the Cortex-M build, Eigen's
// matvec (vectorised for the host's ISA) elsewhere. ``y`` is resized to W's rows (a Map must
// already have that size); x and y are contiguous and do not alias.
template <class Dst, class Src>
inline void matvec_fast(const MatF& w, const Src& x, Dst&& y) {
#if defined(FWREF_F32_KERNEL_M)
  y.resize(w.rows);
  gemv_f32(w.data, w.rows, w.cols, x.data(), y.data());
#else
  matvec(w, x, y);
#endif
}

}  // namespace fwref
