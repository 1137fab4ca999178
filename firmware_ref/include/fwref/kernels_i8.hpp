// fwref/kernels_i8.hpp -- scope: the int8 matrix-vector kernels: the int32 accumulators
// acc[o] = sum_i W[o, i] * x[i] of a (rows, cols) row-major int8 matrix and an int8 vector. They
// produce integers only; the float rescale of the accumulators stays in fwref/numerics.hpp
// (linear_i8_tensor / linear_i8_folded), in one place.
//
// Every kernel computes the same integers: the sum is exact in int32 (|acc| < 2^24, fwref/config.hpp),
// so the order of the additions does not matter. The kernels:
//   portable    the scalar loop, the reference (tests compare every other kernel with it);
//   avx2        x86-64 AVX2, 4 rows per pass, 32 columns per step: |x| (vpabsb, u8 <= 128) times
//               sign(x) * w (vpsignb, s8: exact because weights are in [-127, 127], docs/formats.md,
//               checked at load) with vpmaddubsw; each pair sum is at most 2 * 128 * 127 = 32512 <
//               32767, so its 16-bit saturation never triggers; vpmaddwd widens to int32;
//   avx2field   the avx2 kernels, and the int8 CNODE's vector field evaluated in one call on the int16
//               copies (fwref/field_w16_avx2.hpp; the same integers and floats, so the same logits): the
//               choice of an AVX2 + FMA CPU without VNNI; FWREF_I8_KERNEL=avx2 keeps the separate steps;
//   avx512vnni  x86-64 AVX-512 VNNI (+VL), the same operands with vpdpbusd (u8 x s8, four products
//               summed into int32 without saturation) on 256-bit vectors (the rows are short); where
//               it is the choice, the host GRU's products use fwref/kernels_w8_vnni.hpp's packed copy;
//   cortex-m    ARMv7E-M DSP (Cortex-M4/M7), 4 rows per pass: x sign-extended once per call into
//               int16 pairs (SXTB16), then per row and 4 columns one LDR, two SXTB16 and two SMLAD
//               (CMSIS-NN's arm_nn_vec_mat_mult_t_s8 loop shape, written for this code base).
// On x86-64 the kernel is chosen at run time (cpuid through __builtin_cpu_supports, once):
// the best one the CPU runs, or the one named by the environment variable FWREF_I8_KERNEL
// (portable, avx2, avx2field, avx512vnni) when the CPU runs it. Elsewhere the portable loop (or the Cortex-M one).
#pragma once

#include <cstdint>
#include <cstring>

#include "fwref/config.hpp"

#if defined(__ARM_FEATURE_SIMD32)
#include <arm_acle.h>
#endif

