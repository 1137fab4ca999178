// src/field_f32_avx2.cpp -- scope: the fp32 CNODE field in one call on AVX2 + FMA (fwref/field_f32_avx2.hpp)
// and whether src/cnode.cpp runs it (the run-time fp32 choice avx2field).
#include "fwref/field_f32_avx2.hpp"

#if defined(FWREF_HAS_F32_FIELD_AVX2)

#include <immintrin.h>

#include <cstdlib>
#include <cstring>

namespace fwref {

namespace {

#define FWREF_F32F inline __attribute__((always_inline))

// Lanes [0, n) of 8.
FWREF_F32F __m256i lanes(int n) { return _mm256_cmpgt_epi32(_mm256_set1_epi32(n), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7)); }

// Column i of NB blocks times x[i]: s[j] = w x (FIRST) or fma(w, x, s[j]).
template <int NB, bool FIRST>
FWREF_F32F void col(const float* wt, int rp, int i, const float* x, __m256* s) {
  const __m256 xv = _mm256_broadcast_ss(x + i);
#pragma GCC unroll 8
  for (int j = 0; j < NB; ++j) {
    const __m256 w = _mm256_load_ps(wt + i * rp + 8 * j);
    s[j] = FIRST ? _mm256_mul_ps(w, xv) : _mm256_fmadd_ps(w, xv, s[j]);
  }
}

// out[j] (rows 8j .. 8j + 7) = the header's sums over cols columns of the copy wt (row stride rp) times x.
// The chains named s0..s3 (not an array indexed at run time, which GCC keeps on the stack).
template <int NB, int COLS>
FWREF_F32F void chains_t(const float* wt, int rp, int cols_rt, const float* x, __m256* out) {
  const int cols = COLS > 0 ? COLS : cols_rt;
  constexpr int C = NB >= 6 ? 1 : NB >= 3 ? 2 : 4;
  __m256 s0[NB], s1[NB], s2[NB], s3[NB];
#pragma GCC unroll 8
  for (int j = 0; j < NB; ++j) s0[j] = s1[j] = s2[j] = s3[j] = _mm256_setzero_ps();
  col<NB, true>(wt, rp, 0, x, s0);  // cols >= 1
  if (C >= 2 && cols > 1) col<NB, true>(wt, rp, 1, x, s1);
  if (C == 4 && cols > 2) col<NB, true>(wt, rp, 2, x, s2);
  if (C == 4 && cols > 3) col<NB, true>(wt, rp, 3, x, s3);
  int i = C;
  for (; i + C <= cols; i += C) {
    col<NB, false>(wt, rp, i, x, s0);
    if (C >= 2) col<NB, false>(wt, rp, i + 1, x, s1);
    if (C == 4) col<NB, false>(wt, rp, i + 2, x, s2), col<NB, false>(wt, rp, i + 3, x, s3);
  }
  if (i < cols) col<NB, false>(wt, rp, i, x, s0);
  if (C >= 2 && i + 1 < cols) col<NB, false>(wt, rp, i + 1, x, s1);
  if (C == 4 && i + 2 < cols) col<NB, false>(wt, rp, i + 2, x, s2);
#pragma GCC unroll 8
  for (int j = 0; j < NB; ++j) {
    out[j] = C == 1 ? s0[j] : C == 2 ? _mm256_add_ps(s0[j], s1[j]) : _mm256_add_ps(_mm256_add_ps(s0[j], s1[j]), _mm256_add_ps(s2[j], s3[j]));
  }
}

// The 8 floats at p of a row with ``left`` floats from p on: lanes past the row's end are 0 (and not read).
FWREF_F32F __m256 load_block(const float* p, int left) {
  return left >= 8 ? _mm256_loadu_ps(p) : _mm256_maskload_ps(p, lanes(left));
}

// ab = tanh8(lin1_z z + v) for NBH blocks (lanes past H: tanh(0 + 0), never read), L = LC (or L).
template <int NBH, int LC>
FWREF_F32F void hidden_t(const float* w1t, int H, int L, const float* z, const float* v, float* ab) {
  __m256 a[NBH];
  chains_t<NBH, LC>(w1t, f32_t_stride(H), L, z, a);
#pragma GCC unroll 8
  for (int j = 0; j < NBH; ++j) {
    _mm256_store_ps(ab + 8 * j, tanh8(_mm256_add_ps(a[j], load_block(v + 8 * j, H - 8 * j))));
  }
}

// k = lin2 ab + b2 for NBL blocks, H = HC (or H); whole blocks with plain stores, a last partial one masked.
template <int NBL, int HC>
FWREF_F32F void output_t(const float* w2t, int L, int H, const float* ab, const float* b2, float* k) {
  __m256 s[NBL];
  chains_t<NBL, HC>(w2t, f32_t_stride(L), H, ab, s);
#pragma GCC unroll 8
  for (int j = 0; j < NBL; ++j) {
    const int left = L - 8 * j;
    const __m256 y = _mm256_add_ps(s[j], load_block(b2 + 8 * j, left));
    if (left >= 8) {
      _mm256_storeu_ps(k + 8 * j, y);
    } else {
      _mm256_maskstore_ps(k + 8 * j, lanes(left), y);
    }
  }
}

// The paper's shape (H = 64, L = 40) with both column counts constant.
void field_64_40(const float* w1t, const float* w2t, const float* z, const float* v, const float* b2, float* k) {
  alignas(32) float ab[64];
  hidden_t<8, 40>(w1t, 64, 40, z, v, ab);
  output_t<5, 64>(w2t, 40, 64, ab, b2, k);
}

template <int NBH>
void hidden_any(const float* w1t, int H, int L, const float* z, const float* v, float* ab) {
  hidden_t<NBH, 0>(w1t, H, L, z, v, ab);
}
template <int NBL>
void output_any(const float* w2t, int L, int H, const float* ab, const float* b2, float* k) {
  output_t<NBL, 0>(w2t, L, H, ab, b2, k);
}

using HiddenFn = void (*)(const float*, int, int, const float*, const float*, float*);
using OutputFn = void (*)(const float*, int, int, const float*, const float*, float*);
constexpr HiddenFn kHidden[8] = {hidden_any<1>, hidden_any<2>, hidden_any<3>, hidden_any<4>,
                                 hidden_any<5>, hidden_any<6>, hidden_any<7>, hidden_any<8>};
constexpr OutputFn kOutput[8] = {output_any<1>, output_any<2>, output_any<3>, output_any<4>,
                                 output_any<5>, output_any<6>, output_any<7>, output_any<8>};

#undef FWREF_F32F

bool cpu_runs() {
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
}

// Before main: FWREF_F32_KERNEL=avx2field asks for it; avx2 (the row-major gemv) or avx512 on an AVX-512F
// CPU turn it off; unset (or anything else), it is the choice of a CPU without AVX-512F.
bool init_choice() {
  const char* want = std::getenv("FWREF_F32_KERNEL");
  const auto is = [&](const char* name) { return want != nullptr && std::strcmp(want, name) == 0; };
  if (!cpu_runs() || is("avx2")) return false;
  return is("avx2field") || !__builtin_cpu_supports("avx512f");
}

bool g_field = init_choice();

}  // namespace

bool field_f32_t_avx2(const float* w1t, const float* w2t, int H, int L, const float* z, const float* v,
                      const float* b2, float* k) {
  if (H < 1 || L < 1 || H > 64 || L > 64) return false;
  if (H == 64 && L == 40) return field_64_40(w1t, w2t, z, v, b2, k), true;
  alignas(32) float ab[64];
  kHidden[(H - 1) / 8](w1t, H, L, z, v, ab);
  kOutput[(L - 1) / 8](w2t, L, H, ab, b2, k);
  return true;
}

bool field_f32_avx2_active() { return g_field; }

namespace detail {
bool field_f32_avx2_set(bool on) { return g_field = on && cpu_runs(); }
}  // namespace detail

}  // namespace fwref

#endif
