// src/kernels_i8.cpp -- scope: the x86-64 int8 kernels of fwref/kernels_i8.hpp and their run-time
// dispatch. Each SIMD kernel is compiled for its instruction set with a target attribute (the rest
// of the build may target a baseline x86-64), and is selected only if cpuid says the CPU runs it.
#include "fwref/kernels_i8.hpp"

#if defined(__x86_64__) && !defined(FWREF_PORTABLE_KERNELS)

#include "fwref/field_w16_avx2.hpp"  // FWREF_HAS_FIELD_W16_AVX2

#include <immintrin.h>

#include <cstdlib>
#include <cstring>

namespace fwref {

namespace {

// One body, two products: DOT(acc, ax, sw) adds the products of |x| (u8) and sign(x) * w (s8).
// Columns go 32 at a time, then one 16- and one 8-column step with the upper part of the vector
// zero (zero products), then the last 1..7 columns as the row's last 8 bytes against x with the
// already counted lanes zeroed (scalar code only for rows shorter than 8); no load reads past a row.
// Rows go 4 at a time, so each x vector (and its |x|) serves 4 rows.
#define FWREF_LOAD32(p) _mm256_loadu_si256(reinterpret_cast<const __m256i*>(p))
#define FWREF_LOAD16(p) _mm256_zextsi128_si256(_mm_loadu_si128(reinterpret_cast<const __m128i*>(p)))
#define FWREF_LOAD8(p) _mm256_zextsi128_si256(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(p)))
// One column step of the 4 rows: x's vector xv (|x| in ax) against each row's LOAD at column ``at``.
#define FWREF_ROWS4(DOT, LOAD, at)                                                                 \
  a0 = DOT(a0, ax, _mm256_sign_epi8(LOAD(r0 + (at)), xv));                                         \
  a1 = DOT(a1, ax, _mm256_sign_epi8(LOAD(r1 + (at)), xv));                                         \
  a2 = DOT(a2, ax, _mm256_sign_epi8(LOAD(r2 + (at)), xv));                                         \
  a3 = DOT(a3, ax, _mm256_sign_epi8(LOAD(r3 + (at)), xv));
#define FWREF_GEMV_BODY(DOT)                                                                       \
  int o = 0;                                                                                       \
  for (; o + 4 <= rows; o += 4) {                                                                  \
    const std::int8_t* r0 = w + o * cols;                                                          \
    const std::int8_t* r1 = r0 + cols;                                                             \
    const std::int8_t* r2 = r1 + cols;                                                             \
    const std::int8_t* r3 = r2 + cols;                                                             \
    __m256i a0 = _mm256_setzero_si256(), a1 = a0, a2 = a0, a3 = a0;                                \
    int i = 0;                                                                                     \
    for (; i + 32 <= cols; i += 32) {                                                              \
      const __m256i xv = FWREF_LOAD32(x + i);                                                      \
      const __m256i ax = _mm256_abs_epi8(xv);                                                      \
      FWREF_ROWS4(DOT, FWREF_LOAD32, i)                                                            \
    }                                                                                              \
    if (i + 16 <= cols) {                                                                          \
      const __m256i xv = FWREF_LOAD16(x + i);                                                      \
      const __m256i ax = _mm256_abs_epi8(xv);                                                      \
      FWREF_ROWS4(DOT, FWREF_LOAD16, i)                                                            \
      i += 16;                                                                                     \
    }                                                                                              \
    if (i + 8 <= cols) {                                                                           \
      const __m256i xv = FWREF_LOAD8(x + i);                                                       \
      const __m256i ax = _mm256_abs_epi8(xv);                                                      \
      FWREF_ROWS4(DOT, FWREF_LOAD8, i)                                                             \
      i += 8;                                                                                      \
    }                                                                                              \
    if (i < cols && cols >= 8) { /* the last 1..7 columns: the row's last 8 bytes, x's first lanes zeroed */ \
      const int keep = cols - i;                                                                   \
      std::uint64_t xq;                                                                            \
      std::memcpy(&xq, x + cols - 8, 8);                                                           \
      xq &= ~std::uint64_t(0) << (8 * (8 - keep));                                                 \
      const __m256i xv = _mm256_zextsi128_si256(_mm_cvtsi64_si128(static_cast<long long>(xq)));    \
      const __m256i ax = _mm256_abs_epi8(xv);                                                      \
      FWREF_ROWS4(DOT, FWREF_LOAD8, cols - 8)                                                      \
      i = cols;                                                                                    \
    }                                                                                              \
    /* [a0 a1 a2 a3] lane sums: two rounds of hadd, then the two 128-bit halves */                 \
    const __m256i h = _mm256_hadd_epi32(_mm256_hadd_epi32(a0, a1), _mm256_hadd_epi32(a2, a3));     \
    __m128i s = _mm_add_epi32(_mm256_castsi256_si128(h), _mm256_extracti128_si256(h, 1));          \
    alignas(16) std::int32_t t[4];                                                                 \
    _mm_store_si128(reinterpret_cast<__m128i*>(t), s);                                             \
    for (; i < cols; ++i) {                                                                        \
      const std::int32_t xi = x[i];                                                                \
      t[0] += r0[i] * xi, t[1] += r1[i] * xi, t[2] += r2[i] * xi, t[3] += r3[i] * xi;              \
    }                                                                                              \
    acc[o] = t[0], acc[o + 1] = t[1], acc[o + 2] = t[2], acc[o + 3] = t[3];                        \
  }                                                                                                \
  if (o < rows) gemv_i8_portable(w + o * cols, rows - o, cols, x, acc + o);

__attribute__((target("avx2"))) inline __m256i dot_avx2(__m256i acc, __m256i ax, __m256i sw) {
  return _mm256_add_epi32(acc, _mm256_madd_epi16(_mm256_maddubs_epi16(ax, sw), _mm256_set1_epi16(1)));
}

__attribute__((target("avx2"))) void gemv_i8_avx2(const std::int8_t* w, int rows, int cols, const std::int8_t* x,
                                                   std::int32_t* acc) {
  FWREF_GEMV_BODY(dot_avx2)
}

__attribute__((target("avx2,avx512f,avx512vl,avx512vnni"))) inline __m256i dot_vnni(__m256i acc, __m256i ax,
                                                                                     __m256i sw) {
  return _mm256_dpbusd_epi32(acc, ax, sw);
}

__attribute__((target("avx2,avx512f,avx512vl,avx512vnni"))) void gemv_i8_avx512vnni(
    const std::int8_t* w, int rows, int cols, const std::int8_t* x, std::int32_t* acc) {
  FWREF_GEMV_BODY(dot_vnni)
}

#undef FWREF_GEMV_BODY
#undef FWREF_ROWS4
#undef FWREF_LOAD8
#undef FWREF_LOAD16
#undef FWREF_LOAD32

// The packed int16 copy (fwref/kernels_i8.hpp): a panel of NB blocks of 8 rows; per column pair one
// broadcast of x's pair and NB vpmaddwd (the weights straight from memory) and NB vpaddd; the NB
// vectors of int32 are the panel's 8 * NB accumulators, stored as they are (no horizontal sums).
// Four pairs per iteration: the copies' rows and x16 are zero-padded to a multiple of 8 columns,
// so ``quads`` = w16_stride(cols) / 8 iterations cover every column (the padding adds zeros).
template <int NB>
__attribute__((target("avx2"))) inline void w16_panel(const std::int16_t* p, const std::int16_t* x16, int quads,
                                                      std::int32_t* acc) {
  __m256i a[NB];
  for (int j = 0; j < NB; ++j) a[j] = _mm256_setzero_si256();
  for (int k = 0; k < quads; ++k, x16 += 8) {
    for (int u = 0; u < 4; ++u, p += 16 * NB) {
      std::int32_t xp;
      std::memcpy(&xp, x16 + 2 * u, 4);
      const __m256i xb = _mm256_set1_epi32(xp);
      for (int j = 0; j < NB; ++j) {
        const __m256i wv = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(p + 16 * j));
        a[j] = _mm256_add_epi32(a[j], _mm256_madd_epi16(xb, wv));
        // Keeps each sum in its register as written: without it GCC reassociates the 16 additions
        // into a tree that needs more than the 16 ymm registers and spills (measured: 10 % more).
        __asm__("" : "+x"(a[j]));
      }
    }
  }
  for (int j = 0; j < NB; ++j) _mm256_storeu_si256(reinterpret_cast<__m256i*>(acc + 8 * j), a[j]);
}

__attribute__((target("avx2"))) void gemv_w16_avx2(const std::int16_t* w, int rows, int cols, const std::int16_t* x16,
                                                    std::int32_t* acc) {
  const int stride = w16_stride(cols), quads = stride / 8, blocks = rows / 8;
  int b = 0;
  for (; b + 4 <= blocks; b += 4) w16_panel<4>(w + 8 * b * stride, x16, quads, acc + 8 * b);
  switch (blocks - b) {
    case 3: w16_panel<3>(w + 8 * b * stride, x16, quads, acc + 8 * b); break;
    case 2: w16_panel<2>(w + 8 * b * stride, x16, quads, acc + 8 * b); break;
    case 1: w16_panel<1>(w + 8 * b * stride, x16, quads, acc + 8 * b); break;
    default: break;
  }
  for (int r = 8 * blocks; r < rows; ++r) {  // the row-major tail rows
    const std::int16_t* row = w + r * stride;
    std::int32_t s = 0;
    for (int c = 0; c < cols; ++c) s += std::int32_t(row[c]) * x16[c];
    acc[r] = s;
  }
}

bool cpu_avx2() {
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx2");
}
bool cpu_vnni() {
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("avx512f") &&
         __builtin_cpu_supports("avx512vl") && __builtin_cpu_supports("avx512vnni");
}

// (VNNI has no int16 dot product beyond vpmaddwd's: its int16 path is the AVX2 one.) avx2field: the avx2
// products, and the int8 CNODE's field in one call on them (fwref/field_w16_avx2.hpp); the best choice of
// an AVX2 CPU without VNNI, FWREF_I8_KERNEL=avx2 keeping the separate steps.
GemvI8Kernel g_kernels[] = {
    {"portable", gemv_i8_portable, true, gemv_w16_portable},
    {"avx2", gemv_i8_avx2, false, gemv_w16_avx2},
#if defined(FWREF_HAS_FIELD_W16_AVX2)
    {"avx2field", gemv_i8_avx2, false, gemv_w16_avx2},
#endif
    {"avx512vnni", gemv_i8_avx512vnni, false, gemv_w16_avx2},
};
constexpr int kKernels = sizeof g_kernels / sizeof g_kernels[0];
int g_active = 0;

bool cpu_runs(const char* name) {
  if (std::strcmp(name, "portable") == 0) return true;
  if (std::strcmp(name, "avx512vnni") == 0) return cpu_vnni();
  if (std::strcmp(name, "avx2field") == 0) return cpu_avx2() && __builtin_cpu_supports("fma");
  return cpu_avx2();
}

// Runs before main (static initialisation of g_gemv_i8): detect, pick the best, honour FWREF_I8_KERNEL.
GemvI8Fn init_dispatch() {
  for (int k = 0; k < kKernels; ++k) {
    g_kernels[k].cpu_runs = cpu_runs(g_kernels[k].name);
    if (g_kernels[k].cpu_runs) g_active = k;
  }
  const char* want = std::getenv("FWREF_I8_KERNEL");
  if (want != nullptr && *want != '\0') {
    for (int k = 0; k < kKernels; ++k) {
      if (std::strcmp(want, g_kernels[k].name) == 0 && g_kernels[k].cpu_runs) g_active = k;
    }
  }
  return g_kernels[g_active].fn;
}

}  // namespace

