// tools/fwref_vmath_gru.hpp -- scope: fwref_vmath's checks of the host's GRU int8 step math
// (fwref/vmath_gru_i8.hpp) against the portable path's scalar expressions (src/gru.cpp: the rescale
// of linear_i8_folded / linear_i8_tensor into gx / gh, gru_cell, quantize), bit for bit (h, codes,
// x_norm; a NaN h as NaN, see gates_once) and element for element (guards after n untouched).
//
//   gru_input_row   normalise_quantize_row (int8 and int16 codes, x_norm stored or not) on every
//                   length 1..70: x with NaN/inf/huge values, and rows whose x / s_x hits every
//                   round-half-even tie of the quantizer and the saturation bounds (+- a float);
//   gru_gates       gru_gates_i8 (int8 and int16 codes) on every hidden size 1..70: accumulators
//                   with the int32 extremes, scales, biases and h with NaN/inf/denormals mixed in;
//   gru_gate_rows   the GRU's own shape (H = 80, s_h = f32(1/127), realistic accumulators and h in
//                   (-1, 1)) over many steps: a y one ulp off changes a code only near a tie.
// Each check returns the number of elements that differ and adds to ``compared``.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <random>
#include <vector>

#include "fwref/vmath_gru_i8.hpp"
#include "fwref_vmath_i8.hpp"

