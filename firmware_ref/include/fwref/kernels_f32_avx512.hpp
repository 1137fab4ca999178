// fwref/kernels_f32_avx512.hpp -- scope: the host's fp32 product y = W x (+ b) on 512-bit vectors,
// for x86-64 CPUs with AVX-512F, chosen at run time (src/kernels_f32_avx512.cpp); the AVX2 kernel of
// fwref/vmath_f32.hpp (gemv_f32_fma) stays the path of every other x86-64 host and the reference the
// tests compare against.
//
//   gemv_f32_avx512(w, rows, cols, x, b, y, reverse)
//                                             W (rows, cols) row-major, any rows, cols >= 1; x, b, y
//                                             unaligned, y not aliasing x; b may be null. reverse: the
//                                             row passes last to first (the same results): a caller
//                                             that alternates the direction from call to call finds
//                                             the rows it read last still in L1 (the GRU's W_hh)
//   gemv_f32_avx512_active()                  true when matvec_f32 runs it (the CPU has AVX-512F and
//                                             FWREF_F32_KERNEL is not "avx2")
//   gemv_f32_select(name)                     "avx2", "avx2field" (the AVX2 kernel, and the CNODE's field in
//                                             one call on AVX2, fwref/field_f32_avx2.hpp) or "avx512": switch
//                                             the choice (false when the CPU does not run it); for the checks
//                                             (tools/fwref_vmath.cpp)
//
// Summation order (checked bit for bit by fwref_vmath against a scalar statement of it): 16 rows per
// pass share each load of x (the last rows % 16 in passes of 8, 4, 2, 1); per row 16 lanes,
//   lane j (0..15): a_j = fma(w[o][i], x[i], a_j) for i = j + 16, j + 32, ... < cols, from a_j = w[o][j] x[j]
//                   when cols >= 16, else from a_j = +0; the last cols % 16 columns through masked loads
//                   (lanes past cols get fma(0, 0, a_j));
//   then halving folds, a_k = a_k + a_{k+8} (k < 8), a_k + a_{k+4} (k < 4), a_k + a_{k+2} (k < 2), a_0 + a_1,
//   the 16 rows' folds done together (shuffles within and across the 128-bit quarters, no horizontal
//   adds), then y[o] + b[o].
//
// The column-major copy (the CNODE's field products, latency-bound at batch 1: no folds at all):
//   pack_f32_t(w, rows, cols, wt)            wt[i * f32_t_stride(rows) + o] = w[o][i], zero for o >= rows
//                                            (cols * f32_t_stride(rows) floats, wt 64-byte aligned)
//   gemv_f32_t_avx512(wt, rows, cols, x, b, y)
//                                            y = W x (+ b) from that copy: 16 rows per vector, each
//                                            column's x[i] broadcast to them, 4 chains per row:
//     s_p = fma(w[o][i], x[i], s_p) for i = p + 4, p + 8, ... < cols, from s_p = w[o][p] x[p] (p < cols;
//     s_p = +0 for p >= cols); y[o] = ((s_0 + s_1) + (s_2 + s_3)), then y[o] + b[o].
//   Error: gamma(ceil(cols / 4) + 2) * sum_i |w[o][i] x[i]|. Checked by fwref_vmath as the other.
//   field_f32_t_avx512(w1t, w2t, H, L, z, v, b2, k)
//                                            the CNODE's field on the copies of lin1_z (H x L) and lin2
//                                            (L x H): k = lin2 tanh(lin1_z z + v) + b2 in one call, the
//                                            hidden vector kept in registers: the same operations as
//                                            gemv_f32_t_avx512, tanh_n, gemv_f32_t_avx512 (so the same
//                                            bits; fwref_vmath checks it). H, L <= 64, else false and
//                                            nothing computed.
//
// Error: |y[o] - sum_i w[o][i] x[i]| <= gamma(ceil(cols / 16) + 4) * sum_i |w[o][i] x[i]|. The order
// differs from the AVX2 kernel's (8 lanes, 3 folds) in the last bits, within the fp32 tolerance
// (core/contracts.py FP32_CPP_REL_TOL; `quadfdi parity`); it depends only on cols, never on alignment
// or on which row pass ran, so every AVX-512 host gives the same bits.
#pragma once

#if defined(__x86_64__) && defined(__AVX2__) && defined(__FMA__) && !defined(FWREF_PORTABLE_KERNELS) && \
    !defined(FWREF_LIBM_ACTIVATIONS)
#define FWREF_HAS_F32_AVX512 1

namespace fwref {

void gemv_f32_avx512(const float* w, int rows, int cols, const float* x, const float* b, float* y, bool reverse = false);
bool gemv_f32_avx512_active();
constexpr int f32_t_stride(int rows) { return (rows + 15) & ~15; }
void pack_f32_t(const float* w, int rows, int cols, float* wt);
void gemv_f32_t_avx512(const float* wt, int rows, int cols, const float* x, const float* b, float* y);
bool field_f32_t_avx512(const float* w1t, const float* w2t, int H, int L, const float* z, const float* v,
                        const float* b2, float* k);
bool gemv_f32_select(const char* name);

namespace detail {
extern bool g_f32_avx512;  // the run-time choice, read by matvec_f32 (fwref/vmath_f32.hpp)
}

}  // namespace fwref
#endif
