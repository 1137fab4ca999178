// src/gru_step.cpp -- scope: one step of the streaming GRU, fp32 and int8 (fwref/gru_step.hpp), on
// the windowed GRU's kernels (src/gru.cpp): matvec_fast in fp32, the int16 weight copies in int8.
#include "fwref/gru_step.hpp"

#include "fwref/kernels_f32.hpp"
#include "fwref/kernels_i8.hpp"
#include "fwref/numerics.hpp"
#include "model_common.hpp"

namespace fwref {

namespace {

// PyTorch's GRU cell, the windowed GRU's operation order (src/gru.cpp keeps its own private), on
// the gate pre-activations gx(o) = (W_ih x)[o] + b_ih[o] and gh(o) = (W_hh h)[o] + b_hh[o], formed
// here as they are read (the same float operations as the separate bias and rescale passes, fused:
// no store and reload of the 2 x 3H gate rows).
template <class Gx, class Gh>
inline void cell(const Gx& gx, const Gh& gh, int H, float* h) {
  for (int j = 0; j < H; ++j) {
    const float r = logistic_approx(gx(j) + gh(j));
    const float z = logistic_approx(gx(H + j) + gh(H + j));
    const float n = tanh_approx(gx(2 * H + j) + gh(2 * H + j) * r);
    h[j] = (h[j] - n) * z + n;
  }
}

// The int16 copies of W_hh and W_ih this build's int8 step reads (null: the int8 kernels), expanded
// when the state does not hold this model's yet (reset, or a step after the model changed).
struct Weights16 {
  const std::int16_t* whh = nullptr;
  const std::int16_t* wih = nullptr;
};

Weights16 int16_copies(const GruI8& m, GruStepState& s) {
  Weights16 w;
#if defined(FWREF_GRU_WHH_INT16) && defined(FWREF_HAS_W16_KERNEL)
  const int C = m.dims.channels, H = m.dims.hidden;
  if (s.w16_of != m.w_hh.q) {
    expand_i8_to_i16(m.w_hh.q, 3 * H, H, s.whh16);
    expand_i8_to_i16(m.w_ih.q, 3 * H, C, s.wih16);
    s.w16_of = m.w_hh.q;
  }
  w.whh = s.whh16;
  w.wih = s.wih16;
#else
  (void)m;
  (void)s;
#endif
  return w;
}

}  // namespace

void reset(const GruF32& m, GruStepState& s) {
  s.h.setZero(m.dims.hidden);
  s.steps = 0;
  s.hq_at = -1;  // hq is the int8 step's
}

Status step(const GruF32& m, const float* sample, GruStepState& s, float* logits) {
  if (sample == nullptr || logits == nullptr) return Status::kNullArgument;
  const int C = m.dims.channels, H = m.dims.hidden;
  if (s.h.size() != H) return Status::kDimsInvalid;  // reset() was not called for this model
  if (!all_finite_f32(sample, C)) return Status::kNonFiniteInput;
  s.xn.resize(C);
  for (int c = 0; c < C; ++c) s.xn[c] = normalise(sample[c], m.mean[c], m.std[c]);
  matvec_fast(m.w_ih, s.xn, s.gx);
  matvec_fast(m.w_hh, s.h, s.gh);
  const float *gx = s.gx.data(), *gh = s.gh.data(), *b_ih = m.b_ih, *b_hh = m.b_hh;
  cell([=](int o) { return gx[o] + b_ih[o]; }, [=](int o) { return gh[o] + b_hh[o]; }, H, s.h.data());
  ++s.steps;
  MapVec out(logits, m.dims.classes);
  matvec_fast(m.head_w, s.h, out);
  out += ConstMapVec(m.head_b, m.dims.classes);
  return detail::all_finite(logits, m.dims.classes) ? Status::kOk : Status::kNonFiniteOutput;
}

void reset(const GruI8& m, GruStepState& s) {
  s.h.setZero(m.dims.hidden);
  s.steps = 0;
  for (int j = 0; j < m.dims.hidden; ++j) s.hq[j] = 0;  // quantize(0, s_h)
  s.hq_at = 0;
  int16_copies(m, s);
}

// x_norm quantized per channel; acc_x = W_ih' xq, acc_h = W_hh hq (int32, the int16 kernels when the
// copies exist); then the gates as linear_i8_folded / linear_i8_tensor form them (numerics.hpp,
// ONNX Runtime's MatMulIntegerToFloat: (f32(acc) * s_w') + b and (f32(acc) * f32(s_h * s_w)) + b),
// fused into the cell; hq = quantize(h, s_h) once, for the head and the next step's W_hh.
Status step(const GruI8& m, const float* sample, GruStepState& s, float* logits) {
  if (sample == nullptr || logits == nullptr) return Status::kNullArgument;
  const int C = m.dims.channels, H = m.dims.hidden, K = m.dims.classes;
  if (s.h.size() != H) return Status::kDimsInvalid;
  if (!all_finite_f32(sample, C)) return Status::kNonFiniteInput;
  const Weights16 w16 = int16_copies(m, s);  // expanded by reset(): a pointer compare here
  for (int c = 0; c < C; ++c) s.xq[c] = quantize(normalise(sample[c], m.mean[c], m.std[c]), m.s_x[c]);
  gemv_i8_any(m.w_ih.q, w16.wih, 0, 3 * H, C, s.xq, s.acc_x);
  if (s.hq_at != s.steps) {  // hq is not quantize(h) (the state was reset or stepped by the fp32 path)
    for (int j = 0; j < H; ++j) s.hq[j] = quantize(s.h[j], m.s_h);
  }
  gemv_i8_any(m.w_hh.q, w16.whh, 0, 3 * H, H, s.hq, s.acc_h);
  const std::int32_t *ax = s.acc_x, *ah = s.acc_h;
  const float *sx = m.w_ih.scale, *bx = m.b_ih, *sh = m.w_hh.scale, *bh = m.b_hh, s_h = m.s_h;
  cell([=](int o) { return (static_cast<float>(ax[o]) * sx[o]) + bx[o]; },
       [=](int o) { return rescale_i32(ah[o], s_h, sh[o]) + bh[o]; }, H, s.h.data());
  ++s.steps;
  for (int j = 0; j < H; ++j) s.hq[j] = quantize(s.h[j], m.s_h);
  s.hq_at = s.steps;
  linear_i8_tensor(m.head_w.q, m.head_w.scale, K, H, s.hq, m.s_h, m.head_b, logits);
  return detail::all_finite(logits, K) ? Status::kOk : Status::kNonFiniteOutput;
}

}  // namespace fwref
