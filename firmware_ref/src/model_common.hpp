// src/model_common.hpp -- scope: internal helpers shared by cnode.cpp and gru.cpp: argument and
// weight checks, the finite-window check, and the classic RK4 loop (core/rk4.py's RK4_PROGRAM).
#pragma once

#include <cmath>
#include <cstdint>

#include "fwref/config.hpp"
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

// int8 weights are in [-127, 127] (docs/formats.md): the SIMD kernels' sign trick
// (fwref/kernels_i8.hpp) is exact only then, so a -128 is refused as bad weights.
inline bool weights_in_range(const std::int8_t* q, long n) {
  for (long i = 0; i < n; ++i) {
    if (q[i] == -128) return false;
  }
  return true;
}

inline bool view_ok(const MatQ& m, int rows, int cols) {
  return m.q != nullptr && m.rows == rows && m.cols == cols && all_positive_finite(m.scale, rows) &&
         weights_in_range(m.q, long(rows) * cols);
}

// Every model check runs in this order: the dimensions first (they size everything else), then the
// views' shapes, then the values (read with those dimensions). ``shapes_ok()`` -> bool and
// ``values()`` -> Status are called only when what precedes them passed.
template <class Shapes, class Values>
Status check_model(Status dims, Shapes shapes_ok, Values values) {
  if (dims != Status::kOk) return dims;
  if (!shapes_ok()) return Status::kBadShape;
  return values();
}

// Classic RK4, N steps of h over [0, 1], evaluated exactly as core/rk4.py's RK4_PROGRAM (repeated in
// fwref/contracts_gen.hpp), with its float32 constants ``c`` in RK4_CONSTANT_NAMES order (weights.bin's
// rk4.consts): int8 results are bit-identical to ONNX Runtime's only if every float32 operation
// happens in the same order, so the statements below follow the program line by line.
// ``f(e, state, k)`` is evaluation e = 4n + i; each state it is called with is also written to
// ``trace_stages`` (4N, L) when that is not null.
template <class Vec, class Field>
void rk4_integrate(const float* c, int steps, Vec& z, Vec& k1, Vec& k2, Vec& k3, Vec& k4, Vec& state,
                   Field& f, float* trace_stages) {
  const float half_h = c[contracts::kRk4HalfH], h = c[contracts::kRk4H], two = c[contracts::kRk4Two],
              h_over_6 = c[contracts::kRk4HOver6];
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
    eval(z, k1);                                             // k1 = f(t, z)
    state = z + k1 * half_h;                                 // k2 = f(t + h/2, z + half_h * k1)
    eval(state, k2);
    state = z + k2 * half_h;                                 // k3 = f(t + h/2, z + half_h * k2)
    eval(state, k3);
    state = z + k3 * h;                                      // k4 = f(t + h, z + h * k3)
    eval(state, k4);
    z = z + (((k1 + k2 * two) + k3 * two) + k4) * h_over_6;  // z = z + h_over_6 * (((k1 + two * k2) + ...
  }
}

}  // namespace detail
}  // namespace fwref