namespace fwref {

// The reference: one row at a time, one product at a time.
inline void gemv_i8_portable(const std::int8_t* w, int rows, int cols, const std::int8_t* x, std::int32_t* acc) {
  for (int o = 0; o < rows; ++o) {
    const std::int8_t* row = w + o * cols;
    std::int32_t s = 0;
    for (int i = 0; i < cols; ++i) s += static_cast<std::int32_t>(row[i]) * static_cast<std::int32_t>(x[i]);
    acc[o] = s;
  }
}

// The longest row any gemv_i8 call has (the int8 products' inner dimensions; interp's rows are
// summed sparsely in cnode.cpp, not here).
constexpr int max_of(int a, int b) { return a > b ? a : b; }
constexpr int kMaxGemvCols = max_of(max_of(kMaxChannels, kMaxLatent), max_of(kMaxCnodeHidden, kMaxGruHidden));

#if defined(__ARM_FEATURE_SIMD32)

namespace detail {
inline std::uint32_t sxtb16_ror8(std::uint32_t v) {
  std::uint32_t r;
  __asm__("sxtb16 %0, %1, ror #8" : "=r"(r) : "r"(v));
  return r;
}
inline std::uint32_t load_u32(const std::int8_t* p) {
  std::uint32_t v;
  std::memcpy(&v, p, 4);  // an unaligned LDR (allowed on ARMv7-M)
  return v;
}
}  // namespace detail

// Cortex-M4/M7. xe holds x as int16 pairs: xe[2k] = (x[4k], x[4k+2]), xe[2k+1] = (x[4k+1], x[4k+3]),
// which is what SXTB16 and SXTB16 ROR #8 make of a weight word; so 4 products of a row cost one LDR,
// two SXTB16 and two SMLAD, and one LDRD of xe serves 4 rows. The 4-row loop is assembly (8 columns
// per iteration: 44 instructions for 32 products) so that the 13 live values stay in registers:
// rows o and o+1 through p0 and p0 + cols, rows o+2 and o+3 through p2 and p2 + cols. Every
// read-write operand is early-clobber ("+&r"): otherwise GCC may give an input of equal value (the
// end pointer, equal to the next row's start) the same register.
#define FWREF_M_ROWS4_STEP                                                                          \
  "ldrd   %[xa], %[xb], [%[xp]], #8\n\t"                                                            \
  "ldr    %[t], [%[p0], %[c]]\n\t"                                                                  \
  "sxtb16 %[u], %[t]\n\t"                                                                           \
  "smlad  %[a1], %[u], %[xa], %[a1]\n\t"                                                            \
  "sxtb16 %[t], %[t], ror #8\n\t"                                                                   \
  "smlad  %[a1], %[t], %[xb], %[a1]\n\t"                                                            \
  "ldr    %[t], [%[p2], %[c]]\n\t"                                                                  \
  "sxtb16 %[u], %[t]\n\t"                                                                           \
  "smlad  %[a3], %[u], %[xa], %[a3]\n\t"                                                            \
  "sxtb16 %[t], %[t], ror #8\n\t"                                                                   \
  "smlad  %[a3], %[t], %[xb], %[a3]\n\t"                                                            \
  "ldr    %[t], [%[p2]], #4\n\t"                                                                    \
  "sxtb16 %[u], %[t]\n\t"                                                                           \
  "smlad  %[a2], %[u], %[xa], %[a2]\n\t"                                                            \
  "sxtb16 %[t], %[t], ror #8\n\t"                                                                   \
  "smlad  %[a2], %[t], %[xb], %[a2]\n\t"                                                            \
  "ldr    %[t], [%[p0]], #4\n\t"                                                                    \
  "sxtb16 %[u], %[t]\n\t"                                                                           \
  "smlad  %[a0], %[u], %[xa], %[a0]\n\t"                                                            \
  "sxtb16 %[t], %[t], ror #8\n\t"                                                                   \
  "smlad  %[a0], %[t], %[xb], %[a0]\n\t"
inline void gemv_i8(const std::int8_t* w, int rows, int cols, const std::int8_t* x, std::int32_t* acc) {
  const int c4 = cols & ~3, c8 = cols & ~7;
  std::uint32_t xe[kMaxGemvCols / 2 + 2];
  for (int i = 0; i < c4; i += 4) {
    const std::uint32_t v = detail::load_u32(x + i);
    xe[i / 2] = __sxtb16(v);
    xe[i / 2 + 1] = detail::sxtb16_ror8(v);
  }
  // The last 1..3 columns (when cols >= 4): the row's last word against x's last word with the
  // lanes already counted zeroed, one more step of the loop body.
  const int rem = cols - c4;
  std::uint32_t xt[2] = {0, 0};
  if (rem != 0 && cols >= 4) {
    const std::uint32_t v = detail::load_u32(x + cols - 4) & (~0u << (8 * (4 - rem)));
    xt[0] = __sxtb16(v);
    xt[1] = detail::sxtb16_ror8(v);
  }
  int o = 0;
  for (; o + 4 <= rows; o += 4) {
    const std::int8_t* p0 = w + o * cols;
    const std::int8_t* p2 = p0 + 2 * cols;
    const std::int8_t* const end8 = p0 + c8;
    const std::uint32_t* xp = xe;
    std::int32_t a0 = 0, a1 = 0, a2 = 0, a3 = 0;
    std::uint32_t xa, xb, t, u;
    if (c8 > 0) {
      __asm__ volatile("1:\n\t" FWREF_M_ROWS4_STEP FWREF_M_ROWS4_STEP
                       "cmp    %[p0], %[end]\n\t"
                       "bne    1b\n\t"
                       : [a0] "+&r"(a0), [a1] "+&r"(a1), [a2] "+&r"(a2), [a3] "+&r"(a3), [p0] "+&r"(p0), [p2] "+&r"(p2),
                         [xp] "+&r"(xp), [xa] "=&r"(xa), [xb] "=&r"(xb), [t] "=&r"(t), [u] "=&r"(u)
                       : [c] "r"(cols), [end] "r"(end8)
                       : "cc", "memory");
    }
    if (c4 > c8) {
      __asm__ volatile(FWREF_M_ROWS4_STEP
                       : [a0] "+&r"(a0), [a1] "+&r"(a1), [a2] "+&r"(a2), [a3] "+&r"(a3), [p0] "+&r"(p0), [p2] "+&r"(p2),
                         [xp] "+&r"(xp), [xa] "=&r"(xa), [xb] "=&r"(xb), [t] "=&r"(t), [u] "=&r"(u)
                       : [c] "r"(cols)
                       : "memory");
    }
    if (rem != 0 && cols >= 4) {
      p0 = w + o * cols + cols - 4;
      p2 = p0 + 2 * cols;
      xp = xt;
      __asm__ volatile(FWREF_M_ROWS4_STEP
                       : [a0] "+&r"(a0), [a1] "+&r"(a1), [a2] "+&r"(a2), [a3] "+&r"(a3), [p0] "+&r"(p0), [p2] "+&r"(p2),
                         [xp] "+&r"(xp), [xa] "=&r"(xa), [xb] "=&r"(xb), [t] "=&r"(t), [u] "=&r"(u)
                       : [c] "r"(cols)
                       : "memory");
    } else {
      for (int i = c4; i < cols; ++i, ++p0, ++p2) {  // p0, p2 now point at column c4 of rows o, o + 2
        const std::int32_t xi = x[i];
        a0 += p0[0] * xi, a1 += p0[cols] * xi, a2 += p2[0] * xi, a3 += p2[cols] * xi;
      }
    }
    acc[o] = a0, acc[o + 1] = a1, acc[o + 2] = a2, acc[o + 3] = a3;
  }
  for (; o < rows; ++o) {
    const std::int8_t* r0 = w + o * cols;
    std::int32_t a0 = 0;
    const std::uint32_t* xp = xe;
    for (int i = 0; i < c4; i += 4, xp += 2) {
      const std::uint32_t v = detail::load_u32(r0 + i);
      a0 = __smlad(__sxtb16(v), xp[0], a0);
      a0 = __smlad(detail::sxtb16_ror8(v), xp[1], a0);
    }
    for (int i = c4; i < cols; ++i) a0 += r0[i] * static_cast<std::int32_t>(x[i]);
    acc[o] = a0;
  }
}
#undef FWREF_M_ROWS4_STEP

#if defined(FWREF_GRU_WHH_INT16) || defined(FWREF_CNODE_W_INT16)
#define FWREF_HAS_W16_KERNEL 1
// The same products with the weights already sign-extended to int16 (a copy in RAM made once at
// load by expand_i8_to_i16; weights.bin and flash keep int8), repacked so that one pointer walks
// them in the order the kernel reads them: per block of 4 rows and per 4 columns, 16 int16
// [row0 c0..c3, row1 c0..c3, row2 c0..c3, row3 c0..c3]. One LDM of 4 words brings 2 rows x 4
// columns, one LDRD the 4 columns of x (plain int16 pairs): 4 columns of 4 rows are LDRD, 2 LDM and
// 8 SMLAD, 11 instructions for 16 products (0.69 per MAC) plus the loop's 3 per 8 columns. Rows
// are padded with zeros to a multiple of 8 columns; the rows after the last whole block of 4 stay
// row-major (stride w16_stride(cols)). Block b starts at element 4 * b * stride, as row 4b of a
// row-major copy would, so rows [o0, o0 + n) with o0 a multiple of 4 start at o0 * stride.
// Row stride of the int16 copies: cols rounded up to 8, the tail zero (x's copy is zero there too).
constexpr int w16_stride(int cols) { return (cols + 7) & ~7; }
// (rows, cols) int8 -> the blocked int16 copy above ((rows, w16_stride(cols)) elements), padding zero.
inline void expand_i8_to_i16(const std::int8_t* q, int rows, int cols, std::int16_t* out) {
  const int stride = w16_stride(cols);
  const int blocked = rows & ~3;
  for (int o = 0; o < rows; ++o) {
    for (int i = 0; i < stride; ++i) {
      const std::int16_t v = i < cols ? q[o * cols + i] : 0;
      if (o < blocked) {
        out[(o & ~3) * stride + (i / 4) * 16 + (o & 3) * 4 + (i & 3)] = v;
      } else {
        out[o * stride + i] = v;
      }
    }
  }
}
#define FWREF_M_W16_COLS4                                                                           \
  "ldrd   %[xa], %[xb], [%[xp]], #8\n\t"                                                            \
  "ldmia  %[p]!, {%[w0], %[w1], %[w2], %[w3]}\n\t"                                                  \
  "smlad  %[a0], %[w0], %[xa], %[a0]\n\t"                                                           \
  "smlad  %[a0], %[w1], %[xb], %[a0]\n\t"                                                           \
  "smlad  %[a1], %[w2], %[xa], %[a1]\n\t"                                                           \
  "smlad  %[a1], %[w3], %[xb], %[a1]\n\t"                                                           \
  "ldmia  %[p]!, {%[w0], %[w1], %[w2], %[w3]}\n\t"                                                  \
  "smlad  %[a2], %[w0], %[xa], %[a2]\n\t"                                                           \
  "smlad  %[a2], %[w1], %[xb], %[a2]\n\t"                                                           \
  "smlad  %[a3], %[w2], %[xa], %[a3]\n\t"                                                           \
  "smlad  %[a3], %[w3], %[xb], %[a3]\n\t"
// ``w``: the blocked int16 copy; ``x16``: x as int16, word-aligned (LDRD), w16_stride(cols) long
// with zeros after cols. The caller that quantizes x can write it so directly (no widening pass).
// The first 4 columns of a block start the sums with SMUAD (no accumulator to zero) instead of SMLAD.
#define FWREF_M_W16_COLS4_FIRST                                                                     \
  "ldrd   %[xa], %[xb], [%[xp]], #8\n\t"                                                            \
  "ldmia  %[p]!, {%[w0], %[w1], %[w2], %[w3]}\n\t"                                                  \
  "smuad  %[a0], %[w0], %[xa]\n\t"                                                                 \
  "smlad  %[a0], %[w1], %[xb], %[a0]\n\t"                                                           \
  "smuad  %[a1], %[w2], %[xa]\n\t"                                                                 \
  "smlad  %[a1], %[w3], %[xb], %[a1]\n\t"                                                           \
  "ldmia  %[p]!, {%[w0], %[w1], %[w2], %[w3]}\n\t"                                                  \
  "smuad  %[a2], %[w0], %[xa]\n\t"                                                                 \
  "smlad  %[a2], %[w1], %[xb], %[a2]\n\t"                                                           \
  "smuad  %[a3], %[w2], %[xa]\n\t"                                                                 \
  "smlad  %[a3], %[w3], %[xb], %[a3]\n\t"
// Per block of 4 rows: the first 8 columns (w16_stride(cols) >= 8 always), then the loop over the
// rest; the block's 4 sums go straight to acc through a pointer (no row counter to keep: the loop's
// values already take every register, so a counter would live on the stack).
inline void gemv_w16_x16(const std::int16_t* w, int rows, int cols, const std::int16_t* x16, std::int32_t* acc) {
  const int stride = w16_stride(cols);
  // A stack slot: the 12 values of the loop fill the registers the compiler can give (see the asm).
  const std::int16_t* volatile xend = x16 + stride;
  const std::int16_t* p = w;
  std::int32_t* out = acc;
  std::int32_t* const out_end = acc + (rows & ~3);
  for (; out != out_end; out += 4) {
    const std::int16_t* xp = x16;
    std::int32_t a0, a1, a2, a3;
    std::uint32_t xa, xb;
    // LDM takes its registers in ascending order and fills them from ascending addresses: fixed
    // registers, so that w0..w3 are the 1st..4th word (r0..r3, ascending).
    register std::uint32_t w0 __asm__("r0");
    register std::uint32_t w1 __asm__("r1");
    register std::uint32_t w2 __asm__("r2");
    register std::uint32_t w3 __asm__("r3");
    __asm__ volatile(FWREF_M_W16_COLS4_FIRST FWREF_M_W16_COLS4
                     "ldr    %[w0], %[xend]\n\t"  // w0 is free until the next LDM
                     "cmp    %[xp], %[w0]\n\t"
                     "beq    2f\n\t"
                     "1:\n\t" FWREF_M_W16_COLS4 FWREF_M_W16_COLS4
                     "ldr    %[w0], %[xend]\n\t"
                     "cmp    %[xp], %[w0]\n\t"
                     "bne    1b\n\t"
                     "2:\n\t"
                     : [a0] "=&r"(a0), [a1] "=&r"(a1), [a2] "=&r"(a2), [a3] "=&r"(a3), [p] "+&r"(p), [xp] "+&r"(xp),
                       [xa] "=&r"(xa), [xb] "=&r"(xb), [w0] "=&r"(w0), [w1] "=&r"(w1), [w2] "=&r"(w2), [w3] "=&r"(w3)
                     : [xend] "m"(xend)
                     : "cc", "memory");
    out[0] = a0, out[1] = a1, out[2] = a2, out[3] = a3;
  }
  for (int o = rows & ~3; o < rows; ++o) {  // the row-major tail rows
    const std::int16_t* r = w + o * stride;
    std::int32_t s = 0;
    for (int i = 0; i < stride; ++i) s += std::int32_t(r[i]) * x16[i];
    acc[o] = s;
  }
}
#undef FWREF_M_W16_COLS4_FIRST
#undef FWREF_M_W16_COLS4
#endif
inline const char* gemv_i8_kernel_name() { return "cortex-m-dsp-4row"; }

#elif defined(__x86_64__) && !defined(FWREF_PORTABLE_KERNELS)

// x86-64: run-time dispatch (src/kernels_i8.cpp).
using GemvI8Fn = void (*)(const std::int8_t* w, int rows, int cols, const std::int8_t* x, std::int32_t* acc);
extern GemvI8Fn g_gemv_i8;
inline void gemv_i8(const std::int8_t* w, int rows, int cols, const std::int8_t* x, std::int32_t* acc) {
  g_gemv_i8(w, rows, cols, x, acc);
}
// The int16 path (FWREF_CNODE_W_INT16 / FWREF_GRU_WHH_INT16, on by default on the host): the
// weights sign-extended to int16 once (expand_i8_to_i16, at the first inference) and packed for
// vpmaddwd: per block of 8 rows and per column pair k, one 256-bit vector of the 8 rows' int16
// pairs (w[r][2k], w[r][2k+1]); blocks go in panels of up to 4 (32 rows) so that one broadcast pair
// of x serves 4 vectors; within a panel of nb blocks the vector of block j, pair k is at
// (k * nb + j) * 16. Panels start at element 8 * b * stride (b: the panel's first block), where
// row 8b of a row-major copy would; rows after the last whole block of 8 are row-major. Hence rows
// [o0, o0 + n) can be multiplied on their own when o0 is a multiple of 32 and n is a multiple of
// 32 or reaches the last row (the callers' blocks of kGemvRowBlock rows are). Exact: int16
// products summed in int32 by vpmaddwd, as the int8 ones are (|acc| < 2^24).
constexpr int w16_stride(int cols) { return (cols + 7) & ~7; }
inline long w16_index(int r, int c, int rows, int stride) {
  const int blocks = rows / 8;
  if (r >= 8 * blocks) return long(r) * stride + c;
  const int b = r / 8, b0 = b & ~3, nb = blocks - b0 < 4 ? blocks - b0 : 4;
  return long(8 * b0) * stride + (long(c / 2) * nb + (b - b0)) * 16 + (r % 8) * 2 + (c & 1);
}
// (rows, cols) int8 -> the packed int16 copy above (rows * w16_stride(cols) elements), padding zero.
inline void expand_i8_to_i16(const std::int8_t* q, int rows, int cols, std::int16_t* out) {
  const int stride = w16_stride(cols);
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < stride; ++c) out[w16_index(r, c, rows, stride)] = c < cols ? q[r * cols + c] : 0;
  }
}
// x16: x as int16, w16_stride(cols) long, zero after cols.
using GemvW16Fn = void (*)(const std::int16_t* w, int rows, int cols, const std::int16_t* x16, std::int32_t* acc);
extern GemvW16Fn g_gemv_w16;
#define FWREF_HAS_W16_KERNEL 1
inline void gemv_w16_x16(const std::int16_t* w, int rows, int cols, const std::int16_t* x16, std::int32_t* acc) {
  g_gemv_w16(w, rows, cols, x16, acc);
}
// The reference of the packed layout: one product at a time.
inline void gemv_w16_portable(const std::int16_t* w, int rows, int cols, const std::int16_t* x16, std::int32_t* acc) {
  const int stride = w16_stride(cols);
  for (int r = 0; r < rows; ++r) {
    std::int32_t s = 0;
    for (int c = 0; c < cols; ++c) s += std::int32_t(w[w16_index(r, c, rows, stride)]) * x16[c];
    acc[r] = s;
  }
}
// The kernels this build has, and whether the CPU runs each (index 0 is the portable one); ``w16``
// is the same instruction set's kernel for the packed int16 copy.
struct GemvI8Kernel {
  const char* name;
  GemvI8Fn fn;
  bool cpu_runs;
  GemvW16Fn w16;
};
int gemv_i8_kernels(const GemvI8Kernel** out);
const char* gemv_i8_kernel_name();
// Select by name; false (and no change) when unknown or when this CPU cannot run it.
bool gemv_i8_select(const char* name);
// The instruction sets the fp32 code was compiled for (e.g. "avx2 fma"), from the compiler's macros.
const char* fp32_build_isa();

