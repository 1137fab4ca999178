// src/gru_step.cpp -- scope: one step of the streaming GRU, fp32 and int8 (fwref/gru_step.hpp), on
// the windowed GRU's kernels (src/gru.cpp): matvec_fast in fp32, the int16 weight copies in int8.
#include "fwref/gru_step.hpp"

#include <cstdint>
#include <cstring>

#include "fwref/kernels_f32.hpp"
#include "fwref/kernels_i8.hpp"
#include "fwref/numerics.hpp"
#include "model_common.hpp"

namespace fwref {

namespace {

#if defined(FWREF_GRU_WHH_INT16) && defined(FWREF_HAS_W16_KERNEL)
#define FWREF_SGRU_W16 1
#endif

// |x| <= the float whose bits are ``limit`` (false for NaN and beyond), on the bits: one integer
// compare where the clamps of logistic_approx / tanh_approx take two float compares and branches.
inline bool within(float x, std::uint32_t limit) {
  std::uint32_t b;
  std::memcpy(&b, &x, 4);
  return (b & 0x7fffffffu) <= limit;
}
constexpr std::uint32_t kBits18 = 0x41900000u, kBits9 = 0x41100000u;  // 18.0f, 9.0f
// logistic_approx and tanh_approx (fwref/numerics.hpp), bit for bit: inside the clamp range the
// clamps are no-ops and *_core is the same float operations; outside (and NaN) the functions.
inline float sigmoid(float x) { return within(x, kBits18) ? logistic_core(x) : logistic_approx(x); }
inline float tanh_(float x) { return within(x, kBits9) ? tanh_core(x) : tanh_approx(x); }

// PyTorch's GRU cell, the windowed GRU's operation order (src/gru.cpp keeps its own private), on
// the gate pre-activations gx(o) = (W_ih x)[o] + b_ih[o] and gh(o) = (W_hh h)[o] + b_hh[o], formed
// here as they are read (the same float operations as the separate bias and rescale passes, fused:
// no store and reload of the 2 x 3H gate rows); out(j, h_j) sees each new h_j (int8: its code).
template <class Gx, class Gh, class Out>
inline void cell(const Gx& gx, const Gh& gh, int H, float* h, const Out& out) {
  for (int j = 0; j < H; ++j) {
    const float r = sigmoid(gx(j) + gh(j));
    const float z = sigmoid(gx(H + j) + gh(H + j));
    const float n = tanh_(gx(2 * H + j) + gh(2 * H + j) * r);
    const float hj = (h[j] - n) * z + n;
    h[j] = hj;
    out(j, hj);
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
#if defined(FWREF_SGRU_W16)
  const int C = m.dims.channels, H = m.dims.hidden;
  if (s.w16_of != m.w_hh.q) {
    expand_i8_to_i16(m.w_hh.q, 3 * H, H, s.whh16);
    expand_i8_to_i16(m.w_ih.q, 3 * H, C, s.wih16);
    for (int c = C; c < w16_stride(C); ++c) s.xq16[c] = 0;  // the kernels read x up to the stride
    for (int j = H; j < w16_stride(H); ++j) s.hq16[j] = 0;
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

// mh[o] = f32(s_h * s_w_hh[o]): rescale_i32's multiplier, the same float32 product, formed once.
void multipliers(const GruI8& m, GruStepState& s) {
  if (s.mh_of == m.w_hh.scale) return;
  for (int o = 0; o < 3 * m.dims.hidden; ++o) s.mh[o] = m.s_h * m.w_hh.scale[o];
  s.mh_of = m.w_hh.scale;
}

// hq (and its int16 copy) = quantize(h, s_h) of the current h, when the last step did not leave it.
void requantize(const GruI8& m, GruStepState& s) {
  if (s.hq_at == s.steps) return;
  for (int j = 0; j < m.dims.hidden; ++j) {
    s.hq[j] = quantize(s.h[j], m.s_h);
#if defined(FWREF_SGRU_W16)
    s.hq16[j] = s.hq[j];
#endif
  }
  s.hq_at = s.steps;
}

}  // namespace

void reset(const GruF32& m, GruStepState& s) {
  s.h.setZero(m.dims.hidden);
  s.steps = 0;
  s.hq_at = -1;  // hq is the int8 step's
}

Status head(const GruF32& m, GruStepState& s, float* logits) {
  if (logits == nullptr) return Status::kNullArgument;
  if (s.h.size() != m.dims.hidden) return Status::kDimsInvalid;
  MapVec out(logits, m.dims.classes);
  matvec_fast(m.head_w, s.h, out);
  out += ConstMapVec(m.head_b, m.dims.classes);
  return detail::all_finite(logits, m.dims.classes) ? Status::kOk : Status::kNonFiniteOutput;
}

Status step(const GruF32& m, const float* sample, GruStepState& s, float* logits) {
  if (sample == nullptr) return Status::kNullArgument;
  const int C = m.dims.channels, H = m.dims.hidden;
  if (s.h.size() != H) return Status::kDimsInvalid;  // reset() was not called for this model
  if (!all_finite_f32(sample, C)) return Status::kNonFiniteInput;
  s.xn.resize(C);
  for (int c = 0; c < C; ++c) s.xn[c] = normalise(sample[c], m.mean[c], m.std[c]);
  matvec_fast(m.w_ih, s.xn, s.gx);
  matvec_fast(m.w_hh, s.h, s.gh);
  const float *gx = s.gx.data(), *gh = s.gh.data(), *b_ih = m.b_ih, *b_hh = m.b_hh;
  cell([=](int o) { return gx[o] + b_ih[o]; }, [=](int o) { return gh[o] + b_hh[o]; }, H, s.h.data(),
       [](int, float) {});
  ++s.steps;
  return logits == nullptr ? Status::kOk : head(m, s, logits);
}

void reset(const GruI8& m, GruStepState& s) {
  s.h.setZero(m.dims.hidden);
  s.steps = 0;
  for (int j = 0; j < m.dims.hidden; ++j) s.hq[j] = 0;  // quantize(0, s_h)
#if defined(FWREF_SGRU_W16)
  for (int j = 0; j < m.dims.hidden; ++j) s.hq16[j] = 0;
#endif
  s.hq_at = 0;
  int16_copies(m, s);
  multipliers(m, s);
}

// The int8 head on hq = quantize(h, s_h) (linear_i8_tensor, ONNX Runtime's MatMulIntegerToFloat).
Status head(const GruI8& m, GruStepState& s, float* logits) {
  if (logits == nullptr) return Status::kNullArgument;
  const int H = m.dims.hidden, K = m.dims.classes;
  if (s.h.size() != H) return Status::kDimsInvalid;
  requantize(m, s);
  linear_i8_tensor(m.head_w.q, m.head_w.scale, K, H, s.hq, m.s_h, m.head_b, logits);
  return detail::all_finite(logits, K) ? Status::kOk : Status::kNonFiniteOutput;
}

// x_norm quantized per channel; acc_x = W_ih' xq, acc_h = W_hh hq (int32, the int16 kernels when the
// copies exist, on int16 codes written by the quantization itself); then the gates as
// linear_i8_folded / linear_i8_tensor form them (numerics.hpp, ONNX Runtime's MatMulIntegerToFloat:
// (f32(acc) * s_w') + b and (f32(acc) * f32(s_h * s_w)) + b, the multiplier formed once: mh), fused
// into the cell; hq = quantize(h, s_h) in the cell's loop, for the next step's W_hh and the head.
Status step(const GruI8& m, const float* sample, GruStepState& s, float* logits) {
  if (sample == nullptr) return Status::kNullArgument;
  const int C = m.dims.channels, H = m.dims.hidden;
  if (s.h.size() != H) return Status::kDimsInvalid;
  if (!all_finite_f32(sample, C)) return Status::kNonFiniteInput;
  const Weights16 w16 = int16_copies(m, s);  // expanded by reset(): a pointer compare here
  multipliers(m, s);
  requantize(m, s);  // hq is not quantize(h) when the state was reset or stepped by the fp32 path
#if defined(FWREF_SGRU_W16)
  for (int c = 0; c < C; ++c) s.xq16[c] = quantize(normalise(sample[c], m.mean[c], m.std[c]), m.s_x[c]);
  gemv_w16_x16(w16.wih, 3 * H, C, s.xq16, s.acc_x);
  gemv_w16_x16(w16.whh, 3 * H, H, s.hq16, s.acc_h);
  std::int8_t* hq = s.hq;
  std::int16_t* hq16 = s.hq16;
  const auto out = [=](int j, float hj) {
    const std::int8_t q = quantize(hj, m.s_h);
    hq[j] = q;
    hq16[j] = q;
  };
#else
  (void)w16;
  for (int c = 0; c < C; ++c) s.xq[c] = quantize(normalise(sample[c], m.mean[c], m.std[c]), m.s_x[c]);
  gemv_i8(m.w_ih.q, 3 * H, C, s.xq, s.acc_x);
  gemv_i8(m.w_hh.q, 3 * H, H, s.hq, s.acc_h);
  std::int8_t* hq = s.hq;
  const auto out = [=](int j, float hj) { hq[j] = quantize(hj, m.s_h); };
#endif
  const std::int32_t *ax = s.acc_x, *ah = s.acc_h;
  const float *sx = m.w_ih.scale, *bx = m.b_ih, *mh = s.mh, *bh = m.b_hh;
  cell([=](int o) { return (static_cast<float>(ax[o]) * sx[o]) + bx[o]; },
       [=](int o) { return (static_cast<float>(ah[o]) * mh[o]) + bh[o]; }, H, s.h.data(), out);
  ++s.steps;
  s.hq_at = s.steps;
  return logits == nullptr ? Status::kOk : head(m, s, logits);
}

}  // namespace fwref
