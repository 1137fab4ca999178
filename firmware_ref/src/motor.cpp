// src/motor.cpp -- scope: the motor head (fwref/motor.hpp): its weight checks, and infer_motor, the one
// definition for both nets and both precisions.
#include "fwref/motor.hpp"

#include <cstdint>

#include "fwref/cnode.hpp"
#include "fwref/gru.hpp"
#include "fwref/numerics.hpp"
#include "model_common.hpp"

namespace fwref {

namespace {

template <class Head>
Status check_head(const Head& m, int max_features) {
  const int F = m.dims.features, M = m.dims.motors;
  if (F <= 0 || M != kMotors) return Status::kDimsInvalid;
  if (F > max_features) return Status::kDimsTooLarge;
  if (!detail::view_ok(m.w, M, F) || m.b == nullptr) return Status::kBadShape;
  return detail::all_finite(m.b, M) ? Status::kOk : Status::kBadWeights;
}

// What each net's class head reads, the motor head's input: its width, where infer() leaves it (the CNODE's
// z1 in ws.z, the GRU's h_W in ws.h: the int8 class head quantized a copy), and the int8 head's input scale.
int head_width(const CnodeDims& d) { return d.latent; }
int head_width(const GruDims& d) { return d.hidden; }
const float* head_input(const CnodeWorkspace& ws) { return ws.z.data(); }
const float* head_input(const GruWorkspace& ws) { return ws.h.data(); }
float head_scale(const CnodeI8& m) { return m.s_z1; }
float head_scale(const GruI8& m) { return m.s_h; }

// fp32: out = W f + b.
template <int Net, class Model>
void motor_head(const MotorF32T<Net>& h, const Model&, const float* f, float* out) {
  const int F = h.dims.features, M = h.dims.motors;
  MapVec y(out, M);
  matvec(h.w, ConstMapVec(f, F), y);
  y += ConstMapVec(h.b, M);
}

// int8: f quantized with the class head's scale, then pattern A (the class head's arithmetic).
template <int Net, class Model>
void motor_head(const MotorI8T<Net>& h, const Model& m, const float* f, float* out) {
  const int F = h.dims.features;
  const float s_a = head_scale(m);
  std::int8_t q[kMaxLatent > kMaxGruHidden ? kMaxLatent : kMaxGruHidden];
  for (int i = 0; i < F; ++i) q[i] = quantize(f[i], s_a);
  linear_i8_tensor(h.w.q, h.w.scale, h.dims.motors, F, q, s_a, h.b, out);
}

}  // namespace

Status check(const CnodeMotorF32& m) { return check_head(m, kMaxLatent); }
Status check(const CnodeMotorI8& m) { return check_head(m, kMaxLatent); }
Status check(const GruMotorF32& m) { return check_head(m, kMaxGruHidden); }
Status check(const GruMotorI8& m) { return check_head(m, kMaxGruHidden); }

template <class Model, class Head, class Workspace>
Status infer_motor(const Model& m, const Head& h, const float* x, float* logits, float* motor, Workspace& ws) {
  if (motor == nullptr) return Status::kNullArgument;
  if (h.dims.features != head_width(m.dims)) return Status::kDimsInvalid;
  const Status s = infer(m, x, logits, ws);
  if (s != Status::kOk) return s;
  motor_head(h, m, head_input(ws), motor);
  return detail::all_finite(motor, h.dims.motors) ? Status::kOk : Status::kNonFiniteOutput;
}

template Status infer_motor(const CnodeF32&, const CnodeMotorF32&, const float*, float*, float*, CnodeWorkspace&);
template Status infer_motor(const CnodeI8&, const CnodeMotorI8&, const float*, float*, float*, CnodeWorkspace&);
template Status infer_motor(const GruF32&, const GruMotorF32&, const float*, float*, float*, GruWorkspace&);
template Status infer_motor(const GruI8&, const GruMotorI8&, const float*, float*, float*, GruWorkspace&);

}  // namespace fwref
