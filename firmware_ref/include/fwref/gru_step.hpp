// fwref/gru_step.hpp -- scope: the streaming GRU (models/stream_gru.py), fp32 and int8, one step per sample:
// the hidden state is carried from sample to sample instead of re-running a window.
//
//   x_norm = (sample - mean) / std
//   gx = W_ih x_norm + b_ih,  gh = W_hh h + b_hh            (3H) rows r, z, n
//   r = sigmoid(gx_r + gh_r);  z = sigmoid(gx_z + gh_z)
//   n = tanh(gx_n + gh_n * r); h = (h - n) * z + n          PyTorch's cell, ONNX linear_before_reset=1
//   logits = head(h)
//
// The weights are a GruF32 (fwref/gru.hpp) with dims.window = 1 (checked by its check()); the cell is
// the windowed GRU's arithmetic, step by step, so that one step here is one step of export/onnx_sgru.py's
// graph (sgru_step.onnx). No allocation: the state and its buffers live in the caller's GruStepState.
#pragma once

#include <cstdint>

#include "fwref/config.hpp"
#include "fwref/gru.hpp"
#include "fwref/linalg.hpp"
#include "fwref/status.hpp"

namespace fwref {

struct GruStepState {
  VecN<kMaxGruHidden> h;  // the carried hidden state (H)
  VecN<kMaxGruGates> gx, gh;
  VecN<kMaxChannels> xn;
  std::int8_t xq[kMaxChannels];  // int8 only: the quantized sample and state
  std::int8_t hq[kMaxGruHidden];
  std::int32_t acc_x[kMaxGruGates], acc_h[kMaxGruGates];  // int8 only: W_ih xq and W_hh hq, int32
  long steps = 0;  // samples stepped since the last reset
  long hq_at = -1;  // int8 only: hq = quantize(h, s_h) as of this step count (the head's, reused by the next step)
  // int8 only: the recurrent rescale's multipliers f32(s_h * s_w_hh[o]) (rescale_i32's product, formed
  // once by reset() or when the weights change, by address as w16_of below), not per sample.
  float mh[kMaxGruGates];
  const float* mh_of = nullptr;
#if defined(FWREF_GRU_WHH_INT16)
  // int8 only, option FWREF_GRU_WHH_INT16 (on in firmware_ref/mcu and in the host build): W_hh and
  // W_ih sign-extended to int16 and packed for the platform's int16 kernel, as the windowed GRU's
  // GruWorkspace holds them (fwref/gru.hpp: LDM + SMLAD on the Cortex-M, vpmaddwd on x86-64), the
  // same int32 accumulators as the int8 kernel. Made by reset(GruI8) (and by step() if the model
  // changed), not per sample: 2 * 3H * (pad8(H) + pad8(C)) bytes, sized by the limits (no heap).
  // w16_of records which weights they hold BY ADDRESS: a caller that frees a model's weights and
  // loads others at the same address must call reset() (it expands again) or set w16_of = nullptr.
  alignas(8) std::int16_t whh16[kMaxGruGates * ((kMaxGruHidden + 7) & ~7)];  // LDRD needs word alignment
  alignas(8) std::int16_t wih16[kMaxGruGates * ((kMaxChannels + 7) & ~7)];
  const std::int8_t* w16_of = nullptr;
  // The int16 kernels' inputs, written as int16 by the quantization itself (no widening pass per
  // product): xq and hq's codes, zero after C / H up to the next multiple of 8 (zeroed by reset()).
  alignas(32) std::int16_t xq16[(kMaxChannels + 7) & ~7];
  alignas(32) std::int16_t hq16[(kMaxGruHidden + 7) & ~7];
#endif
};

// h = 0 (take-off, or a reset between flights / after a gap in the timestamps).
void reset(const GruF32& m, GruStepState& s);
// fp32 step: the products by matvec_fast (fwref/kernels_f32.hpp: the Cortex-M VFP kernel, bit-identical
// per row to the plain loop; Eigen's matvec on the host), as the windowed fp32 GRU's.

// One new raw sample (C floats): advances h and writes the class logits (K). A sample holding NaN or
// Inf returns kNonFiniteInput and leaves the state as it was (the sample is skipped, the caller says so).
// logits == nullptr: h advances and the head is not run (kOk, no check of the state's finiteness):
// the stream asks for logits only on the samples that end a stride (fwref/stream.hpp); head() gives
// the logits of the current state later, the same bits as a step with logits.
Status step(const GruF32& m, const float* sample, GruStepState& s, float* logits);
Status head(const GruF32& m, GruStepState& s, float* logits);

// int8 (export/onnx_sgru_int8.py, sgru_step.int8.onnx): the windowed int8 GRU's step (src/gru.cpp) with
// the state carried: x_norm quantized per channel (folded into W_ih), h and the head input with s_h.
// reset() also expands the int16 weight copies (FWREF_GRU_WHH_INT16, above) when they are not this
// model's: the step then uses the windowed GRU's int16 kernels (the same accumulators, bit for bit).
void reset(const GruI8& m, GruStepState& s);
Status step(const GruI8& m, const float* sample, GruStepState& s, float* logits);
Status head(const GruI8& m, GruStepState& s, float* logits);

}  // namespace fwref
