// src/cnode_step.cpp -- scope: one step of the streaming CNODE, fp32 and int8 (fwref/cnode_step.hpp): the
// control's two products per sample collapse to one (v_new is carried as the next v_prev), the four field
// evaluations run through detail::rk4_integrate (the RK4 program shared with the windowed CNODE).
#include "fwref/cnode_step.hpp"

#include <cstdint>

#include "fwref/kernels_f32.hpp"
#include "fwref/kernels_i8.hpp"
#include "fwref/numerics.hpp"
#include "model_common.hpp"

namespace fwref {

namespace {

using Lat = ScnodeStepState::Lat;

Status check_dims(const ScnodeDims& d) {
  if (d.channels <= 0 || d.latent <= 0 || d.hidden <= 0 || d.classes <= 0) return Status::kDimsInvalid;
  if (d.channels > kMaxChannels || d.latent > kMaxLatent || d.hidden > kMaxCnodeHidden || d.classes > kMaxClasses) {
    return Status::kDimsTooLarge;
  }
  return Status::kOk;
}

template <class Model>
bool vectors_ok(const Model& m) {
  const ScnodeDims& d = m.dims;
  return m.mean != nullptr && m.std != nullptr && m.rk4 != nullptr && m.lin1_b != nullptr && m.lin2_b != nullptr &&
         m.head_b != nullptr && detail::all_positive_finite(m.std, d.channels) &&
         detail::all_finite(m.mean, d.channels) && detail::all_positive_finite(m.rk4, 4) &&
         (m.decay == nullptr || detail::all_finite(m.decay, d.latent));
}

// The stage's control row: v_prev at evaluation 0, v_mid at 1 and 2, v_new at 3 (rk4_step's stage times).
const float* control_of(const ScnodeStepState& s, int e) {
  return e == 0 ? s.v_prev : (e == 3 ? s.v_new : s.v_mid);
}

// k = k - decay * z (the leak; graph: Sub(k, Mul(z, decay))).
void leak(const float* decay, const Lat& z, Lat& k) {
  if (decay == nullptr) return;
  for (int i = 0; i < static_cast<int>(z.size()); ++i) k[i] = k[i] - z[i] * decay[i];
}

// v_prev = v_new of the last step (or of this sample at the first step), v_mid = (v_prev + v_new) * 0.5.
void controls_mid(ScnodeStepState& s, int H) {
  if (s.steps == 0) {
    for (int j = 0; j < H; ++j) s.v_prev[j] = s.v_new[j];
  }
  for (int j = 0; j < H; ++j) s.v_mid[j] = (s.v_prev[j] + s.v_new[j]) * 0.5f;
}

// After the step: the new sample's v is the next step's v_prev.
void controls_carry(ScnodeStepState& s, int H) {
  for (int j = 0; j < H; ++j) s.v_prev[j] = s.v_new[j];
  ++s.steps;
}

}  // namespace

Status check(const ScnodeF32& m) {
  const ScnodeDims& d = m.dims;
  return detail::check_model(
      check_dims(d),
      [&] {
        return detail::view_ok(m.lin1_z, d.hidden, d.latent) && detail::view_ok(m.lin1_u, d.hidden, d.channels) &&
               detail::view_ok(m.lin2_w, d.latent, d.hidden) && detail::view_ok(m.head_w, d.classes, d.latent);
      },
      [&] { return vectors_ok(m) ? Status::kOk : Status::kBadWeights; });
}

Status check(const ScnodeI8& m) {
  const ScnodeDims& d = m.dims;
  return detail::check_model(
      check_dims(d),
      [&] {
        return detail::view_ok(m.lin1_z, d.hidden, d.latent) && detail::view_ok(m.lin1_u, d.hidden, d.channels) &&
               detail::view_ok(m.lin2_w, d.latent, d.hidden) && detail::view_ok(m.head_w, d.classes, d.latent);
      },
      [&] {
        const bool scales = detail::all_positive_finite(m.s_x, d.channels) && detail::all_positive_finite(&m.s_z, 1) &&
                            detail::all_positive_finite(&m.s_hidden, 1);
        return vectors_ok(m) && scales ? Status::kOk : Status::kBadWeights;
      });
}

void reset(const ScnodeF32& m, ScnodeStepState& s) {
  s.z.setZero(m.dims.latent);
  s.steps = 0;
}

void reset(const ScnodeI8& m, ScnodeStepState& s) {
  s.z.setZero(m.dims.latent);
  s.steps = 0;
}

Status head(const ScnodeF32& m, ScnodeStepState& s, float* logits) {
  if (logits == nullptr) return Status::kNullArgument;
  if (s.z.size() != m.dims.latent) return Status::kDimsInvalid;
  MapVec out(logits, m.dims.classes);
  matvec_fast(m.head_w, s.z, out);
  out += ConstMapVec(m.head_b, m.dims.classes);
  return detail::all_finite(logits, m.dims.classes) ? Status::kOk : Status::kNonFiniteOutput;
}

// fp32: the graph's Gemms as matvec + bias (the summation order differs from MLAS: FP32_CPP_REL_TOL).
Status step(const ScnodeF32& m, const float* sample, ScnodeStepState& s, float* logits) {
  if (sample == nullptr) return Status::kNullArgument;
  const int C = m.dims.channels, L = m.dims.latent, H = m.dims.hidden;
  if (s.z.size() != L) return Status::kDimsInvalid;  // reset() was not called for this model
  if (!all_finite_f32(sample, C)) return Status::kNonFiniteInput;
  VecN<kMaxChannels> xn(C);
  for (int c = 0; c < C; ++c) xn[c] = normalise(sample[c], m.mean[c], m.std[c]);
  MapVec vn(s.v_new, H);
  matvec_fast(m.lin1_u, xn, vn);
  vn += ConstMapVec(m.lin1_b, H);
  controls_mid(s, H);
  VecN<kMaxCnodeHidden> a(H);
  auto field = [&](int e, const Lat& z, Lat& k) {
    matvec_fast(m.lin1_z, z, a);
    const float* v = control_of(s, e);
    for (int j = 0; j < H; ++j) a[j] = tanh_approx(a[j] + v[j]);
    matvec_fast(m.lin2_w, a, k);
    k += ConstMapVec(m.lin2_b, L);
    leak(m.decay, z, k);
  };
  detail::rk4_integrate(m.rk4, 1, s.z, s.k1, s.k2, s.k3, s.k4, s.st, field, nullptr);
  controls_carry(s, H);
  return logits == nullptr ? Status::kOk : head(m, s, logits);
}

// The int8 head: quantize(z, s_z), one MatMulIntegerToFloat (pattern A).
Status head(const ScnodeI8& m, ScnodeStepState& s, float* logits) {
  if (logits == nullptr) return Status::kNullArgument;
  const int L = m.dims.latent, K = m.dims.classes;
  if (s.z.size() != L) return Status::kDimsInvalid;
  for (int i = 0; i < L; ++i) s.zq[i] = quantize(s.z[i], m.s_z);
  linear_i8_tensor(m.head_w.q, m.head_w.scale, K, L, s.zq, m.s_z, m.head_b, logits);
  return detail::all_finite(logits, K) ? Status::kOk : Status::kNonFiniteOutput;
}

// int8, the graph's order: x_norm per channel (folded into lin1_u) -> v_new = (f32(acc) * s_w') + b;
// per evaluation zq = quantize(z, s_z), a = (f32(acc) * f32(s_z * s_w)) + v (a bias-less product, then
// the Add), hq = quantize(tanh(a), s_hidden), k = (f32(acc) * f32(s_hidden * s_w2)) + b2, then the leak.
Status step(const ScnodeI8& m, const float* sample, ScnodeStepState& s, float* logits) {
  if (sample == nullptr) return Status::kNullArgument;
  const int C = m.dims.channels, L = m.dims.latent, H = m.dims.hidden;
  if (s.z.size() != L) return Status::kDimsInvalid;
  if (!all_finite_f32(sample, C)) return Status::kNonFiniteInput;
  for (int c = 0; c < C; ++c) s.xq[c] = quantize(normalise(sample[c], m.mean[c], m.std[c]), m.s_x[c]);
  linear_i8_folded(m.lin1_u.q, m.lin1_u.scale, H, C, s.xq, m.lin1_b, s.v_new);
  controls_mid(s, H);
  auto field = [&](int e, const Lat& z, Lat& k) {
    for (int i = 0; i < L; ++i) s.zq[i] = quantize(z[i], m.s_z);
    gemv_i8(m.lin1_z.q, H, L, s.zq, s.acc);
    const float* v = control_of(s, e);
    for (int j = 0; j < H; ++j) {
      s.a[j] = rescale_i32(s.acc[j], m.s_z, m.lin1_z.scale[j]) + v[j];
      s.hq[j] = quantize(tanh_approx(s.a[j]), m.s_hidden);
    }
    k.resize(L);
    linear_i8_tensor(m.lin2_w.q, m.lin2_w.scale, L, H, s.hq, m.s_hidden, m.lin2_b, k.data());
    leak(m.decay, z, k);
  };
  detail::rk4_integrate(m.rk4, 1, s.z, s.k1, s.k2, s.k3, s.k4, s.st, field, nullptr);
  controls_carry(s, H);
  return logits == nullptr ? Status::kOk : head(m, s, logits);
}

}  // namespace fwref
