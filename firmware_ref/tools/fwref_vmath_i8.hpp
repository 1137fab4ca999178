// tools/fwref_vmath_i8.hpp -- scope: fwref_vmath's checks of the host's int8 vector math
// (fwref/vmath_i8.hpp) against the scalar expressions of fwref/numerics.hpp it replaces, bit for bit
// (codes, floats) and element for element (nothing written outside [0, n)).
//
//   quantize          quantize_n (int8 and int16 codes) against quantize(): every x / s that is a
//                     round-half-even tie k + 0.5 (k = -131..130, s = 2^-7, 0.5, 1, 4) and its two
//                     neighbouring floats, the saturation bounds (-128.5, -128, 127, 127.5 and
//                     neighbours), +-0, +-inf, NaNs, denormals, and every N-th float32 bit pattern,
//                     with scales 1, f32(1/127) and 0.0123;
//   rescale_tanh_quantize / rescale_bias
//                     random int32 accumulators (|acc| < 2^24, and the int32 extremes, where the
//                     int -> float conversion rounds), scales and rows with NaN/inf mixed in, every
//                     length 1..70 (vector body and scalar tail);
//   accumulate / rescale_quantize_row
//                     the control path's per-channel work, every length 1..70, x with NaN/inf/huge
//                     values; guard elements after n must stay untouched;
//   nonzero           for_each_nonzero against a plain scan, rows of every length 1..300.
// Each check returns the number of elements (or calls) that differ and adds to ``compared``.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "fwref/vmath_i8.hpp"
#include "fwref_vmath_check.hpp"

