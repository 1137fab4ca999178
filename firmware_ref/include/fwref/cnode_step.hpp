// fwref/cnode_step.hpp -- scope: the streaming CNODE (models/stream_cnode.py), fp32 and int8, one classic
// RK4 step of the CNODE's controlled vector field per sample, the latent state z carried across the flight:
//
//   x_norm = (sample - mean) / std;  v_new = lin1_u x_norm + lin1.bias          (H)
//   v_mid  = (v_prev + v_new) * 0.5   (v_prev: the previous sample's v_new; at the first sample v_new)
//   f(z, v) = lin2(tanh(lin1_z z + v)) - decay * z      (decay: the leak, optional)
//   z = one step of detail::rk4_integrate (core/rk4.py's RK4_PROGRAM, constants rk4 = [h/2, h, 2, h/6])
//       with v = v_prev, v_mid, v_mid, v_new at its 4 evaluations;  logits = head(z)
//
// One step here is one run of export/onnx_scnode.py's graph (scnode_step.onnx, .int8.onnx) fed the previous
// and the new sample: the int8 step computes its operations in the graph's order (int8 bit-identical to
// ONNX Runtime), except that v_prev is carried, not recomputed from the previous sample (the same bits: the
// same operations on the same sample). No allocation: the state and its buffers live in ScnodeStepState.
#pragma once

#include <cstdint>

#include "fwref/config.hpp"
#include "fwref/linalg.hpp"
#include "fwref/status.hpp"

namespace fwref {

struct ScnodeDims {
  int channels;  // C
  int latent;    // L
  int hidden;    // H, the field's hidden width
  int classes;   // K
};

struct ScnodeF32 {
  ScnodeDims dims;
  const float* mean;    // (C)
  const float* std;     // (C)
  const float* rk4;     // (4) [h/2, h, 2, h/6] of the time step per sample
  MatF lin1_z;          // (H, L)
  MatF lin1_u;          // (H, C)
  const float* lin1_b;  // (H)
  MatF lin2_w;          // (L, H)
  const float* lin2_b;  // (L)
  const float* decay;   // (L) or nullptr: no leak
  MatF head_w;          // (K, L)
  const float* head_b;  // (K)
};

// int8: per-row weight scales, static activation scales (export/onnx_scnode.py ScnodeQuant).
struct ScnodeI8 {
  ScnodeDims dims;
  const float* mean;
  const float* std;
  const float* rk4;
  MatQ lin1_u;          // (H, C) folded with act.x_norm.scale (pattern B)
  const float* lin1_b;  // (H)
  MatQ lin1_z;          // (H, L) pattern A, activation scale s_z
  MatQ lin2_w;          // (L, H) pattern A, activation scale s_hidden
  const float* lin2_b;  // (L)
  const float* decay;   // (L) or nullptr
  MatQ head_w;          // (K, L) pattern A, activation scale s_z
  const float* head_b;  // (K)
  const float* s_x;     // (C) act.x_norm.scale
  float s_z;            // act.z.scale: every stage's state and the head's input
  float s_hidden;       // act.hidden.scale (1/127: tanh output)
};

struct ScnodeStepState {
  using Lat = VecN<kMaxLatent>;
  Lat z, k1, k2, k3, k4, st;
  float v_prev[kMaxCnodeHidden], v_new[kMaxCnodeHidden], v_mid[kMaxCnodeHidden], a[kMaxCnodeHidden];
  float xn[kMaxChannels];
  std::int8_t xq[kMaxChannels], zq[kMaxLatent], hq[kMaxCnodeHidden];
  std::int32_t acc[kMaxCnodeHidden];
  long steps = 0;  // samples stepped since the last reset (0: the next sample is held as its own predecessor)
};

Status check(const ScnodeF32& m);
Status check(const ScnodeI8& m);

// z = 0 and no previous sample (take-off, between flights, after a reset).
void reset(const ScnodeF32& m, ScnodeStepState& s);
void reset(const ScnodeI8& m, ScnodeStepState& s);

// One new raw sample (C floats): advances z and writes the logits (K) unless ``logits`` is nullptr (then
// head() gives them later, the same bits). A sample holding NaN or Inf returns kNonFiniteInput and leaves
// the state as it was.
Status step(const ScnodeF32& m, const float* sample, ScnodeStepState& s, float* logits);
Status step(const ScnodeI8& m, const float* sample, ScnodeStepState& s, float* logits);
Status head(const ScnodeF32& m, ScnodeStepState& s, float* logits);
Status head(const ScnodeI8& m, ScnodeStepState& s, float* logits);

}  // namespace fwref
