// tools/fwref_vmath_check.hpp -- scope: the harness every fwref_vmath check runs in: the one report line of a
// check ("name: B of N differ") and the tally that decides the exit code, the special floats mixed into inputs,
// random rows, 64-byte aligned float buffers, the random fp32 CNODE fields of the two fp32 field checks, and the
// int8 control-row check that control_row_avx2 and control_row_avx512 (the same contract) both take, and the
// walk over every row length 1..70 of the element-wise checks.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <random>
#include <vector>

#include "fwref/kernels_f32_avx512.hpp"
#include "fwref/numerics.hpp"
#include "fwref/vmath_i8.hpp"

namespace vmath_check {

// NaN, +-inf and a finite value whose products overflow: where a vector path most easily parts from the scalar.
inline const float kOdd[4] = {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(),
                              -std::numeric_limits<float>::infinity(), 3e38f};

inline bool differ(float a, float b) { return fwref::float_bits(a) != fwref::float_bits(b); }

// x and its two neighbouring floats: both sides of a clamp edge or a rounding tie.
inline void push_with_neighbours(std::vector<float>& v, float x) {
  v.push_back(x);
  v.push_back(std::nextafter(x, std::numeric_limits<float>::infinity()));
  v.push_back(std::nextafter(x, -std::numeric_limits<float>::infinity()));
}

// Draws of d into each row in turn, element by element (so a check's draws do not depend on how it groups them).
template <class Dist, class... Rows>
void fill(std::mt19937& rng, Dist& d, Rows&... rows) {
  const auto one = [&](std::vector<float>& r) {
    for (float& f : r) f = d(rng);
  };
  (one(rows), ...);
}

// n floats starting on a 64-byte boundary inside ``v`` (the column-major copies' alignment, which Eigen's
// aligned_allocator gives only in a build whose own vectors are 512-bit).
inline float* floats64(std::vector<float>& v, std::size_t n) {
  v.assign(n + 16, 0.0f);
  const std::uintptr_t a = reinterpret_cast<std::uintptr_t>(v.data());
  return v.data() + ((64 - a % 64) % 64) / sizeof(float);
}

// Rows of every length 1..70 (the vector bodies and the scalar tails; no model row is longer), ``draws`` draws
// each: the sum of check(n, draw), each call's elements that differ.
template <class Check>
long every_length(int draws, Check check) {
  long bad = 0;
  for (int n = 1; n <= 70; ++n) {
    for (int d = 0; d < draws; ++d) bad += check(n, d);
  }
  return bad;
}

// All checks' differences; a check that returns -1 did not run on this CPU and prints nothing.
struct Tally {
  long bad = 0;
  template <class Check>
  long run(const char* name, Check check) {
    long compared = 0;
    const long b = check(&compared);
    if (b < 0) return b;
    std::printf("%s: %ld of %ld differ\n", name, b, compared);
    bad += b;
    return b;
  }
};

// A CNODE field in one call, ``field(z, k)`` (false: the shape is refused), against ``want`` (the separate steps'
// k): into a guarded k and in place (z == k). Elements that differ, plus one if the float after k was written;
// -1 when the call was refused.
template <class Field>
long compare_one_call(Field field, const std::vector<float>& z, const std::vector<float>& want) {
  const int L = static_cast<int>(want.size());
  std::vector<float> got(L + 1, 7.0f), inplace(z);
  if (!field(z.data(), got.data())) return -1;
  field(inplace.data(), inplace.data());
  long bad = got[L] != 7.0f;
  for (int o = 0; o < L; ++o) bad += differ(want[o], got[o]) + differ(want[o], inplace[o]);
  return bad;
}

#if defined(FWREF_HAS_F32_AVX512)
// One random fp32 CNODE field of shape (H, L), drawn from nd (one per check: it caches every other draw):
// lin1_z (H, L) and lin2 (L, H) row-major and packed column-major (t1, t2: pack_f32_t, 64-byte aligned),
// z scaled so that tanh's clamp is crossed, v and b2.
struct FieldF32Case {
  std::vector<float> w1, w2, z, v, b2;
  float* t1;
  float* t2;
  FieldF32Case(std::mt19937& rng, std::normal_distribution<float>& nd, int H, int L)
      : w1(H * L), w2(L * H), z(L), v(H), b2(L) {
    fill(rng, nd, w1, w2);
    for (float& f : z) f = 3.0f * nd(rng) / std::sqrt(float(L));
    fill(rng, nd, v, b2);
    t1 = floats64(s1_, std::size_t(L) * fwref::f32_t_stride(H));
    t2 = floats64(s2_, std::size_t(H) * fwref::f32_t_stride(L));
    fwref::pack_f32_t(w1.data(), H, L, t1);
    fwref::pack_f32_t(w2.data(), L, H, t2);
  }
  FieldF32Case(const FieldF32Case&) = delete;
  FieldF32Case& operator=(const FieldF32Case&) = delete;