namespace vmath_i8_check {

// Inputs x such that x / s hits the quantizer's edges for the scale s.
inline std::vector<float> quantize_edges(float s) {
  std::vector<float> v;
  for (int k = -131; k <= 130; ++k) vmath_check::push_with_neighbours(v, (static_cast<float>(k) + 0.5f) * s);  // ties
  for (float b : {-128.5f, -128.0f, 127.0f, 127.5f, 1e9f, -1e9f}) vmath_check::push_with_neighbours(v, b * s);
  for (std::uint32_t u : {0x00000000u, 0x80000000u, 0x7f800000u, 0xff800000u, 0x7fc00000u, 0xffc00000u,
                          0x7fa00001u, 0xffa00001u, 0x00000001u, 0x80000001u, 0x007fffffu, 0x7f7fffffu, 0xff7fffffu}) {
    v.push_back(fwref::bits_float(u));
  }
  return v;
}

template <class Q>
long quantize_codes(const std::vector<float>& x, float s, long* compared) {
  const int n = static_cast<int>(x.size());
  std::vector<Q> q(n + 1, Q(77));
  fwref::quantize_n(x.data(), n, s, q.data());
  long bad = q[n] != Q(77);
  for (int i = 0; i < n; ++i) {
    const Q want = fwref::quantize(x[i], s);
    if (q[i] != want) {
      if (bad < 5) std::printf("  quantize x=%a s=%a: vector %d, scalar %d\n", x[i], s, int(q[i]), int(want));
      ++bad;
    }
  }
  *compared += n;
  return bad;
}

inline long check_quantize(const std::vector<float>& walk, long* compared) {
  long bad = 0;
  for (float s : {0.0078125f, 0.5f, 1.0f, 4.0f, 1.0f / 127.0f, 0.0123f}) {
    std::vector<float> x = quantize_edges(s);
    for (float w : walk) x.push_back(w);
    while (x.size() % 8 != 5) x.push_back(0.5f * s);  // a scalar tail
    bad += quantize_codes<std::int8_t>(x, s, compared) + quantize_codes<std::int16_t>(x, s, compared);
  }
  return bad;
}

// Random floats of a row: mostly N(0, sigma), sometimes one of the special values.
inline float pick(std::mt19937& rng, float sigma) {
  const float special[] = {0.0f, -0.0f, std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(),
                           std::numeric_limits<float>::quiet_NaN(), 1e30f, -1e30f, fwref::bits_float(0x00000001u)};
  if (rng() % 16 == 0) return special[rng() % 8];
  return std::normal_distribution<float>(0.0f, sigma)(rng);
}

inline std::int32_t pick_acc(std::mt19937& rng) {
  const std::int32_t extremes[] = {std::numeric_limits<std::int32_t>::min(), std::numeric_limits<std::int32_t>::max(),
                                   (1 << 24) + 1, -(1 << 24) - 3, 0};
  if (rng() % 16 == 0) return extremes[rng() % 5];
  return static_cast<std::int32_t>(rng() % (1u << 24)) - (1 << 23);
}

inline long check_rescale(long* compared) {
  std::mt19937 rng(4321);
  std::uniform_real_distribution<float> scale(1e-6f, 1e-3f);
  return vmath_check::every_length(4, [&](int n, int rep) {
    long bad = 0;
    std::vector<std::int32_t> acc(n);
    std::vector<float> s_w(n), v(n), b(n), y(n + 1, 7.0f);
    for (int i = 0; i < n; ++i) acc[i] = pick_acc(rng), s_w[i] = scale(rng), v[i] = pick(rng, 2.0f), b[i] = pick(rng, 1.0f);
    const float s_a = rep == 0 ? 1.0f / 127.0f : scale(rng) * 100.0f;
    const float s_q = rep % 2 == 0 ? 1.0f / 127.0f : 0.0123f;
    std::vector<std::int16_t> q(n + 1, 77);
    fwref::rescale_tanh_quantize_n(acc.data(), s_a, s_w.data(), v.data(), s_q, n, q.data());
    fwref::rescale_bias_n(acc.data(), s_w.data(), b.data(), n, y.data());
    bad += (q[n] != 77) + (fwref::float_bits(y[n]) != fwref::float_bits(7.0f));
    for (int i = 0; i < n; ++i) {
      const std::int16_t want = fwref::quantize(fwref::tanh_approx(fwref::rescale_i32(acc[i], s_a, s_w[i]) + v[i]), s_q);
      const float want_y = static_cast<float>(acc[i]) * s_w[i] + b[i];
      if (q[i] != want || fwref::float_bits(y[i]) != fwref::float_bits(want_y)) {
        if (bad < 5) std::printf("  rescale n=%d i=%d acc=%d: code %d vs %d, y %a vs %a\n", n, i, acc[i], q[i], want, y[i], want_y);
        ++bad;
      }
    }
    *compared += 2 * n;
    return bad;
  });
}

// The hidden layer's rows as the CNODE has them (acc from int8 products, y mostly in tanh's steep
// part, s_q = f32(1/127)), many of them: a y one ulp off (e.g. an FMA where the scalar rounds twice)
// changes a code only near a rounding tie, so this takes millions of elements to see.
inline long check_hidden_rows(long* compared) {
  std::mt19937 rng(2024);
  std::uniform_real_distribution<float> s_w_d(2e-3f, 1.2e-2f), v_d(-1.5f, 1.5f);
  const int n = 64;
  std::vector<std::int32_t> acc(n);
  std::vector<float> s_w(n), v(n);
  std::vector<std::int8_t> q(n);
  long bad = 0;
  for (int rep = 0; rep < 60000; ++rep) {
    for (int i = 0; i < n; ++i) {
      acc[i] = static_cast<std::int32_t>(rng() % 40001) - 20000, s_w[i] = s_w_d(rng), v[i] = v_d(rng);
    }
    const float s_a = 1e-4f + 1e-4f * static_cast<float>(rep % 97);
    fwref::rescale_tanh_quantize_n(acc.data(), s_a, s_w.data(), v.data(), 1.0f / 127.0f, n, q.data());
    for (int i = 0; i < n; ++i) {
      bad += q[i] != fwref::quantize(fwref::tanh_approx(fwref::rescale_i32(acc[i], s_a, s_w[i]) + v[i]), 1.0f / 127.0f);
    }
  }
  *compared += 60000L * n;
  return bad;
}

// The control path's per-channel work: acc[c] += p * quantize(normalise(x, mean, std), s_x) over a
// few samples, then u = rescale_i32(acc, s_p, s_x) and its code with s_u.
inline long check_control_row(long* compared) {
  std::mt19937 rng(99);
  std::uniform_real_distribution<float> pos(0.05f, 3.0f), p_scale(1e-3f, 2e-2f);
  return vmath_check::every_length(3, [&](int n, int rep) {
    long bad = 0;
    std::vector<float> mean(n), std_(n), s_x(n), s_u(n);
    for (int i = 0; i < n; ++i) mean[i] = pick(rng, 1.0f), std_[i] = pos(rng), s_x[i] = pos(rng) / 64, s_u[i] = pos(rng) / 64;
    std::vector<std::int32_t> acc(n + 1, 0), ref(n, 0);
    acc[n] = 12345;
    for (int sample = 0; sample < 3; ++sample) {
      std::vector<float> x(n);
      for (float& f : x) f = pick(rng, 4.0f);
      const std::int32_t p = static_cast<std::int32_t>(rng() % 255) - 127;
      fwref::accumulate_codes(x.data(), mean.data(), std_.data(), s_x.data(), n, p, acc.data());
      for (int i = 0; i < n; ++i) ref[i] += p * fwref::quantize(fwref::normalise(x[i], mean[i], std_[i]), s_x[i]);
    }
    bad += acc[n] != 12345;
    for (int i = 0; i < n; ++i) bad += acc[i] != ref[i];
    const float s_p = p_scale(rng);
    std::vector<float> u(n + 1, 7.0f);
    std::vector<std::int8_t> q(n + 1, 77);
    fwref::rescale_quantize_row(acc.data(), s_p, s_x.data(), s_u.data(), n, rep == 2 ? nullptr : u.data(), q.data());
    bad += (q[n] != 77) + (fwref::float_bits(u[n]) != fwref::float_bits(7.0f));
    for (int i = 0; i < n; ++i) {
      const float want_u = fwref::rescale_i32(acc[i], s_p, s_x[i]);
      const std::int8_t want_q = fwref::quantize(want_u, s_u[i]);
      if (q[i] != want_q || (rep != 2 && fwref::float_bits(u[i]) != fwref::float_bits(want_u))) {
        if (bad < 5) std::printf("  control row n=%d i=%d: code %d vs %d, u %a vs %a\n", n, i, q[i], want_q, u[i], want_u);
        ++bad;
      }
    }
    *compared += 2 * n;
    return bad;
  });
}

inline long check_nonzero(long* compared) {
  std::mt19937 rng(7);
  long bad = 0;
  for (int n = 1; n <= 300; ++n) {
    std::vector<std::int8_t> p(n, 0);
    for (int k = 0; k < 1 + n / 40; ++k) p[rng() % n] = static_cast<std::int8_t>(rng() % 255 - 127);
    std::vector<std::pair<int, std::int32_t>> got, want;
    fwref::for_each_nonzero(p.data(), n, [&](int i, std::int32_t v) { got.emplace_back(i, v); });
    for (int i = 0; i < n; ++i) {
      if (p[i] != 0) want.emplace_back(i, p[i]);
    }
    bad += got != want;
    ++*compared;
  }
  return bad;
}

}  // namespace vmath_i8_check
