// src/gru_step.cpp -- scope: one step of the streaming GRU, fp32 and int8 (fwref/gru_step.hpp), on
// the windowed GRU's kernels (src/gru.cpp): matvec_fast in fp32, the int16 weight copies in int8.
#include "fwref/gru_step.hpp"

#include "fwref/kernels_f32.hpp"
#include "fwref/kernels_i8.hpp"
#include "fwref/numerics.hpp"
#include "model_common.hpp"

namespace fwref {

namespace {

// PyTorch's GRU cell, the windowed GRU's operation order (src/gru.cpp keeps its own private).
void cell(const float* gx, const float* gh, int H, float* h) {
  for (int j = 0; j < H; ++j) {
    const float r = logistic_approx(gx[j] + gh[j]);
    const float z = logistic_approx(gx[H + j] + gh[H + j]);
    const float n = tanh_approx(gx[2 * H + j] + gh[2 * H + j] * r);
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
}

Status step(const GruF32& m, const float* sample, GruStepState& s, float* logits) {
  if (sample == nullptr || logits == nullptr) return Status::kNullArgument;
  const int C = m.dims.channels, H = m.dims.hidden;
  if (s.h.size() != H) return Status::kDimsInvalid;  // reset() was not called for this model
  if (!all_finite_f32(sample, C)) return Status::kNonFiniteInput;
  s.xn.resize(C);
  for (int c = 0; c < C; ++c) s.xn[c] = normalise(sample[c], m.mean[c], m.std[c]);
  matvec_fast(m.w_ih, s.xn, s.gx);
  s.gx += ConstMapVec(m.b_ih, 3 * H);
  matvec_fast(m.w_hh, s.h, s.gh);
  s.gh += ConstMapVec(m.b_hh, 3 * H);
  cell(s.gx.data(), s.gh.data(), H, s.h.data());
  ++s.steps;
  MapVec out(logits, m.dims.classes);
  matvec_fast(m.head_w, s.h, out);
  out += ConstMapVec(m.head_b, m.dims.classes);
  return detail::all_finite(logits, m.dims.classes) ? Status::kOk : Status::kNonFiniteOutput;
}

void reset(const GruI8& m, GruStepState& s) {
  s.h.setZero(m.dims.hidden);
  s.steps = 0;
  int16_copies(m, s);
}

Status step(const GruI8& m, const float* sample, GruStepState& s, float* logits) {
  if (sample == nullptr || logits == nullptr) return Status::kNullArgument;
  const int C = m.dims.channels, H = m.dims.hidden, K = m.dims.classes;
  if (s.h.size() != H) return Status::kDimsInvalid;
  if (!all_finite_f32(sample, C)) return Status::kNonFiniteInput;
  const Weights16 w16 = int16_copies(m, s);  // expanded by reset(): a pointer compare here
  s.gx.resize(3 * H);
  s.gh.resize(3 * H);
  for (int c = 0; c < C; ++c) s.xq[c] = quantize(normalise(sample[c], m.mean[c], m.std[c]), m.s_x[c]);
  linear_i8_folded(m.w_ih.q, m.w_ih.scale, 3 * H, C, s.xq, m.b_ih, s.gx.data(), w16.wih);
  for (int j = 0; j < H; ++j) s.hq[j] = quantize(s.h[j], m.s_h);
  linear_i8_tensor(m.w_hh.q, m.w_hh.scale, 3 * H, H, s.hq, m.s_h, m.b_hh, s.gh.data(), w16.whh);
  cell(s.gx.data(), s.gh.data(), H, s.h.data());
  ++s.steps;
  for (int j = 0; j < H; ++j) s.hq[j] = quantize(s.h[j], m.s_h);
  linear_i8_tensor(m.head_w.q, m.head_w.scale, K, H, s.hq, m.s_h, m.head_b, logits);
  return detail::all_finite(logits, K) ? Status::kOk : Status::kNonFiniteOutput;
}

}  // namespace fwref
