// scripts/cnode_u8_avx2_micro.cpp -- would the int8 CNODE field on an AVX2 host be faster with u8 x s8 products
// (vpmaddubsw + vpmaddwd by ones + vpaddd: 3 vector ops per 8 rows x 4 columns) than with the shipped int16 copies
// (vpmaddwd + vpaddd per 8 rows x 2 columns: 4 ops per 8 rows x 4 columns)? A measurement, not shipped code.
//
// The paper's shapes (H = 64, L = 40), 7-bit weights in [-63, 63] as the exports' uint8 encoding has them (so
// a u8 code (<= 255) times a weight, summed in pairs, stays <= 2 * 255 * 63 = 32130: vpmaddubsw cannot
// saturate); z's and the hidden layer's codes go in as u8 = code + 128 and each row's accumulator starts at
// -128 * sum(w), so the int32 sums are exactly the int16 path's. Everything after the products is the shipped
// field's code (src/field_w16_avx2.cpp): the same float operations in the same order. The check: k of the u8
// field equals fwref::field_w16_avx2's bit for bit over a serial chain of 32 evaluations x 200 draws. The
// timing: the two fields interleaved over 9 rounds of 2,000 chains of 32 evaluations (median per evaluation).
//
//   g++ -O3 -std=c++17 -march=native -ffp-contract=off -fno-trapping-math -DFWREF_CNODE_W_INT16 -Ifirmware_ref/include
//       -I/usr/include/eigen3 scripts/cnode_u8_avx2_micro.cpp firmware_ref/src/kernels_i8.cpp
//       firmware_ref/src/field_w16_avx2.cpp -o /tmp/cnode_u8_avx2_micro
//   FWREF_I8_KERNEL=avx2field taskset -c 1 /tmp/cnode_u8_avx2_micro
#include <immintrin.h>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <random>
#include <vector>

#include "fwref/field_w16_avx2.hpp"
#include "fwref/kernels_i8.hpp"
#include "fwref/vmath_i8.hpp"
#include "micro_timing.hpp"

namespace {

constexpr int H = 64, L = 40, E = 32;
using fwref::vmath_i8_detail::pack16;
using fwref::vmath_i8_detail::quantize8;

// u8 packing: block j (rows 8j..8j+7), group g (columns 4g..4g+3) at (g * NB + j) * 32: row r's 4 weights at r * 4.
void pack_u8(const std::int8_t* w, int rows, int cols, std::int8_t* out, std::int32_t* init) {
  const int nb = rows / 8;
  for (int g = 0; g < cols / 4; ++g)
    for (int j = 0; j < nb; ++j)
      for (int r = 0; r < 8; ++r)
        for (int c = 0; c < 4; ++c) out[(g * nb + j) * 32 + r * 4 + c] = w[(8 * j + r) * cols + 4 * g + c];
  for (int r = 0; r < rows; ++r) {
    int s = 0;
    for (int c = 0; c < cols; ++c) s += w[r * cols + c];
    init[r] = -128 * s;
  }
}

template <int NB, int COLS>
inline __attribute__((always_inline)) void product_u8(const std::int8_t* w, const std::int32_t* init,
                                                      const std::uint8_t* xu, __m256i* acc) {
  const __m256i ones = _mm256_set1_epi16(1);
#pragma GCC unroll 8
  for (int j = 0; j < NB; ++j) acc[j] = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(init + 8 * j));
#pragma GCC unroll 4
  for (int g = 0; g < COLS / 4; ++g) {
    std::int32_t xp;
    std::memcpy(&xp, xu + 4 * g, 4);
    const __m256i xb = _mm256_set1_epi32(xp);
#pragma GCC unroll 8
    for (int j = 0; j < NB; ++j) {
      const __m256i wv = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(w + (g * NB + j) * 32));
      acc[j] = _mm256_add_epi32(acc[j], _mm256_madd_epi16(_mm256_maddubs_epi16(xb, wv), ones));
    }
  }
}

inline __attribute__((always_inline)) void store_u8(__m256i codes32, std::uint8_t* dst) {
  const __m128i c16 = _mm_add_epi16(pack16(codes32), _mm_set1_epi16(128));
  _mm_storel_epi64(reinterpret_cast<__m128i*>(dst), _mm_packus_epi16(c16, c16));
}

struct FieldU8 {
  const std::int8_t *w1, *w2;
  const std::int32_t *init1, *init2;
  const float *s_w1, *mult2, *b2;
  float s_hidden;
};

