// src/motor_common.hpp -- scope: internal: the motor head's product (fwref/motor.hpp), shared by
// the CNODE's and the GRU's infer_motor and the checks of src/motor.cpp.
#pragma once

#include <cstdint>

#include "fwref/motor.hpp"
#include "fwref/numerics.hpp"
#include "model_common.hpp"

namespace fwref {
namespace detail {

// fp32: out = W f + b.
template <int Net>
void motor_head(const MotorF32T<Net>& h, const float* f, float* out) {
  const int F = h.dims.features, M = h.dims.motors;
  MapVec y(out, M);
  matvec(h.w, ConstMapVec(f, F), y);
  y += ConstMapVec(h.b, M);
}

// int8: f quantized with the class head's scale s_a, then pattern A (the class head's arithmetic).
template <int Net>
void motor_head(const MotorI8T<Net>& h, const float* f, float s_a, float* out) {
  const int F = h.dims.features;
  std::int8_t q[kMaxLatent > kMaxGruHidden ? kMaxLatent : kMaxGruHidden];
  for (int i = 0; i < F; ++i) q[i] = quantize(f[i], s_a);
  linear_i8_tensor(h.w.q, h.w.scale, h.dims.motors, F, q, s_a, h.b, out);
}

}  // namespace detail
}  // namespace fwref
