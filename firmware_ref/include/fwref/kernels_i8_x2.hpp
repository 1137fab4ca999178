// fwref/kernels_i8_x2.hpp -- scope: the int8 product of one matrix with two vectors,
// acc_a = W xa and acc_b = W xb (int32 accumulators, exact), for the CNODE's lin1_u, which multiplies
// the same weights with each of the S rows of U: on Cortex-M one pass over the weights serves two
// rows of U; elsewhere two calls of fwref/kernels_i8.hpp's gemv_i8.
#pragma once

#include <cstdint>

#include "fwref/kernels_i8.hpp"

namespace fwref {

#if defined(__ARM_FEATURE_SIMD32)
// Two right-hand sides through the same matrix: acc_a = W xa and acc_b = W xb. Each weight word is
// loaded and sign-extended once and serves both vectors (the CNODE's lin1_u, applied to the S rows
// of U: two rows of U per call). 2 rows per pass; per 4 columns one LDM brings both vectors' int16
// pairs ([xa lo, xa hi, xb lo, xb hi], made once per call), then per row and half-word lane one LDR,
// one SXTB16 and two SMLAD (the word is loaded twice: the 12 values of the loop take every register
// GCC gives an asm, so there is none for a second copy): 17 instructions for 16 MACs, plus 3 per 8
// columns for the loop (1.11 per MAC, against 1.375 for gemv_i8's loop). The same exact int32 sums
// as gemv_i8 (any order gives the same integers).
#define FWREF_HAS_I8_X2 1
#define FWREF_M_X2_STEP                                                                             \
  "ldmia  %[xp]!, {%[xa0], %[xa1], %[xb0], %[xb1]}\n\t"                                             \
  "ldr    %[t], [%[p0], %[c]]\n\t"                                                                  \
  "sxtb16 %[t], %[t]\n\t"                                                                           \
  "smlad  %[a1], %[t], %[xa0], %[a1]\n\t"                                                           \
  "smlad  %[b1], %[t], %[xb0], %[b1]\n\t"                                                           \
  "ldr    %[t], [%[p0], %[c]]\n\t"                                                                  \
  "sxtb16 %[t], %[t], ror #8\n\t"                                                                   \
  "smlad  %[a1], %[t], %[xa1], %[a1]\n\t"                                                           \
  "smlad  %[b1], %[t], %[xb1], %[b1]\n\t"                                                           \
  "ldr    %[t], [%[p0]]\n\t"                                                                        \
  "sxtb16 %[t], %[t]\n\t"                                                                           \
  "smlad  %[a0], %[t], %[xa0], %[a0]\n\t"                                                           \
  "smlad  %[b0], %[t], %[xb0], %[b0]\n\t"                                                           \
  "ldr    %[t], [%[p0]], #4\n\t"                                                                    \
  "sxtb16 %[t], %[t], ror #8\n\t"                                                                   \
  "smlad  %[a0], %[t], %[xa1], %[a0]\n\t"                                                           \
  "smlad  %[b0], %[t], %[xb1], %[b0]\n\t"                                                           
#define FWREF_M_X2_OPERANDS                                                                         \
  : [a0] "+&r"(a0), [a1] "+&r"(a1), [b0] "+&r"(b0), [b1] "+&r"(b1), [p0] "+&r"(p0), [xp] "+&r"(xp),   \
    [t] "=&r"(t), [xa0] "=&r"(xa0), [xa1] "=&r"(xa1), [xb0] "=&r"(xb0), [xb1] "=&r"(xb1)
inline void gemv_i8_x2(const std::int8_t* w, int rows, int cols, const std::int8_t* xa, const std::int8_t* xb,
                       std::int32_t* acc_a, std::int32_t* acc_b) {
  if (cols < 4) {
    gemv_i8(w, rows, cols, xa, acc_a);
    gemv_i8(w, rows, cols, xb, acc_b);
    return;
  }
  const int c4 = cols & ~3, c8 = cols & ~7, rem = cols - c4;
  // per 4 columns: xa's SXTB16 pair, then xb's; the last 1..3 columns as one more group from the
  // vectors' last words with the lanes already counted zeroed
  std::uint32_t xe[kMaxGemvCols + 4];
  int k = 0;
  for (int i = 0; i < c4; i += 4, k += 4) {
    const std::uint32_t va = detail::load_u32(xa + i), vb = detail::load_u32(xb + i);
    xe[k] = __sxtb16(va), xe[k + 1] = detail::sxtb16_ror8(va), xe[k + 2] = __sxtb16(vb), xe[k + 3] = detail::sxtb16_ror8(vb);
  }
  if (rem != 0) {
    const std::uint32_t mask = ~0u << (8 * (4 - rem));
    const std::uint32_t va = detail::load_u32(xa + cols - 4) & mask, vb = detail::load_u32(xb + cols - 4) & mask;
    xe[k] = __sxtb16(va), xe[k + 1] = detail::sxtb16_ror8(va), xe[k + 2] = __sxtb16(vb), xe[k + 3] = detail::sxtb16_ror8(vb);
  }
  // A stack slot: the 12 values of the loop take every register the compiler can give.
  const std::uint32_t* volatile xend = xe + c8;
  int o = 0;
  for (; o + 2 <= rows; o += 2) {
    const std::int8_t* p0 = w + o * cols;
    const std::uint32_t* xp = xe;
    std::int32_t a0 = 0, a1 = 0, b0 = 0, b1 = 0;
    std::uint32_t t;
    // LDM fills ascending registers from ascending addresses: fixed registers r0..r3 in that order.
    register std::uint32_t xa0 __asm__("r0");
    register std::uint32_t xa1 __asm__("r1");
    register std::uint32_t xb0 __asm__("r2");
    register std::uint32_t xb1 __asm__("r3");
    if (c8 > 0) {
      __asm__ volatile("1:\n\t" FWREF_M_X2_STEP FWREF_M_X2_STEP
                       "ldr    %[t], %[xend]\n\t"  // t is free until the next step's LDR
                       "cmp    %[xp], %[t]\n\t"
                       "bne    1b\n\t" FWREF_M_X2_OPERANDS
                       : [c] "r"(cols), [xend] "m"(xend)
                       : "cc", "memory");
    }
    if (c4 > c8) {
      __asm__ volatile(FWREF_M_X2_STEP FWREF_M_X2_OPERANDS : [c] "r"(cols) : "memory");
    }
    if (rem != 0) {
      p0 = w + o * cols + cols - 4;  // the rows' last words; xp is at the masked group
      __asm__ volatile(FWREF_M_X2_STEP FWREF_M_X2_OPERANDS : [c] "r"(cols) : "memory");
    }
    acc_a[o] = a0, acc_a[o + 1] = a1, acc_b[o] = b0, acc_b[o + 1] = b1;
  }
  if (o < rows) {
    gemv_i8(w + o * cols, rows - o, cols, xa, acc_a + o);
    gemv_i8(w + o * cols, rows - o, cols, xb, acc_b + o);
  }
}
#undef FWREF_M_X2_STEP
#undef FWREF_M_X2_OPERANDS

#else

// Two right-hand sides through the same matrix (a single-pass kernel on Cortex-M, above).
inline void gemv_i8_x2(const std::int8_t* w, int rows, int cols, const std::int8_t* xa, const std::int8_t* xb,
                       std::int32_t* acc_a, std::int32_t* acc_b) {
  gemv_i8(w, rows, cols, xa, acc_a);
  gemv_i8(w, rows, cols, xb, acc_b);
}
#endif

}  // namespace fwref