namespace vmath_gru_check {

using vmath_i8_check::pick;
using vmath_i8_check::pick_acc;

template <class Q>
long input_row(const std::vector<float>& x, const std::vector<float>& mean, const std::vector<float>& std_,
               const std::vector<float>& s_x, bool store_xn, long* compared) {
  const int n = static_cast<int>(x.size());
  std::vector<float> xn(n + 1, 7.0f);
  std::vector<Q> q(n + 1, Q(77));
  fwref::normalise_quantize_row(x.data(), mean.data(), std_.data(), s_x.data(), n, store_xn ? xn.data() : nullptr,
                                q.data());
  long bad = (q[n] != Q(77)) + (fwref::float_bits(xn[n]) != fwref::float_bits(7.0f));
  for (int i = 0; i < n; ++i) {
    const float want = fwref::normalise(x[i], mean[i], std_[i]);
    const float got_xn = store_xn ? xn[i] : want;
    if (q[i] != fwref::quantize(want, s_x[i]) || fwref::float_bits(got_xn) != fwref::float_bits(want)) {
      if (bad < 5) std::printf("  gru input n=%d i=%d x=%a: code %d vs %d\n", n, i, x[i], int(q[i]), int(fwref::quantize(want, s_x[i])));
      ++bad;
    }
  }
  *compared += n;
  return bad;
}

inline long check_input_row(long* compared) {
  std::mt19937 rng(515);
  std::uniform_real_distribution<float> pos(0.05f, 3.0f);
  const float pow2[] = {0.0078125f, 0.5f, 1.0f, 4.0f};
  return vmath_check::every_length(4, [&](int n, int rep) {
    long bad = 0;
    std::vector<float> x(n), mean(n), std_(n), s_x(n);
    for (int i = 0; i < n; ++i) {
      if (rep < 2) {  // random rows with special values
        x[i] = pick(rng, 4.0f), mean[i] = pick(rng, 1.0f), std_[i] = pos(rng), s_x[i] = pos(rng) / 64;
      } else {  // mean 0, std 1, a power-of-two scale: x / s_x exactly a tie or a bound, or a float next to it
        const float s = pow2[rng() % 4];
        const float k = static_cast<float>(static_cast<int>(rng() % 262) - 131) + 0.5f;
        const float edges[] = {k, -128.5f, -128.0f, 127.0f, 127.5f};
        float v = edges[rng() % 5] * s;
        if (rng() % 3 == 0) v = std::nextafter(v, rng() % 2 ? 1e30f : -1e30f);
        x[i] = v, mean[i] = 0.0f, std_[i] = 1.0f, s_x[i] = s;
      }
    }
    bad += input_row<std::int8_t>(x, mean, std_, s_x, rep % 2 == 0, compared);
    bad += input_row<std::int16_t>(x, mean, std_, s_x, rep % 2 == 1, compared);
    return bad;
  });
}

// The portable path's arithmetic (src/gru.cpp: linear_i8_folded's and linear_i8_tensor's rescale into
// float rows gx, gh, then gru_cell's scalar loop, then quantize_all), one unit.
struct GateRef {
  float h;
  int q;
};
inline GateRef gate_reference(const fwref::GruGateInputs& g, int hidden, int j, float h) {
  float gx[3], gh[3];
  for (int k = 0; k < 3; ++k) {
    const int o = k * hidden + j;
    gx[k] = (static_cast<float>(g.acc_x[o]) * g.s_wx[o]) + g.b_ih[o];
    gh[k] = fwref::rescale_i32(g.acc_h[o], g.s_h, g.s_wh[o]) + g.b_hh[o];
  }
  const float r = fwref::logistic_approx(gx[0] + gh[0]);
  const float z = fwref::logistic_approx(gx[1] + gh[1]);
  const float n = fwref::tanh_approx(gx[2] + gh[2] * r);
  const float hn = (h - n) * z + n;
  return {hn, fwref::quantize(hn, g.s_h)};
}

struct GateRows {
  std::vector<std::int32_t> acc_x, acc_h;
  std::vector<float> s_wx, b_ih, s_wh, b_hh;
  explicit GateRows(int hidden)
      : acc_x(3 * hidden), acc_h(3 * hidden), s_wx(3 * hidden), b_ih(3 * hidden), s_wh(3 * hidden), b_hh(3 * hidden) {}
  fwref::GruGateInputs inputs(float s_h) const {
    return {acc_x.data(), s_wx.data(), b_ih.data(), acc_h.data(), s_h, s_wh.data(), b_hh.data()};
  }
};

// gru_gates_i8 on (rows, h) against gate_reference; h0 is copied, guards after hidden checked.
template <class Q>
long gates_once(const GateRows& rows, float s_h, const std::vector<float>& h0, long* compared) {
  const int hidden = static_cast<int>(h0.size());
  const fwref::GruGateInputs g = rows.inputs(s_h);
  std::vector<float> h(h0);
  h.push_back(7.0f);
  std::vector<Q> q(hidden + 1, Q(77));
  fwref::gru_gates_i8(g, hidden, h.data(), q.data());
  long bad = (q[hidden] != Q(77)) + (fwref::float_bits(h[hidden]) != fwref::float_bits(7.0f));
  for (int j = 0; j < hidden; ++j) {
    const GateRef want = gate_reference(g, hidden, j, h0[j]);
    // A NaN h is compared as NaN only: where two NaNs meet (h and a bias, say), which one an x86
    // instruction returns follows the operand order the compiler chose for a commutative IEEE
    // operation, which C++ does not fix (seen: -nan vs nan). Its code is compared exactly (0 both ways).
    const bool same_h = std::isnan(want.h) ? std::isnan(h[j]) : fwref::float_bits(h[j]) == fwref::float_bits(want.h);
    if (q[j] != want.q || !same_h) {
      if (bad < 5) std::printf("  gru gates H=%d j=%d: h %a vs %a, code %d vs %d\n", hidden, j, h[j], want.h, int(q[j]), want.q);
      ++bad;
    }
  }
  *compared += hidden;
  return bad;
}

inline long check_gates(long* compared) {
  std::mt19937 rng(8080);
  std::uniform_real_distribution<float> scale(1e-7f, 1e-4f);
  return vmath_check::every_length(4, [&](int hidden, int rep) {
    long bad = 0;
    GateRows rows(hidden);
    for (int o = 0; o < 3 * hidden; ++o) {
      rows.acc_x[o] = pick_acc(rng), rows.acc_h[o] = pick_acc(rng);
      rows.s_wx[o] = scale(rng), rows.s_wh[o] = scale(rng) * 100.0f;
      rows.b_ih[o] = pick(rng, 1.0f), rows.b_hh[o] = pick(rng, 1.0f);
    }
    std::vector<float> h0(hidden);
    for (float& v : h0) v = pick(rng, 0.5f);
    const float s_h = rep == 0 ? 1.0f / 127.0f : rep == 1 ? 0.0123f : scale(rng) * 1000.0f;
    bad += gates_once<std::int8_t>(rows, s_h, h0, compared) + gates_once<std::int16_t>(rows, s_h, h0, compared);
    return bad;
  });
}

inline long check_gate_rows(long* compared) {
  std::mt19937 rng(1280);
  std::uniform_real_distribution<float> s_wx_d(1e-4f, 4e-3f), s_wh_d(2e-3f, 1.2e-2f), b_d(-0.5f, 0.5f),
      h_d(-0.999f, 0.999f);
  const int hidden = 80;
  GateRows rows(hidden);
  std::vector<float> h0(hidden);
  long bad = 0;
  for (int rep = 0; rep < 40000; ++rep) {
    for (int o = 0; o < 3 * hidden; ++o) {
      rows.acc_x[o] = static_cast<std::int32_t>(rng() % 20001) - 10000;
      rows.acc_h[o] = static_cast<std::int32_t>(rng() % 40001) - 20000;
      rows.s_wx[o] = s_wx_d(rng), rows.s_wh[o] = s_wh_d(rng), rows.b_ih[o] = b_d(rng), rows.b_hh[o] = b_d(rng);
    }
    for (float& v : h0) v = h_d(rng);
    bad += gates_once<std::int16_t>(rows, 1.0f / 127.0f, h0, compared);
  }
  return bad;
}

}  // namespace vmath_gru_check