void field_u8(const FieldU8& f, const float* z, float s_z, const float* v, float* k) {
  alignas(16) std::uint8_t zu[L], hu[H];
  const __m256 sz = _mm256_set1_ps(s_z);
  for (int i = 0; i < L; i += 8) store_u8(quantize8(_mm256_loadu_ps(z + i), sz), zu + i);
  __m256i acc[8];
  product_u8<8, L>(f.w1, f.init1, zu, acc);
  const __m256 sh = _mm256_set1_ps(f.s_hidden);
  for (int j = 0; j < 8; ++j) {
    const __m256 m = _mm256_mul_ps(sz, _mm256_loadu_ps(f.s_w1 + 8 * j));
    const __m256 y = _mm256_add_ps(_mm256_mul_ps(_mm256_cvtepi32_ps(acc[j]), m), _mm256_loadu_ps(v + 8 * j));
    store_u8(quantize8(fwref::tanh8(y), sh), hu + 8 * j);
  }
  product_u8<5, H>(f.w2, f.init2, hu, acc);
  for (int j = 0; j < 5; ++j) {
    const __m256 y = _mm256_add_ps(_mm256_mul_ps(_mm256_cvtepi32_ps(acc[j]), _mm256_loadu_ps(f.mult2 + 8 * j)),
                                   _mm256_loadu_ps(f.b2 + 8 * j));
    _mm256_storeu_ps(k + 8 * j, y);
  }
}

struct Model {
  alignas(64) std::int16_t w1[H * L], w2[L * H];
  alignas(64) std::int8_t p1[H * L], p2[L * H];
  alignas(64) std::int32_t init1[H], init2[L];
  float s_w1[H], s_w2[H], mult2[L], b2[L], v[H], s_z[E], s_hid = 1.0f / 127.0f;
};

}  // namespace

int main() {
  if (!fwref::field_w16_avx2_active()) {
    std::printf("cnode_u8_avx2_micro: run with FWREF_I8_KERNEL=avx2field on an AVX2 + FMA CPU\n");
    return 1;
  }
  std::mt19937 rng(1);
  std::uniform_int_distribution<int> wd(-63, 63);
  std::normal_distribution<float> nd(0.0f, 1.0f);
  static Model m;
  std::vector<std::int8_t> q1(H * L), q2(L * H);
  long differ = 0, compared = 0;
  alignas(64) float z[64] = {}, za[64] = {}, zb[64] = {};
  for (int draw = 0; draw < 200; ++draw) {
    for (auto& q : q1) q = static_cast<std::int8_t>(wd(rng));
    for (auto& q : q2) q = static_cast<std::int8_t>(wd(rng));
    if (draw % 50 == 0) std::fill(q1.begin(), q1.begin() + 8 * L, std::int8_t{63});  // all-max rows
    fwref::expand_i8_to_i16(q1.data(), H, L, m.w1);
    fwref::expand_i8_to_i16(q2.data(), L, H, m.w2);
    pack_u8(q1.data(), H, L, m.p1, m.init1);
    pack_u8(q2.data(), L, H, m.p2, m.init2);
    for (int i = 0; i < H; ++i) m.s_w1[i] = 0.02f / 63.0f, m.v[i] = 0.3f * nd(rng);
    for (int i = 0; i < L; ++i) m.s_w2[i] = 0.04f / 63.0f, m.mult2[i] = m.s_hid * m.s_w2[i], m.b2[i] = 0.1f * nd(rng);
    for (int e = 0; e < E; ++e) m.s_z[e] = 2.0f / 127.0f;
    for (int i = 0; i < L; ++i) za[i] = zb[i] = (draw % 7 == 0 ? 4.0f : 1.0f) * nd(rng);  // some saturate
    const fwref::FieldW16 f16{m.w1, m.w2, H, L, m.s_w1, m.s_hid, m.mult2, m.b2};
    const FieldU8 f8{m.p1, m.p2, m.init1, m.init2, m.s_w1, m.mult2, m.b2, m.s_hid};
    for (int e = 0; e < E; ++e) {
      fwref::field_w16_avx2(f16, za, m.s_z[e], m.v, za);
      field_u8(f8, zb, m.s_z[e], m.v, zb);
      for (int i = 0; i < L; ++i) differ += std::memcmp(&za[i], &zb[i], 4) != 0, ++compared;
    }
  }
  std::printf("u8 field against field_w16_avx2: %ld of %ld outputs differ\n", differ, compared);
  for (int i = 0; i < L; ++i) z[i] = std::normal_distribution<float>(0.0f, 1.0f)(rng);
  const fwref::FieldW16 f16{m.w1, m.w2, H, L, m.s_w1, m.s_hid, m.mult2, m.b2};
  const FieldU8 f8{m.p1, m.p2, m.init1, m.init2, m.s_w1, m.mult2, m.b2, m.s_hid};
  std::vector<double> a, b;
  for (int r = 0; r < 9; ++r) {
    a.push_back(median_call_ns([&] { for (int e = 0; e < E; ++e) fwref::field_w16_avx2(f16, z, m.s_z[e], m.v, z); }) / E);
    b.push_back(median_call_ns([&] { for (int e = 0; e < E; ++e) field_u8(f8, z, m.s_z[e], m.v, z); }) / E);
  }
  std::sort(a.begin(), a.end());
  std::sort(b.begin(), b.end());
  std::printf("interleaved, 9 rounds: int16 field (shipped) %.1f ns, u8 field %.1f ns per evaluation (medians; "
              "rounds %.1f-%.1f and %.1f-%.1f)\n", a[4], b[4], a[0], a[8], b[0], b[8]);
  return 0;
}