#else

inline void gemv_i8(const std::int8_t* w, int rows, int cols, const std::int8_t* x, std::int32_t* acc) {
  gemv_i8_portable(w, rows, cols, x, acc);
}
inline const char* gemv_i8_kernel_name() { return "portable"; }

#endif

#if defined(FWREF_HAS_W16_KERNEL)
// The int16 product with int8 x, widened here (once per call) into the zero-padded int16 x the kernel reads:
// 32-byte aligned for x86-64's vector loads, 8 on Cortex-M (LDRD; no more stack than that needs).
inline void gemv_i8w16(const std::int16_t* w, int rows, int cols, const std::int8_t* x, std::int32_t* acc) {
#if defined(__x86_64__)
  constexpr std::size_t kAlign = 32;
#else
  constexpr std::size_t kAlign = 8;
#endif
  const int stride = w16_stride(cols);
  alignas(kAlign) std::int16_t x16[w16_stride(kMaxGemvCols)];
  for (int i = 0; i < cols; ++i) x16[i] = x[i];
  for (int i = cols; i < stride; ++i) x16[i] = 0;
  gemv_w16_x16(w, rows, cols, x16, acc);
}
#endif

// Rows [o0, o0 + rows) of the matrix: from its int16 copy ``w16`` when there is one and the kernel
// for it is built (Cortex-M, FWREF_GRU_WHH_INT16 or FWREF_CNODE_W_INT16), else from the int8 ``w``.
inline void gemv_i8_any(const std::int8_t* w, const std::int16_t* w16, int o0, int rows, int cols,
                        const std::int8_t* x, std::int32_t* acc) {
#if defined(FWREF_HAS_W16_KERNEL)
  if (w16 != nullptr) {
    gemv_i8w16(w16 + o0 * w16_stride(cols), rows, cols, x, acc);
    return;
  }
#else
  (void)w16;
#endif
  gemv_i8(w + o0 * cols, rows, cols, x, acc);
}

}  // namespace fwref
