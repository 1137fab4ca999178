// fwref/kernels_w8_vnni.hpp -- scope: x86-64 hosts with AVX-512 VNNI: the int8 products of a
// reused matrix (the GRU's W_ih and W_hh at every step) from a packed int8 copy made once, 16 rows
// per 512-bit vector, with vpdpbusd. The same exact int32 accumulators as every kernel of
// fwref/kernels_i8.hpp (tools/fwref_kernels --check compares them with the portable loop).
//
// vpdpbusd multiplies UNSIGNED bytes by signed bytes: x's int8 codes go in as xu = x + 128 (u8, the
// code's byte XOR 0x80) and each row's accumulator starts at -128 * sum_c W[r][c], so
//   acc[r] = -128 * sum_c W[r][c] + sum_c W[r][c] * (x[c] + 128) = sum_c W[r][c] * x[c],
// exactly: vpdpbusd adds its four u8 x s8 products to the int32 lane without saturation, and every
// partial sum stays far inside int32 (|W| <= 127, x + 128 <= 255, cols < 2^15).
//
// The copy (pack_i8_w8): first the rows' starting values corr[r] = -128 * sum_c W[r][c] (int32),
// then the weights in blocks of 16 rows (the last block: the remaining nr rows), each block the
// w8_cols(cols) / 4 column quads in order, each quad the block's rows' 4 bytes W[r][4k .. 4k + 3]
// (row i of the block at byte 4i: lane i of a vector); columns past cols are zero. Block b starts at
// byte 4 * rows + 16 * b * w8_cols(cols), where row 16b of a row-major copy would: W[16b + i][c] is at
// 4 * rows + 16 * b * w8_cols(cols) + (c / 4) * 4 * nr + 4 * i + c % 4 (nr: the block's rows).
//
// gemv_w8_kernel() returns the kernel only when the run-time choice of fwref/kernels_i8.hpp is
// avx512vnni (so FWREF_I8_KERNEL=avx2 / portable turn it off), else nullptr: callers then use their
// other path. Nothing here exists outside x86-64 (FWREF_HAS_W8_VNNI).
#pragma once

#include <cstdint>

#include "fwref/kernels_i8.hpp"  // kMaxGemvCols

namespace fwref {

#if defined(__x86_64__) && !defined(FWREF_PORTABLE_KERNELS)
#define FWREF_HAS_W8_VNNI 1

constexpr int w8_cols(int cols) { return (cols + 3) & ~3; }
// Bytes of the packed copy of a (rows, cols) matrix.
constexpr long w8_bytes(int rows, int cols) { return 4L * rows + long(rows) * w8_cols(cols); }
// (rows, cols) int8 -> the packed copy above (w8_bytes(rows, cols) bytes; ``out`` 4-byte aligned).
void pack_i8_w8(const std::int8_t* q, int rows, int cols, std::uint8_t* out);

// acc[r] = sum_c W[r][c] * x[c] for the copy ``w8`` and xu[c] = x[c] + 128 (w8_cols(cols) bytes; the
// padding's values do not matter: its weights are zero).
using GemvW8Fn = void (*)(const std::uint8_t* w8, int rows, int cols, const std::uint8_t* xu, std::int32_t* acc);
GemvW8Fn gemv_w8_kernel();
// The reference of the layout: one product at a time (for the checks).
void gemv_w8_portable(const std::uint8_t* w8, int rows, int cols, const std::uint8_t* xu, std::int32_t* acc);
// The VNNI kernel itself, whatever the run-time choice (only where the CPU runs it: for the checks).
void gemv_w8_avx512vnni(const std::uint8_t* w8, int rows, int cols, const std::uint8_t* xu, std::int32_t* acc);

// xu[i] = x[i] + 128 as u8 (the int8 code's byte with its top bit flipped), i < n.
inline void offset_codes_u8(const std::int8_t* x, int n, std::uint8_t* xu) {
  for (int i = 0; i < n; ++i) xu[i] = static_cast<std::uint8_t>(static_cast<std::uint8_t>(x[i]) ^ 0x80u);
}

// acc[r] = sum_c W[r][c] * q[c] for int8 codes q (cols <= kMaxGemvCols) on the copy ``w8``, by ``fn``:
// the codes offset to u8 here, the padding up to w8_cols(cols) set to 128 (read against zero weights).
inline void gemv_w8_codes(GemvW8Fn fn, const std::uint8_t* w8, int rows, int cols, const std::int8_t* q,
                          std::int32_t* acc) {
  alignas(64) std::uint8_t xu[w8_cols(kMaxGemvCols)];
  offset_codes_u8(q, cols, xu);
  for (int i = cols; i < w8_cols(cols); ++i) xu[i] = 128;
  fn(w8, rows, cols, xu, acc);
}
#endif

}  // namespace fwref
