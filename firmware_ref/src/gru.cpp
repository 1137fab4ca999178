// src/gru.cpp -- scope: GRU inference, fp32 and int8 (fwref/gru.hpp), and its weight checks.
#include "fwref/gru.hpp"

#include <cstring>

#include "fwref/kernels_f32.hpp"
#include "fwref/numerics.hpp"
#include "fwref/vmath_f32.hpp"
#include "model_common.hpp"

// The host's int8 step (x86-64 with the int16 weight copies): see infer_i8_host below. Elsewhere (the
// Cortex-M build, FWREF_PORTABLE_KERNELS) the portable path of infer(const GruI8&) runs.
#if defined(FWREF_GRU_WHH_INT16) && defined(__x86_64__) && !defined(FWREF_PORTABLE_KERNELS)
#define FWREF_GRU_I8_HOST 1
#include "fwref/vmath_gru_i8.hpp"
#endif

namespace fwref {

namespace {

using namespace detail;  // src/'s internal helpers (model_common.hpp and the model's own headers)

Status check_dims(const GruDims& d) {
  if (d.channels <= 0 || d.window < 1 || d.classes <= 0 || d.hidden <= 0) return Status::kDimsInvalid;
  if (!dim_ok(d.channels, kMaxChannels) || !dim_ok(d.window, kMaxWindow) || !dim_ok(d.classes, kMaxClasses) ||
      !dim_ok(d.hidden, kMaxGruHidden)) {
    return Status::kDimsTooLarge;
  }
  return Status::kOk;
}

template <class Model>
Status check_common(const Model& m) {
  const GruDims& d = m.dims;
  if (m.mean == nullptr || m.std == nullptr || m.b_ih == nullptr || m.b_hh == nullptr || m.head_b == nullptr) {
    return Status::kNullArgument;
  }
  if (!all_positive_finite(m.std, d.channels) || !all_finite(m.mean, d.channels)) return Status::kBadWeights;
  return Status::kOk;
}

// PyTorch's GRU cell on the gate pre-activations gx (input part) and gh (recurrent part), in the
// int8 graph's operator order: r = sigmoid(gx_r + gh_r), z = sigmoid(gx_z + gh_z),
// n = tanh(gx_n + gh_n * r), h = (h - n) * z + n. h[j] depends on the old h[j] only (gh holds the
// recurrent product of the old h), so the update is in place.
void gru_cell(const float* gx, const float* gh, int hidden, float* h) {
  int j = 0;
#if defined(FWREF_VMATH_AVX2)
  // 8 units per AVX2 vector, each lane the scalar loop's operations below (fwref/vmath_f32.hpp's
  // logistic8 / tanh8 are bit-identical to logistic_approx / tanh_approx; mul, add, sub unfused)
  for (; j + 8 <= hidden; j += 8) {
    const __m256 r = logistic8(_mm256_add_ps(_mm256_loadu_ps(gx + j), _mm256_loadu_ps(gh + j)));
    const __m256 z = logistic8(_mm256_add_ps(_mm256_loadu_ps(gx + hidden + j), _mm256_loadu_ps(gh + hidden + j)));
    const __m256 n = tanh8(_mm256_add_ps(_mm256_loadu_ps(gx + 2 * hidden + j),
                                         _mm256_mul_ps(_mm256_loadu_ps(gh + 2 * hidden + j), r)));
    const __m256 hj = _mm256_loadu_ps(h + j);
    _mm256_storeu_ps(h + j, _mm256_add_ps(_mm256_mul_ps(_mm256_sub_ps(hj, n), z), n));
  }
#endif
  for (; j < hidden; ++j) {
    const float r = logistic_approx(gx[j] + gh[j]);
    const float z = logistic_approx(gx[hidden + j] + gh[hidden + j]);
    const float n = tanh_approx(gx[2 * hidden + j] + gh[2 * hidden + j] * r);
    h[j] = (h[j] - n) * z + n;
  }
}

// q[j] = quantize(x[j], s) through plain pointers (an int8 store may alias anything: a loop over an
// Eigen vector would reload its data pointer and size per element).
void quantize_all(const float* x, int n, float s, std::int8_t* q) {
  for (int i = 0; i < n; ++i) q[i] = quantize(x[i], s);
}

template <class Vec>
void trace_row(const Vec& v, int n, float* out) {
  if (out == nullptr) return;
  for (int i = 0; i < n; ++i) out[i] = v[i];
}

// The matrix shapes a GRU of either precision must have (same layout, other element type).
template <class Model>
bool shapes_ok(const Model& m) {
  const GruDims& d = m.dims;
  return view_ok(m.w_ih, 3 * d.hidden, d.channels) && view_ok(m.w_hh, 3 * d.hidden, d.hidden) &&
         view_ok(m.head_w, d.classes, d.hidden);
}

bool scales_ok(const GruF32&) { return true; }
bool scales_ok(const GruI8& m) { return all_positive_finite(m.s_x, m.dims.channels) && all_positive_finite(&m.s_h, 1); }

template <class Model>
Status check_any(const Model& m) {
  return detail::check_model(check_dims(m.dims), [&] { return shapes_ok(m); },
                             [&] { return scales_ok(m) ? check_common(m) : Status::kBadWeights; });
}

}  // namespace

Status check(const GruF32& m) { return check_any(m); }
Status check(const GruI8& m) { return check_any(m); }

#if defined(FWREF_HAS_W8_VNNI)
namespace {
// gh = W_hh h + b_hh. With the AVX2 + FMA build, odd steps ask for the row passes in reverse (used by
// the AVX-512 kernel): W_hh (3H x H floats, 77 KB for H = 80) does not fit L1d, but the rows a step
// read last are still there when the next step starts with them. The same results in either order.
void recurrent_product(const GruF32& m, GruWorkspace& ws, bool reverse) {
#if defined(FWREF_GEMV_FMA)
  ws.gh.resize(m.w_hh.rows);
  gemv_f32_host(m.w_hh.data, m.w_hh.rows, m.w_hh.cols, ws.h.data(), m.b_hh, ws.gh.data(), reverse);
#else
  (void)reverse;
  matvec_bias_f32(m.w_hh, ws.h, m.b_hh, ws.gh);
#endif
}

// The fp32 steps on an x86-64 host: blocks of GruWorkspace::kGxSteps steps, first the block's input
// gates (W_ih held in L1 across them), then its recurrent steps (only W_hh streams from L2). Every
// product and cell is the one of the step-by-step loop below, so the same bits.
void steps_f32_blocked(const GruF32& m, const float* x, GruWorkspace& ws, GruTrace* tr) {
  const int C = m.dims.channels, W = m.dims.window, H = m.dims.hidden;
  for (int t0 = 0; t0 < W; t0 += GruWorkspace::kGxSteps) {
    const int nt = W - t0 < GruWorkspace::kGxSteps ? W - t0 : GruWorkspace::kGxSteps;
    for (int k = 0; k < nt; ++k) {
      const int t = t0 + k;
      for (int c = 0; c < C; ++c) ws.xn[c] = normalise(x[t * C + c], m.mean[c], m.std[c]);
      if (tr != nullptr) trace_row(ws.xn, C, tr->x_norm == nullptr ? nullptr : tr->x_norm + t * C);
      matvec_bias_f32(m.w_ih, ws.xn, m.b_ih, MapVec(ws.gx_block + k * 3 * H, 3 * H));
    }
    for (int k = 0; k < nt; ++k) {
      recurrent_product(m, ws, ((t0 + k) & 1) != 0);
      gru_cell(ws.gx_block + k * 3 * H, ws.gh.data(), H, ws.h.data());
      if (tr != nullptr) trace_row(ws.h, H, tr->h == nullptr ? nullptr : tr->h + (t0 + k) * H);
    }
  }
}
}  // namespace
#endif

Status infer(const GruF32& m, const float* x, float* logits, GruWorkspace& ws, GruTrace* tr) {
  if (x == nullptr || logits == nullptr) return Status::kNullArgument;
  const GruDims& d = m.dims;
  const int C = d.channels, W = d.window, H = d.hidden;
  if (!all_finite_n(x, W * C)) return Status::kNonFiniteInput;
  ws.h.setZero(H);
  ws.xn.resize(C);
#if defined(FWREF_HAS_W8_VNNI)
  steps_f32_blocked(m, x, ws, tr);
#else
  for (int t = 0; t < W; ++t) {
    for (int c = 0; c < C; ++c) ws.xn[c] = normalise(x[t * C + c], m.mean[c], m.std[c]);
    if (tr != nullptr) trace_row(ws.xn, C, tr->x_norm == nullptr ? nullptr : tr->x_norm + t * C);
    matvec_bias_f32(m.w_ih, ws.xn, m.b_ih, ws.gx);  // MatMul then Add, as ws.gx = W_ih xn; ws.gx += b_ih
    matvec_bias_f32(m.w_hh, ws.h, m.b_hh, ws.gh);
    gru_cell(ws.gx.data(), ws.gh.data(), H, ws.h.data());
    if (tr != nullptr) trace_row(ws.h, H, tr->h == nullptr ? nullptr : tr->h + t * H);
  }
#endif
  MapVec out(logits, d.classes);
  matvec_bias_f32(m.head_w, ws.h, m.head_b, out);
  return all_finite(logits, d.classes) ? Status::kOk : Status::kNonFiniteOutput;
}

#if defined(FWREF_GRU_WHH_INT16) && defined(FWREF_HAS_W16_KERNEL)
namespace {
// The int16 copies of W_ih and W_hh (fwref/kernels_i8.hpp's packed layout), made at the first int8
// inference of a model (ws.w16_of, fwref/gru.hpp).
void w16_copies(const GruI8& m, GruWorkspace& ws, const std::int16_t** wih16, const std::int16_t** whh16) {
  const int C = m.dims.channels, H = m.dims.hidden;
  if (ws.w16_of != m.w_hh.q) {
    expand_i8_to_i16(m.w_hh.q, 3 * H, H, ws.whh16);
    expand_i8_to_i16(m.w_ih.q, 3 * H, C, ws.wih16);
    ws.w16_of = m.w_hh.q;
  }
  *whh16 = ws.whh16;
  *wih16 = ws.wih16;
}
}  // namespace
#endif

#if defined(FWREF_GRU_I8_HOST)
namespace {

// The host's two products per step, from one of two packed copies (both exact, so the same integers):
// W16 the int16 copies (vpmaddwd, any x86-64: its kernel chosen at run time, fwref/kernels_i8.hpp)
// fed int16 codes; W8 on a CPU whose run-time choice is avx512vnni, the int8 copies for vpdpbusd
// (fwref/kernels_w8_vnni.hpp) fed int8 codes, offset to u8 here.
struct W16Products {
  using Code = std::int16_t;
  const std::int16_t *wih, *whh;
  void run(const std::int16_t* w, int rows, int cols, const Code* q, std::int32_t* acc) const {
    gemv_w16_x16(w, rows, cols, q, acc);
  }
};
struct W8Products {
  using Code = std::int8_t;
  const std::uint8_t *wih, *whh;
  GemvW8Fn fn;
  void run(const std::uint8_t* w, int rows, int cols, const Code* q, std::int32_t* acc) const {
    gemv_w8_codes(fn, w, rows, cols, q, acc);
  }
};

// The host's steps: the input codes quantized straight into the products' code type, both products'
// accumulators over all 3H rows, then the gates, the state update and the state's next codes in one
// pass (fwref/vmath_gru_i8.hpp: 8 lanes per AVX2 vector). The same operations in the same order as
// the portable path below, so the same bits (checked by fwref_vmath, and against ONNX Runtime by the
// parity tests).
template <class Products>
void steps_i8_host(const GruI8& m, const Products& prod, const float* x, GruWorkspace& ws, GruTrace* tr) {
  using Code = typename Products::Code;
  const int C = m.dims.channels, W = m.dims.window, H = m.dims.hidden;
  alignas(32) Code xq[w16_stride(kMaxChannels)] = {};   // zero after C: the int16 kernel's padding
  alignas(32) Code hq[w16_stride(kMaxGruHidden)] = {};  // quantize(h0 = 0, s_h) = 0
  alignas(32) std::int32_t acc_x[kMaxGruGates], acc_h[kMaxGruGates];
  const GruGateInputs g{acc_x, m.w_ih.scale, m.b_ih, acc_h, m.s_h, m.w_hh.scale, m.b_hh};
  float* h = ws.h.data();
  for (int t = 0; t < W; ++t) {
    float* xn = tr != nullptr && tr->x_norm != nullptr ? tr->x_norm + t * C : nullptr;
    normalise_quantize_row(x + t * C, m.mean, m.std, m.s_x, C, xn, xq);
    prod.run(prod.wih, 3 * H, C, xq, acc_x);  // GX row t (s_x folded into W_ih')
    prod.run(prod.whh, 3 * H, H, hq, acc_h);
    gru_gates_i8(g, H, h, hq);
    if (tr != nullptr) trace_row(ws.h, H, tr->h == nullptr ? nullptr : tr->h + t * H);
  }
  for (int j = 0; j < H; ++j) ws.hq[j] = static_cast<std::int8_t>(hq[j]);  // quantize(h_W, s_h)
}

// The host's int8 inference (infer() below sends it every call unless FWREF_I8_KERNEL=portable): the
// steps on the faster copy this CPU runs (W8 where the run-time choice is avx512vnni, else W16), then
// the head as the portable path computes it.
Status infer_i8_host(const GruI8& m, const float* x, float* logits, GruWorkspace& ws, GruTrace* tr) {
  const GruDims& d = m.dims;
  const int C = d.channels, H = d.hidden;
  if (!all_finite_n(x, d.window * C)) return Status::kNonFiniteInput;
  ws.h.setZero(H);
  if (const GemvW8Fn fn = gemv_w8_kernel()) {
    if (ws.w8_of != m.w_hh.q) {
      pack_i8_w8(m.w_ih.q, 3 * H, C, ws.wih8);
      pack_i8_w8(m.w_hh.q, 3 * H, H, ws.whh8);
      ws.w8_of = m.w_hh.q;
    }
    steps_i8_host(m, W8Products{ws.wih8, ws.whh8, fn}, x, ws, tr);
  } else {
    W16Products prod{};
    w16_copies(m, ws, &prod.wih, &prod.whh);
    steps_i8_host(m, prod, x, ws, tr);
  }
  linear_i8_tensor(m.head_w.q, m.head_w.scale, d.classes, H, ws.hq, m.s_h, m.head_b, logits);  // ws.hq: quantize(h_W)
  return all_finite(logits, d.classes) ? Status::kOk : Status::kNonFiniteOutput;
}

}  // namespace
#endif

Status infer(const GruI8& m, const float* x, float* logits, GruWorkspace& ws, GruTrace* tr) {
  if (x == nullptr || logits == nullptr) return Status::kNullArgument;
#if defined(FWREF_GRU_I8_HOST)
  // FWREF_I8_KERNEL=portable (fwref/kernels_i8.hpp) runs the portable path below on the host too: the
  // whole model's paths compared by tests/test_firmware.py
  if (std::strcmp(gemv_i8_kernel_name(), "portable") != 0) return infer_i8_host(m, x, logits, ws, tr);
#endif
  const GruDims& d = m.dims;
  const int C = d.channels, W = d.window, H = d.hidden;
  if (!all_finite_f32(x, W * C)) return Status::kNonFiniteInput;
  ws.h.setZero(H);
  ws.gx.resize(3 * H);
  ws.gh.resize(3 * H);
  const std::int16_t *whh16 = nullptr, *wih16 = nullptr;
#if defined(FWREF_GRU_WHH_INT16) && defined(FWREF_HAS_W16_KERNEL)
  w16_copies(m, ws, &wih16, &whh16);
#endif
  for (int t = 0; t < W; ++t) {
    for (int c = 0; c < C; ++c) {
      const float xn = normalise(x[t * C + c], m.mean[c], m.std[c]);
      if (tr != nullptr && tr->x_norm != nullptr) tr->x_norm[t * C + c] = xn;
      ws.xq[c] = quantize(xn, m.s_x[c]);
    }
    // GX row t = B(xq, W_ih') + b_ih (s_x folded into W_ih'); gh = A(quantize(h, s_h), W_hh, s_h) + b_hh
    linear_i8_folded(m.w_ih.q, m.w_ih.scale, 3 * H, C, ws.xq, m.b_ih, ws.gx.data(), wih16);
    quantize_all(ws.h.data(), H, m.s_h, ws.hq);
    linear_i8_tensor(m.w_hh.q, m.w_hh.scale, 3 * H, H, ws.hq, m.s_h, m.b_hh, ws.gh.data(), whh16);
    gru_cell(ws.gx.data(), ws.gh.data(), H, ws.h.data());
    if (tr != nullptr) trace_row(ws.h, H, tr->h == nullptr ? nullptr : tr->h + t * H);
  }
  quantize_all(ws.h.data(), H, m.s_h, ws.hq);
  linear_i8_tensor(m.head_w.q, m.head_w.scale, d.classes, H, ws.hq, m.s_h, m.head_b, logits);
  return all_finite(logits, d.classes) ? Status::kOk : Status::kNonFiniteOutput;
}

}  // namespace fwref
