// src/model_common.hpp -- scope: internal helpers shared by cnode.cpp and gru.cpp: argument and
// weight checks, the finite-window check, and the classic RK4 loop (written once, like
// train.solvers.rk4_step, whose expressions it evaluates in the same order).
#pragma once

#include <cmath>
#include <cstdint>

#include "fwref/linalg.hpp"
#include "fwref/status.hpp"

namespace fwref {
namespace detail {

inline bool dim_ok(int v, int max) { return v > 0 && v <= max; }

inline bool all_finite(const float* x, int n) {
  for (int i = 0; i < n; ++i) {
    if (!std::isfinite(x[i])) return false;
  }
  return true;
}

inline bool all_positive_finite(const float* x, int n) {
  if (x == nullptr) return false;
  for (int i = 0; i < n; ++i) {
    if (!(x[i] > 0.0f) || !std::isfinite(x[i])) return false;
  }
  return true;
}

inline bool view_ok(const MatF& m, int rows, int cols) {
  return m.data != nullptr && m.rows == rows && m.cols == cols;
}

inline bool view_ok(const MatQ& m, int rows, int cols) {
  return m.q != nullptr && m.rows == rows && m.cols == cols && all_positive_finite(m.scale, rows);
}

// Classic RK4, N steps of h over [0, 1] with consts c = [h/2, h, 2, h/6] (float32, as the graphs
// hold them): k1 = f(z); k2 = f(z + k1*(h/2)); k3 = f(z + k2*(h/2)); k4 = f(z + k3*h);
// z = z + (((k1 + k2*2) + k3*2) + k4) * (h/6). ``f(e, state, k)`` is evaluation e = 4n + i; each
// state it is called with is also written to ``trace_stages`` (4N, L) when that is not null.
template <class Vec, class Field>
void rk4_integrate(const float* c, int steps, Vec& z, Vec& k1, Vec& k2, Vec& k3, Vec& k4, Vec& state,
                   Field& f, float* trace_stages) {
  const float half = c[0], h = c[1], two = c[2], h6 = c[3];
  const int n = static_cast<int>(z.size());
  int e = 0;
  auto eval = [&](const Vec& s, Vec& k) {
    if (trace_stages != nullptr) {
      for (int i = 0; i < n; ++i) trace_stages[e * n + i] = s[i];
    }
    f(e, s, k);
    ++e;
  };
  for (int step = 0; step < steps; ++step) {
    eval(z, k1);
    state = z + k1 * half;
    eval(state, k2);
    state = z + k2 * half;
    eval(state, k3);
    state = z + k3 * h;
    eval(state, k4);
    z = z + (((k1 + k2 * two) + k3 * two) + k4) * h6;
  }
}

}  // namespace detail
}  // namespace fwref
