// src/kernels_f32_avx512.cpp -- scope: the AVX-512F fp32 product of fwref/kernels_f32_avx512.hpp
// (compiled with a target attribute, run only on a CPU that has AVX-512F) and its run-time choice.
#include "fwref/kernels_f32_avx512.hpp"

#include "fwref/field_f32_avx2.hpp"  // gemv_f32_select switches its choice too

#if defined(FWREF_HAS_F32_AVX512)

// GCC 12 warns that the _mm512_undefined_ps() inside _mm512_shuffle_f32x4 / _max_ps / _min_ps "may be /
// is used uninitialized"
// (a false positive inside the intrinsic's header, GCC bug 105593): silenced for this file only.
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
#include <immintrin.h>

#include "fwref/tanh16_avx512.hpp"

#include <cstdlib>
#include <cstring>

namespace fwref {

namespace {

#define FWREF_Z512 __attribute__((target("avx512f"), always_inline)) inline

// fold16's input slot s holds row kSlotRow[s]: then lane r of its result is row r's sum (the shuffles
// below leave the rows in this order; the permutation is its own inverse).
constexpr int kSlotRow[16] = {0, 2, 1, 3, 8, 10, 9, 11, 4, 6, 5, 7, 12, 14, 13, 15};

// 16 slots of 16 lanes -> one vector of 16 row sums, each row's lanes folded as the header states
// (a_k + a_{k+8}, then + 4, + 2, + 1): 8 + 4 + 2 + 1 additions, each of two shuffles of two vectors.
FWREF_Z512 __m512 fold16(const __m512* s) {
  __m512 b[8], c[4], d[2];
  for (int r = 0; r < 8; ++r) {  // 256-bit halves: b[r] = [row r: a_k + a_{k+8} | row r+8: the same]
    b[r] = _mm512_add_ps(_mm512_shuffle_f32x4(s[r], s[r + 8], 0x44), _mm512_shuffle_f32x4(s[r], s[r + 8], 0xEE));
  }
  for (int r = 0; r < 4; ++r) {  // 128-bit quarters: each quarter one row's 4 partial sums
    c[r] = _mm512_add_ps(_mm512_shuffle_f32x4(b[r], b[r + 4], 0x88), _mm512_shuffle_f32x4(b[r], b[r + 4], 0xDD));
  }
  for (int r = 0; r < 2; ++r) {  // within quarters: pairs
    d[r] = _mm512_add_ps(_mm512_shuffle_ps(c[r], c[r + 2], 0x44), _mm512_shuffle_ps(c[r], c[r + 2], 0xEE));
  }
  return _mm512_add_ps(_mm512_shuffle_ps(d[0], d[1], 0x88), _mm512_shuffle_ps(d[0], d[1], 0xDD));
}

// Column i of 16 rows from p (row stride cols) into L1.
FWREF_Z512 void prefetch_rows(const float* p, int cols, int i) {
  for (int r = 0; r < 16; ++r) _mm_prefetch(reinterpret_cast<const char*>(p + r * cols + i), _MM_HINT_T0);
}

// R rows (R <= 16) at w: the order of the header; y[0..R) = the sums (+ b[0..R) when b is not null).
// COLS > 0: cols as a compile-time constant (fixed weight offsets, the packet loop unrolled).
// PF (a matrix larger than L1d, streamed from L2: the GRU's W_hh): each 16-row pass also prefetches
// the rows two passes ahead in its direction (w + pf), one line per weight packet it loads (the
// hardware prefetcher alone kept a 240 x 80 product at about half the L2 probe's bandwidth). A
// prefetch never faults, so the lines past the matrix's ends that the last passes name are harmless.
template <int R, int COLS, bool PF>
FWREF_Z512 void rows16(const float* w, int cols_rt, const float* x, __mmask16 tail, const float* b, float* y,
                       long pf) {
  const int cols = COLS > 0 ? COLS : cols_rt;
  const int n16 = cols & ~15;
  __m512 acc[16];
  for (int r = 0; r < 16; ++r) acc[r] = _mm512_setzero_ps();
  int i = 0;
  if (n16 > 0) {
    const __m512 xv = _mm512_loadu_ps(x);
    for (int r = 0; r < R; ++r) acc[r] = _mm512_mul_ps(_mm512_loadu_ps(w + r * cols), xv);
    if (PF && R == 16) prefetch_rows(w + pf, cols, 0);
    i = 16;
  }
#pragma GCC unroll 16
  for (; i < n16; i += 16) {
    const __m512 xv = _mm512_loadu_ps(x + i);
    for (int r = 0; r < R; ++r) acc[r] = _mm512_fmadd_ps(_mm512_loadu_ps(w + r * cols + i), xv, acc[r]);
    if (PF && R == 16) prefetch_rows(w + pf, cols, i);
  }
  if (n16 < cols) {
    const __m512 xv = _mm512_maskz_loadu_ps(tail, x + n16);
    for (int r = 0; r < R; ++r) acc[r] = _mm512_fmadd_ps(_mm512_maskz_loadu_ps(tail, w + r * cols + n16), xv, acc[r]);
  }
  __m512 slot[16];
  if (PF && R == 16 && n16 < cols) prefetch_rows(w + pf, cols, n16);
  for (int s = 0; s < 16; ++s) slot[s] = acc[kSlotRow[s]];
  __m512 sum = fold16(slot);
  const __mmask16 m = static_cast<__mmask16>(R == 16 ? 0xffffu : (1u << R) - 1u);
  if (b != nullptr) sum = _mm512_add_ps(sum, _mm512_maskz_loadu_ps(m, b));
  _mm512_mask_storeu_ps(y, m, sum);
}

// The last rows % 16 rows (from row ``full``) in passes of 8, 4, 2, 1. (A function, not a lambda in
// gemv_cols: a lambda has no target attribute, so on a build without -mavx512f it could not inline
// rows16.)
template <int COLS, bool PF>
FWREF_Z512 void rest_rows(const float* w, int full, int rows, int cols, const float* x, __mmask16 tail, const float* b,
                          float* y, long pf) {
  int o = full;
  if (o + 8 <= rows) rows16<8, COLS, PF>(w + o * cols, cols, x, tail, b ? b + o : nullptr, y + o, pf), o += 8;
  if (o + 4 <= rows) rows16<4, COLS, PF>(w + o * cols, cols, x, tail, b ? b + o : nullptr, y + o, pf), o += 4;
  if (o + 2 <= rows) rows16<2, COLS, PF>(w + o * cols, cols, x, tail, b ? b + o : nullptr, y + o, pf), o += 2;
  if (o < rows) rows16<1, COLS, PF>(w + o * cols, cols, x, tail, b ? b + o : nullptr, y + o, pf);
}

// All rows: passes of 16, then of 8, 4, 2, 1; REV: the same passes in the opposite order (last first).
template <int COLS, bool PF, bool REV>
__attribute__((target("avx512f"))) void gemv_cols(const float* w, int rows, int cols_rt, const float* x, const float* b,
                                                  float* y) {
  const int cols = COLS > 0 ? COLS : cols_rt;
  const __mmask16 tail = static_cast<__mmask16>((1u << (cols & 15)) - 1u);
  const long pf = (REV ? -32L : 32L) * cols;
  const int full = rows & ~15;
  if (REV) {
    rest_rows<COLS, PF>(w, full, rows, cols, x, tail, b, y, pf);
    for (int o = full - 16; o >= 0; o -= 16) {
      rows16<16, COLS, PF>(w + o * cols, cols, x, tail, b ? b + o : nullptr, y + o, pf);
    }
  } else {
    for (int o = 0; o < full; o += 16) rows16<16, COLS, PF>(w + o * cols, cols, x, tail, b ? b + o : nullptr, y + o, pf);
    rest_rows<COLS, PF>(w, full, rows, cols, x, tail, b, y, pf);
  }
}

// The column-major copy: NB blocks of 16 rows (rows <= 16 NB; the last block's lanes past rows masked
// on the bias load and the store), 4 chains per block over the columns i = p (mod 4), each column's x[i]
// broadcast once for the NB blocks; then ((s0 + s1) + (s2 + s3)) + b, as the header states.
template <int NB>
FWREF_Z512 void col_fma(const float* wt, int rp, int i, const float* x, __m512* s) {
  const __m512 xv = _mm512_set1_ps(x[i]);
  for (int j = 0; j < NB; ++j) s[j] = _mm512_fmadd_ps(_mm512_load_ps(wt + i * rp + 16 * j), xv, s[j]);
}

// The 4 chains of NB blocks of the copy over cols columns, summed: out[j] = ((s0 + s1) + (s2 + s3)).
template <int NB>
FWREF_Z512 void chains_t(const float* wt, int rp, int cols, const float* x, __m512* out) {
  // s0..s3 named (not an array indexed at run time, which GCC kept on the stack)
  __m512 s0[NB], s1[NB], s2[NB], s3[NB];
  for (int j = 0; j < NB; ++j) s0[j] = s1[j] = s2[j] = s3[j] = _mm512_setzero_ps();
  __m512* const chain[4] = {s0, s1, s2, s3};
  for (int p = 0; p < 4; ++p) {  // the first product of each chain: a plain product
    if (p >= cols) break;
    const __m512 xv = _mm512_set1_ps(x[p]);
    for (int j = 0; j < NB; ++j) chain[p][j] = _mm512_mul_ps(_mm512_load_ps(wt + p * rp + 16 * j), xv);
  }
  int i = 4;
  for (; i + 4 <= cols; i += 4) {
    col_fma<NB>(wt, rp, i, x, s0);
    col_fma<NB>(wt, rp, i + 1, x, s1);
    col_fma<NB>(wt, rp, i + 2, x, s2);
    col_fma<NB>(wt, rp, i + 3, x, s3);
  }
  if (i < cols) col_fma<NB>(wt, rp, i, x, s0);
  if (i + 1 < cols) col_fma<NB>(wt, rp, i + 1, x, s1);
  if (i + 2 < cols) col_fma<NB>(wt, rp, i + 2, x, s2);
  for (int j = 0; j < NB; ++j) out[j] = _mm512_add_ps(_mm512_add_ps(s0[j], s1[j]), _mm512_add_ps(s2[j], s3[j]));
}

// y = sum + b over NB blocks of rows: whole blocks with plain loads and stores (a masked store's value
// is not forwarded to a later load of y, which then waits for it to retire), a last partial one masked.
template <int NB>
FWREF_Z512 void store_rows(__m512* sum, int rows, const float* b, float* y) {
  for (int j = 0; j < NB; ++j) {
    const int left = rows - 16 * j;
    if (left >= 16) {
      if (b != nullptr) sum[j] = _mm512_add_ps(sum[j], _mm512_loadu_ps(b + 16 * j));
      _mm512_storeu_ps(y + 16 * j, sum[j]);
      continue;
    }
    const __mmask16 m = static_cast<__mmask16>((1u << left) - 1u);
    if (b != nullptr) sum[j] = _mm512_add_ps(sum[j], _mm512_maskz_loadu_ps(m, b + 16 * j));
    _mm512_mask_storeu_ps(y + 16 * j, m, sum[j]);
  }
}

template <int NB>
FWREF_Z512 void cols_t(const float* wt, int rp, int rows, int cols, const float* x, const float* b, float* y) {
  __m512 sum[NB];
  chains_t<NB>(wt, rp, cols, x, sum);
  store_rows<NB>(sum, rows, b, y);
}

// The fused field: a = tanh(W1 z + v) in NBH registers (stored once to an aligned buffer whose lanes
// lin2 broadcasts), k = W2 a + b2.
template <int NBH, int NBL>
__attribute__((target("avx512f"))) void field_t(const float* w1t, const float* w2t, int H, int L, const float* z,
                                                const float* v, const float* b2, float* k) {
  __m512 a[NBH];
  chains_t<NBH>(w1t, f32_t_stride(H), L, z, a);
  alignas(64) float ab[16 * NBH];
  for (int j = 0; j < NBH; ++j) {
    const int left = H - 16 * j;
    const __mmask16 m = static_cast<__mmask16>(left >= 16 ? 0xffffu : (1u << left) - 1u);
    _mm512_store_ps(ab + 16 * j, tanh16(_mm512_add_ps(a[j], _mm512_maskz_loadu_ps(m, v + 16 * j))));
  }
  __m512 sum[NBL];
  chains_t<NBL>(w2t, f32_t_stride(L), H, ab, sum);
  store_rows<NBL>(sum, L, b2, k);
}

#undef FWREF_Z512

bool cpu_avx512f() {
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx512f");
}

// Before main: AVX-512F when the CPU has it, unless FWREF_F32_KERNEL=avx2 asks for the AVX2 kernel (or
// avx2field for the CNODE's AVX2 field in one call, fwref/field_f32_avx2.hpp).
bool init_choice() {
  const char* want = std::getenv("FWREF_F32_KERNEL");
  return cpu_avx512f() && !(want != nullptr && (std::strcmp(want, "avx2") == 0 || std::strcmp(want, "avx2field") == 0));
}

// The column counts of the paper models' products (channels 23 and 25, latent 40, hidden 64 and 80)
// compiled with cols a constant, any other count in the run-time loop: the same operations in the
// same order either way.
template <bool PF, bool REV>
void gemv_pf(const float* w, int rows, int cols, const float* x, const float* b, float* y) {
  switch (cols) {
    case 23: return gemv_cols<23, PF, REV>(w, rows, cols, x, b, y);
    case 25: return gemv_cols<25, PF, REV>(w, rows, cols, x, b, y);
    case 40: return gemv_cols<40, PF, REV>(w, rows, cols, x, b, y);
    case 64: return gemv_cols<64, PF, REV>(w, rows, cols, x, b, y);
    case 80: return gemv_cols<80, PF, REV>(w, rows, cols, x, b, y);
    default: return gemv_cols<0, PF, REV>(w, rows, cols, x, b, y);
  }
}

}  // namespace

// The prefetching instances for matrices over 32 KiB (more than an L1d holds beside the rest), which
// come from L2 at every call; the result is the same either way, and in either pass order.
void gemv_f32_avx512(const float* w, int rows, int cols, const float* x, const float* b, float* y, bool reverse) {
  if (long(rows) * cols <= 8192) return gemv_pf<false, false>(w, rows, cols, x, b, y);
  if (reverse) return gemv_pf<true, true>(w, rows, cols, x, b, y);
  gemv_pf<true, false>(w, rows, cols, x, b, y);
}

void pack_f32_t(const float* w, int rows, int cols, float* wt) {
  const int rp = f32_t_stride(rows);
  for (int i = 0; i < cols; ++i) {
    for (int o = 0; o < rp; ++o) wt[i * rp + o] = o < rows ? w[o * cols + i] : 0.0f;
  }
}

// 64 rows (4 blocks) per pass over the copy, the last 1..4 blocks in one pass.
__attribute__((target("avx512f"))) void gemv_f32_t_avx512(const float* wt, int rows, int cols, const float* x,
                                                          const float* b, float* y) {
  const int rp = f32_t_stride(rows);
  for (int o = 0; o < rows; o += 64) {
    const int n = rows - o, nb = n >= 64 ? 4 : (n + 15) / 16;
    const float* bo = b != nullptr ? b + o : nullptr;
    switch (nb) {
      case 4: cols_t<4>(wt + o, rp, n, cols, x, bo, y + o); break;
      case 3: cols_t<3>(wt + o, rp, n, cols, x, bo, y + o); break;
      case 2: cols_t<2>(wt + o, rp, n, cols, x, bo, y + o); break;
      default: cols_t<1>(wt + o, rp, n, cols, x, bo, y + o); break;
    }
  }
}

bool field_f32_t_avx512(const float* w1t, const float* w2t, int H, int L, const float* z, const float* v,
                        const float* b2, float* k) {
  using Fn = void (*)(const float*, const float*, int, int, const float*, const float*, const float*, float*);
  static constexpr Fn kFns[4][4] = {{field_t<1, 1>, field_t<1, 2>, field_t<1, 3>, field_t<1, 4>},
                                    {field_t<2, 1>, field_t<2, 2>, field_t<2, 3>, field_t<2, 4>},
                                    {field_t<3, 1>, field_t<3, 2>, field_t<3, 3>, field_t<3, 4>},
                                    {field_t<4, 1>, field_t<4, 2>, field_t<4, 3>, field_t<4, 4>}};
  if (H < 1 || L < 1 || H > 64 || L > 64) return false;
  kFns[(H - 1) / 16][(L - 1) / 16](w1t, w2t, H, L, z, v, b2, k);
  return true;
}

namespace detail {
bool g_f32_avx512 = init_choice();
}

bool gemv_f32_avx512_active() { return detail::g_f32_avx512; }

bool gemv_f32_select(const char* name) {
  if (std::strcmp(name, "avx2") == 0) return detail::field_f32_avx2_set(false), !(detail::g_f32_avx512 = false);
  if (std::strcmp(name, "avx2field") == 0) return detail::field_f32_avx2_set(true) && !(detail::g_f32_avx512 = false);
  if (std::strcmp(name, "avx512") == 0 && cpu_avx512f()) return detail::field_f32_avx2_set(false), (detail::g_f32_avx512 = true);
  return false;
}

}  // namespace fwref

#endif