GemvI8Fn g_gemv_i8 = init_dispatch();
GemvW16Fn g_gemv_w16 = g_kernels[g_active].w16;  // after g_gemv_i8 (same translation unit: in order)

int gemv_i8_kernels(const GemvI8Kernel** out) {
  *out = g_kernels;
  return kKernels;
}

const char* gemv_i8_kernel_name() { return g_kernels[g_active].name; }

#if defined(FWREF_HAS_FIELD_W16_AVX2)
bool field_w16_avx2_active() { return std::strcmp(g_kernels[g_active].name, "avx2field") == 0; }
#endif

bool gemv_i8_select(const char* name) {
  for (int k = 0; k < kKernels; ++k) {
    if (std::strcmp(name, g_kernels[k].name) == 0 && g_kernels[k].cpu_runs) {
      g_active = k;
      g_gemv_i8 = g_kernels[k].fn;
      g_gemv_w16 = g_kernels[k].w16;
      return true;
    }
  }
  return false;
}

const char* fp32_build_isa() {
  return "x86-64"
#ifdef __SSE4_2__
         " sse4.2"
#endif
#ifdef __AVX__
         " avx"
#endif
#ifdef __AVX2__
         " avx2"
#endif
#ifdef __FMA__
         " fma"
#endif
#ifdef __AVX512F__
         " avx512f"
#endif
#ifdef __AVX512VNNI__
         " avx512vnni"
#endif
      ;
}

}  // namespace fwref

#endif