 private:
  std::vector<float> s1_, s2_;
};
#endif

// An int8 control row (controls_avx2.hpp / controls_avx512.hpp: the same arguments and results) against
// for_each_nonzero + accumulate_codes + rescale_quantize_row (fwref/vmath_i8.hpp), codes and floats bit for bit:
// every C in 1..32, windows of 1..100 samples with 0..4 nonzero weights per row and some dense rows, x near the
// codes' ties in some cases and with NaN / +-inf / huge values in others; the code and float after C must stay
// untouched, and without the float row (u null) the codes must be the same. Codes and floats that differ (or
// guards overwritten, or a shape refused) over all cases.
template <class Row>
long check_control_row(Row row, long* compared) {
  std::mt19937 rng(78);
  std::normal_distribution<float> nd(0.0f, 1.0f);
  std::uniform_int_distribution<int> pd(-127, 127);
  long bad = 0;
  for (int C = 1; C <= 32; ++C) {
    for (int W = 1; W <= 100; W += (W < 40 ? 1 : 7)) {
      std::vector<std::int8_t> p(W, 0), want_q(C + 1, 5), got_q(C + 1, 5);
      const int nz = (C + W) % 9 == 0 ? W : (C * W) % 5;  // dense rows now and then, else 0..4 weights
      for (int i = 0; i < nz; ++i) p[(i * 37 + C) % W] = static_cast<std::int8_t>(pd(rng));
      std::vector<float> x(W * C), mean(C), sd(C), s_x(C), s_u(C), want_u(C + 1, 7.0f), got_u(C + 1, 7.0f);
      for (float& f : x) f = 3.0f * nd(rng);
      for (int c = 0; c < C; ++c) {
        mean[c] = 0.3f * nd(rng), sd[c] = 0.5f + std::fabs(nd(rng));
        s_x[c] = 0.02f * (0.5f + std::fabs(nd(rng))), s_u[c] = 0.03f * (0.5f + std::fabs(nd(rng)));
      }
      if ((C + W) % 3 == 0) {  // x / std within an ulp of a code's tie (k + 0.5) * s_x: mean 0, std 0.7, s_x 2^-6
        for (int c = 0; c < C; ++c) mean[c] = 0.0f, sd[c] = 0.7f, s_x[c] = 0.015625f;
        for (float& f : x) f = ((static_cast<float>(pd(rng)) + 0.5f) * 0.015625f) * 0.7f;
      }
      if ((C + W) % 4 == 0) x[(C * 7 + W) % (W * C)] = kOdd[(C + W) % 16 / 4];
      const float s_p = 1.0f / 127.0f;
      std::vector<std::int32_t> acc(C, 0);
      fwref::for_each_nonzero(p.data(), W, [&](int w, std::int32_t pw) {
        fwref::accumulate_codes(x.data() + w * C, mean.data(), sd.data(), s_x.data(), C, pw, acc.data());
      });
      fwref::rescale_quantize_row(acc.data(), s_p, s_x.data(), s_u.data(), C, want_u.data(), want_q.data());
      if (!row(p.data(), W, x.data(), C, mean.data(), sd.data(), s_x.data(), s_p, s_u.data(), got_u.data(),
               got_q.data())) {
        bad += C + 1;  // a shape the row must take, refused
        continue;
      }
      std::vector<std::int8_t> q_no_u(C, 9);
      row(p.data(), W, x.data(), C, mean.data(), sd.data(), s_x.data(), s_p, s_u.data(), nullptr, q_no_u.data());
      for (int c = 0; c <= C; ++c) {
        bad += want_q[c] != got_q[c];
        bad += differ(want_u[c], got_u[c]);
        bad += c < C && q_no_u[c] != want_q[c];
      }
      *compared += C;
    }
  }
  return bad;
}

}  // namespace vmath_check
