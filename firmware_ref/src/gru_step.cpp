// src/gru_step.cpp -- scope: one step of the streaming GRU, fp32 (fwref/gru_step.hpp).
#include "fwref/gru_step.hpp"

#include "fwref/numerics.hpp"
#include "model_common.hpp"

namespace fwref {

void reset(const GruF32& m, GruStepState& s) {
  s.h.setZero(m.dims.hidden);
  s.steps = 0;
}

Status step(const GruF32& m, const float* sample, GruStepState& s, float* logits) {
  if (sample == nullptr || logits == nullptr) return Status::kNullArgument;
  const int C = m.dims.channels, H = m.dims.hidden;
  if (s.h.size() != H) return Status::kDimsInvalid;  // reset() was not called for this model
  if (!detail::all_finite(sample, C)) return Status::kNonFiniteInput;
  s.xn.resize(C);
  for (int c = 0; c < C; ++c) s.xn[c] = normalise(sample[c], m.mean[c], m.std[c]);
  matvec(m.w_ih, s.xn, s.gx);
  s.gx += ConstMapVec(m.b_ih, 3 * H);
  matvec(m.w_hh, s.h, s.gh);
  s.gh += ConstMapVec(m.b_hh, 3 * H);
  // the windowed GRU's cell (src/gru.cpp), in the same operation order
  const float* gx = s.gx.data();
  const float* gh = s.gh.data();
  float* h = s.h.data();
  for (int j = 0; j < H; ++j) {
    const float r = logistic_approx(gx[j] + gh[j]);
    const float z = logistic_approx(gx[H + j] + gh[H + j]);
    const float n = tanh_approx(gx[2 * H + j] + gh[2 * H + j] * r);
    h[j] = (h[j] - n) * z + n;
  }
  ++s.steps;
  MapVec out(logits, m.dims.classes);
  matvec(m.head_w, s.h, out);
  out += ConstMapVec(m.head_b, m.dims.classes);
  return detail::all_finite(logits, m.dims.classes) ? Status::kOk : Status::kNonFiniteOutput;
}

}  // namespace fwref
