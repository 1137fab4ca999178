// src/cnode.cpp -- scope: CNODE inference, fp32 and int8 (fwref/cnode.hpp), and its weight checks.
#include "fwref/cnode.hpp"

#include <cstring>

#include "fwref/kernels_f32.hpp"
#include "fwref/kernels_i8_x2.hpp"
#include "fwref/linear_w16_avx2.hpp"
#include "fwref/numerics.hpp"
#include "fwref/tanhq.hpp"
#include "fwref/vmath_f32.hpp"
#include "fwref/vmath_i8.hpp"
#include "cnode_controls.hpp"
#include "cnode_copies16.hpp"
#include "cnode_f32_t.hpp"
#include "cnode_field16.hpp"
#include "cnode_vrows.hpp"
#include "model_common.hpp"
#if defined(FWREF_HAS_W8_VNNI)
#include "cnode_w8.hpp"
#endif

namespace fwref {

namespace {

using namespace detail;  // src/'s internal helpers (model_common.hpp and the model's own headers)

Status check_dims(const CnodeDims& d) {
  if (d.channels <= 0 || d.window < 2 || d.classes <= 0 || d.hidden <= 0 || d.latent <= 0 || d.steps <= 0 ||
      d.stage_times != 2 * d.steps + 1) {
    return Status::kDimsInvalid;
  }
  if (!dim_ok(d.channels, kMaxChannels) || !dim_ok(d.window, kMaxWindow) || !dim_ok(d.classes, kMaxClasses) ||
      !dim_ok(d.hidden, kMaxCnodeHidden) || !dim_ok(d.latent, kMaxLatent) || !dim_ok(d.steps, kMaxSteps)) {
    return Status::kDimsTooLarge;
  }
  return Status::kOk;
}

// Shared by both precisions: the tensors that are float32 in both sections.
template <class Model>
Status check_common(const Model& m) {
  const CnodeDims& d = m.dims;
  if (m.mean == nullptr || m.std == nullptr || m.stage_index == nullptr || m.rk4 == nullptr ||
      m.encoder_b == nullptr || m.lin1_b == nullptr || m.lin2_b == nullptr || m.head_b == nullptr) {
    return Status::kNullArgument;
  }
  if (!all_positive_finite(m.std, d.channels) || !all_finite(m.mean, d.channels) || !all_finite(m.rk4, kRk4Consts)) {
    return Status::kBadWeights;
  }
  for (int e = 0; e < d.evals(); ++e) {
    if (m.stage_index[e] < 0 || m.stage_index[e] >= d.stage_times) return Status::kBadWeights;
  }
  if (!v_rows_serve(m.stage_index, d.evals(), d.stage_times)) return Status::kBadWeights;
  return Status::kOk;
}

// U[s, :] = sum over w with interp[s, w] != 0 of interp[s, w] * x_norm[w, :], in increasing w
// (the zeros of the dense product add exact zeros, so skipping them changes nothing).
// AVX2 host: 8 zero tests per comparison, 8 channels per vector (fwref/vmath_f32.hpp: the same bits).
void interp_row_f32(const float* p_row, const float* x, const float* mean, const float* std_, int window,
                    int channels, float* u) {
  for (int c = 0; c < channels; ++c) u[c] = 0.0f;
  int w = 0;
#if defined(FWREF_VMATH_AVX2)
  for (; w + 8 <= window; w += 8) {
    for (unsigned nz = nonzero8(p_row + w); nz != 0; nz &= nz - 1) {
      const int k = w + __builtin_ctz(nz);  // increasing k, as the scalar loop
      add_scaled_normalised_n(u, p_row[k], x + k * channels, mean, std_, channels);
    }
  }
#endif
  for (; w < window; ++w) {
    const float p = p_row[w];
    if (p == 0.0f) continue;
    const float* xw = x + w * channels;
    for (int c = 0; c < channels; ++c) u[c] += p * normalise(xw[c], mean[c], std_[c]);
  }
}

void trace_x_norm(const float* x, const float* mean, const float* std_, int window, int channels, float* out) {
  for (int w = 0; w < window; ++w) {
    for (int c = 0; c < channels; ++c) out[w * channels + c] = normalise(x[w * channels + c], mean[c], std_[c]);
  }
}

// q[i] = quantize(x[i], s) through plain pointers: an int8 store may alias anything, so loops over
// Eigen vectors would reload their data pointer and size per element. (``q`` int16 on the stage path
// with the int16 kernel: the same codes, stored widened.) 8 lanes per AVX2 vector on the host,
// bit-identical (fwref/vmath_i8.hpp).
template <class Q>
void quantize_all(const float* x, int n, float s, Q* q) {
  quantize_n(x, n, s, q);
}
#if defined(__ARM_FEATURE_SAT) && defined(__ARM_FP) && !defined(FWREF_PORTABLE_KERNELS)
// The int16 stage codes on Cortex-M: numerics.hpp's quantize (VDIV, VCVTR, SSAT #8) stored as int16
// without its cast through int8 (a redundant SXTB after SSAT #8), two values per iteration.
inline std::int16_t quantize_i16(float x, float scale) { return static_cast<std::int16_t>(quantize_code(x, scale)); }
void quantize_all(const float* x, int n, float s, std::int16_t* q) {
  int i = 0;
  for (; i + 2 <= n; i += 2) q[i] = quantize_i16(x[i], s), q[i + 1] = quantize_i16(x[i + 1], s);
  if (i < n) q[i] = quantize_i16(x[i], s);
}
#endif

// The stage products' int32 accumulators of rows [o0, o0 + n): from int8 codes (gemv_i8_any: the
// int16 weight copy when there is one); or, on Cortex-M with FWREF_CNODE_W_INT16, from codes that
// were quantized straight into int16 (no widening pass: fwref/kernels_i8.hpp's gemv_w16_x16).
inline void stage_gemv(const std::int8_t* w, const std::int16_t* w16, int o0, int n, int cols, const std::int8_t* x,
                       std::int32_t* acc) {
  gemv_i8_any(w, w16, o0, n, cols, x, acc);
}
#if defined(FWREF_CNODE_W_INT16) && defined(FWREF_HAS_W16_KERNEL)
constexpr bool kStageX16 = true;
inline void stage_gemv(const std::int8_t*, const std::int16_t* w16, int o0, int n, int cols, const std::int16_t* x,
                       std::int32_t* acc) {
  gemv_w16_x16(w16 + o0 * w16_stride(cols), n, cols, x, acc);
}
#else
constexpr bool kStageX16 = false;
#endif

// lin2 of a stage: linear_i8_tensor's operations (pattern A) on either kind of codes.
// ``mult``: rescale_i32's multipliers f32(s_hidden * s_w[o]), formed once per window (the same
// float32 product as forming them here at every stage).
template <class Q>
void stage_lin2(const CnodeI8& m, const std::int16_t* w16, const Q* q_hid, const float* mult, float* k) {
  const int L = m.dims.latent, H = m.dims.hidden;
  std::int32_t acc[kGemvRowBlock];
  for (int o0 = 0; o0 < L; o0 += kGemvRowBlock) {
    const int o1 = L - o0 < kGemvRowBlock ? L : o0 + kGemvRowBlock;
    stage_gemv(m.lin2_w.q, w16, o0, o1 - o0, H, q_hid, acc);
    rescale_bias_n(acc, mult + o0, m.lin2_b + o0, o1 - o0, k + o0);  // f32(acc) * mult + b, 8 lanes on AVX2
  }
}

// One stage's lin1 fused with the hidden activation: q_hid[o] = quantize(tanh(f32(acc[o]) * f32(s_z *
// s_w[o]) + v[o]), s_hid), the operations of linear_i8_tensor then quantize(tanh_approx(.)) in the
// same order, without a float buffer in between. On Cortex-M, with s_hid = 1/127 (always: the bound
// scale), tanh then quantize is fwref/tanhq.hpp's exact table (a few integer operations instead of
// the rational function and two divisions); elsewhere the direct loop (8 lanes per AVX2 vector on
// the host, fwref/vmath_i8.hpp).
template <class Q>
void lin1_tanh_quantize(const CnodeI8& m, const std::int16_t* w16, const Q* zq, float s_z, const float* v, Q* q_hid) {
  const int H = m.dims.hidden, L = m.dims.latent;
  const float* s_w = m.lin1_z.scale;
  std::int32_t acc[kGemvRowBlock];
  for (int o0 = 0; o0 < H; o0 += kGemvRowBlock) {
    const int o1 = H - o0 < kGemvRowBlock ? H : o0 + kGemvRowBlock;
    stage_gemv(m.lin1_z.q, w16, o0, o1 - o0, L, zq, acc);  // w16: the int16 copy, or null
#if defined(__ARM_FEATURE_SIMD32) && !defined(FWREF_PORTABLE_KERNELS)
    if (m.s_hidden == kTanhqScale) {
      for (int o = o0; o < o1; ++o) q_hid[o] = tanh_quantize_bound(rescale_i32(acc[o - o0], s_z, s_w[o]) + v[o]);
      continue;
    }
#endif
    rescale_tanh_quantize_n(acc, s_z, s_w + o0, v + o0, m.s_hidden, o1 - o0, q_hid + o0);
  }
}

// v[i] = tanh_approx(v[i]): 8 lanes per AVX2 vector on the host, bit-identical (fwref/vmath_f32.hpp).
template <class Vec>
void tanh_inplace(Vec& v) {
  tanh_n(v.data(), static_cast<int>(v.size()));
}

template <class Vec>
void copy_out(const Vec& v, float* out) {
  if (out == nullptr) return;
  for (Eigen::Index i = 0; i < v.size(); ++i) out[i] = v[i];
}

// The matrix shapes a CNODE of either precision must have (same layout, other element type).
template <class Model>
bool shapes_ok(const Model& m) {
  const CnodeDims& d = m.dims;
  return view_ok(m.interp, d.stage_times, d.window) && view_ok(m.encoder_w, d.latent, d.channels) &&
         view_ok(m.lin1_z, d.hidden, d.latent) && view_ok(m.lin1_u, d.hidden, d.channels) &&
         view_ok(m.lin2_w, d.latent, d.hidden) && view_ok(m.head_w, d.classes, d.latent);
}

bool scales_ok(const CnodeF32&) { return true; }

bool scales_ok(const CnodeI8& m) {
  const CnodeDims& d = m.dims;
  return all_positive_finite(m.s_x, d.channels) && all_positive_finite(m.s_u, d.channels) &&
         all_positive_finite(m.s_stage, d.evals()) && all_positive_finite(&m.s_hidden, 1) &&
         all_positive_finite(&m.s_z1, 1);
}

template <class Model>
Status check_any(const Model& m) {
  return detail::check_model(check_dims(m.dims), [&] { return shapes_ok(m); },
                             [&] { return scales_ok(m) ? check_common(m) : Status::kBadWeights; });
}

// V[s] = B(uq[s], lin1_u) + b1 for the rows s in [s0, s1) of U: linear_i8_folded's operations. With the
// int8 kernel avx2field, all S rows in one call on lin1_u's int16 copy (fwref/linear_w16_avx2.hpp). On
// Cortex-M (without an int16 copy of lin1_u) two rows of U per pass over the weights
// (fwref/kernels_i8_x2.hpp), then the same rescale, f32(acc) * s_w' + b, row by row.
void lin1_u_rows(const CnodeI8& m, const std::int16_t* lin1u16, CnodeWorkspace& ws, int s0, int s1) {
  const CnodeDims& d = m.dims;
  const int C = d.channels, H = d.hidden;
#if defined(FWREF_HAS_LINEAR_W16_AVX2)
  // avx2field: the S rows in one call on the int16 copy (fwref/linear_w16_avx2.hpp: the same bits)
  if (s0 == 0 && s1 == d.stage_times && lin1u16 != nullptr && field_w16_avx2_active() &&
      linear_folded_w16_avx2(lin1u16, H, C, ws.uq, s1, m.lin1_u.scale, m.lin1_b, ws.v)) {
    return;
  }
#endif
  int s = s0;
#if defined(FWREF_HAS_I8_X2)
  if (lin1u16 == nullptr) {
    std::int32_t acc_a[kMaxCnodeHidden], acc_b[kMaxCnodeHidden];
    const float* s_w = m.lin1_u.scale;
    for (; s + 2 <= s1; s += 2) {
      gemv_i8_x2(m.lin1_u.q, H, C, ws.uq + s * C, ws.uq + (s + 1) * C, acc_a, acc_b);
      float* va = ws.v + v_slot(s) * H;
      float* vb = ws.v + v_slot(s + 1) * H;
      for (int o = 0; o < H; ++o) {
        va[o] = (static_cast<float>(acc_a[o]) * s_w[o]) + m.lin1_b[o];
        vb[o] = (static_cast<float>(acc_b[o]) * s_w[o]) + m.lin1_b[o];
      }
    }
  }
#endif
  for (; s < s1; ++s) {
    linear_i8_folded(m.lin1_u.q, m.lin1_u.scale, H, C, ws.uq + s * C, m.lin1_b, ws.v + v_slot(s) * H, lin1u16);
  }
}

// The control path: U = interp_q @ quantize(x_norm, s_x[c]) in int32, u = f32(acc) * f32(s_P[s] *
// s_x[c]), quantized per channel with s_u[c] into ws.uq; z0 = tanh(B(uq[0], encoder) + b) (V's rows
// from uq: lin1_u_rows, as VRows asks). x_norm is requantized where a sample feeds two
// rows (the same numbers both times), so no (W, C) buffer is needed. The per-channel work and the
// search for a row's nonzero weights run on AVX2 vectors on the host (fwref/vmath_i8.hpp).
void control_path_i8(const CnodeI8& m, const float* x, const StageWeights16& w16, CnodeWorkspace& ws,
                     CnodeTrace* tr) {
  const CnodeDims& d = m.dims;
  const int C = d.channels, L = d.latent;
  std::int32_t acc[kMaxChannels];
  detail::quantize_stage_controls(m, x, acc, ws, tr);
  ws.z.resize(L);
  bool encoded = false;
  static_cast<void>(w16);  // read only by the host's AVX2 encoder below
#if defined(FWREF_HAS_LINEAR_W16_AVX2)
  encoded = w16.enc != nullptr && field_w16_avx2_active() &&  // avx2field: on the int16 copy, the same bits
            linear_folded_w16_avx2(w16.enc, L, C, ws.uq, 1, m.encoder_w.scale, m.encoder_b, ws.z.data());
#endif
  if (!encoded) linear_i8_folded(m.encoder_w.q, m.encoder_w.scale, L, C, ws.uq, m.encoder_b, ws.z.data());
  tanh_inplace(ws.z);
  if (tr != nullptr) copy_out(ws.z, tr->z0);
}

// The fp32 control path, rows [s0, s1): U row by row, each row straight into V = lin1_u U + b1 (MatMul,
// then Add); row 0 also feeds the encoder (interp's row 0 is sample 0 alone), z0 = tanh(encoder U[0] + b)
// in ws.z. lin1u_t: lin1_u's column-major copy where the fp32 choice is AVX-512F (src/cnode_f32_t.hpp),
// else null.
void control_rows_f32(const CnodeF32& m, const float* x, const float* lin1u_t, CnodeWorkspace& ws, CnodeTrace* tr,
                      int s0, int s1) {
  const CnodeDims& d = m.dims;
  const int C = d.channels, W = d.window, H = d.hidden;
  ws.a.resize(CnodeWorkspace::kURowInA ? C : 0);
  float* const u_row = CnodeWorkspace::kURowInA ? ws.a.data() : ws.u_row;
  for (int s = s0; s < s1; ++s) {
    float* const v = ws.v + v_slot(s) * H;
    interp_row_f32(m.interp.data + s * W, x, m.mean, m.std, W, C, u_row);
    if (tr != nullptr && tr->u != nullptr) {
      for (int c = 0; c < C; ++c) tr->u[s * C + c] = u_row[c];
    }
    const ConstMapVec u(u_row, C);
#if defined(FWREF_HAS_F32_AVX512)
    if (lin1u_t != nullptr) {
      gemv_f32_t_avx512(lin1u_t, H, C, u_row, m.lin1_b, v);
    } else
#endif
      matvec_bias_f32(m.lin1_u, u, m.lin1_b, MapVec(v, H));
    if (s == 0) {
      matvec_bias_f32(m.encoder_w, u, m.encoder_b, ws.z);
      tanh_inplace(ws.z);
    }
  }
  (void)lin1u_t;
}

}  // namespace

Status check(const CnodeF32& m) { return check_any(m); }
Status check(const CnodeI8& m) { return check_any(m); }

Status infer(const CnodeF32& m, const float* x, float* logits, CnodeWorkspace& ws, CnodeTrace* tr) {
  if (x == nullptr || logits == nullptr) return Status::kNullArgument;
  const CnodeDims& d = m.dims;
  const int C = d.channels, W = d.window, H = d.hidden;
  if (!all_finite_n(x, W * C)) return Status::kNonFiniteInput;
  if (tr != nullptr && tr->x_norm != nullptr) trace_x_norm(x, m.mean, m.std, W, C, tr->x_norm);

  int made = 0;  // rows of V made by the AVX-512 path
#if defined(FWREF_HAS_F32_AVX512)
  const detail::F32Copies tc = detail::f32_copies(m, ws);
  // avx2field: the same steps on U's rows in registers and on zero-padded copies (src/cnode_f32_t.hpp)
  if (detail::control_path_avx2(m, tc, x, ws, tr)) made = d.stage_times;
  const float* const lin1u_t = tc.lin1u;
#else
  const float* const lin1u_t = nullptr;
#endif
  VRows rows(ws.v, H, d.stage_times, made,
             [&](int s0, int s1) { control_rows_f32(m, x, lin1u_t, ws, tr, s0, s1); });
  rows.row(0);  // z0 (and, without the ring, every row of V)
  if (tr != nullptr) copy_out(ws.z, tr->z0);

  auto field = [&](int e, const CnodeWorkspace::Lat& z, CnodeWorkspace::Lat& k) {
    const float* const v = rows.row(m.stage_index[e]);  // V[stage_index[e]]
#if defined(FWREF_HAS_F32_AVX512)
    if (tc.lin1z != nullptr) return detail::field_t(m, tc, v, z, ws.a, k);
#endif
    matvec_bias_f32(m.lin1_z, z, v, ws.a);  // + V[stage_index[e]]
    tanh_inplace(ws.a);
    matvec_bias_f32(m.lin2_w, ws.a, m.lin2_b, k);
  };
  detail::rk4_integrate(m.rk4, d.steps, ws.z, ws.k1, ws.k2, ws.k3, ws.k4, ws.state, field,
                        tr != nullptr ? tr->stages : nullptr);
  if (tr != nullptr) copy_out(ws.z, tr->z1);

  MapVec out(logits, d.classes);
  matvec_bias_f32(m.head_w, ws.z, m.head_b, out);
  return all_finite(logits, d.classes) ? Status::kOk : Status::kNonFiniteOutput;
}

Status infer(const CnodeI8& m, const float* x, float* logits, CnodeWorkspace& ws, CnodeTrace* tr) {
  if (x == nullptr || logits == nullptr) return Status::kNullArgument;
#if defined(FWREF_HAS_W8_VNNI)
  // x86-64 with the run-time int8 kernel avx512vnni: every product on the packed int8 copies (src/cnode_w8.cpp)
  if (const GemvW8Fn fn = gemv_w8_kernel()) return detail::infer_i8_w8(m, x, logits, ws, tr, fn);
#endif
  const CnodeDims& d = m.dims;
  const int C = d.channels, W = d.window, H = d.hidden, L = d.latent, K = d.classes;
  if (!all_finite_n(x, W * C)) return Status::kNonFiniteInput;
  if (tr != nullptr && tr->x_norm != nullptr) trace_x_norm(x, m.mean, m.std, W, C, tr->x_norm);

  const StageWeights16 w16 = int16_copies(m, ws);
  control_path_i8(m, x, w16, ws, tr);
  VRows rows(ws.v, H, d.stage_times, 0, [&](int s0, int s1) { lin1_u_rows(m, w16.lin1u, ws, s0, s1); });
  rows.row(0);  // without the ring, every row of V
  // The stage codes: int8, or int16 in uq's RAM (free now, but for the ring's own) with zero padding for
  // the int16 kernel.
#if defined(FWREF_CNODE_W_INT16) && defined(FWREF_HAS_W16_KERNEL)
  std::int16_t* const zq = ws.x16.lat;
  std::int16_t* const hq = ws.x16.hid;
  for (int i = L; i < w16_stride(L); ++i) zq[i] = 0;
  for (int i = H; i < w16_stride(H); ++i) hq[i] = 0;
#else
  std::int8_t* const zq = ws.q_lat;
  std::int8_t* const hq = ws.q_hid;
#endif
  static_assert(kStageX16 == (sizeof *zq == 2), "int16 stage codes only with the int16 kernel");
  float lin2_mult[kMaxLatent];
  for (int o = 0; o < L; ++o) lin2_mult[o] = m.s_hidden * m.lin2_w.scale[o];  // rescale_i32's multiplier
  const detail::Field16 one_call = detail::field16(m, w16.lin1z, w16.lin2, lin2_mult);  // AVX2: avx2field
  auto field = [&](int e, const CnodeWorkspace::Lat& z, CnodeWorkspace::Lat& k) {
    const float s_z = m.s_stage[e];
    k.resize(L);
    const float* const v = rows.row(m.stage_index[e]);
    if (one_call(z.data(), s_z, v, k.data())) return;  // the same steps in one call
    quantize_all(z.data(), L, s_z, zq);
    lin1_tanh_quantize(m, w16.lin1z, zq, s_z, v, hq);
    stage_lin2(m, w16.lin2, hq, lin2_mult, k.data());
  };
  detail::rk4_integrate(m.rk4, d.steps, ws.z, ws.k1, ws.k2, ws.k3, ws.k4, ws.state, field,
                        tr != nullptr ? tr->stages : nullptr);
  if (tr != nullptr) copy_out(ws.z, tr->z1);

  quantize_all(ws.z.data(), L, m.s_z1, ws.q_lat);
  linear_i8_tensor(m.head_w.q, m.head_w.scale, K, L, ws.q_lat, m.s_z1, m.head_b, logits);
  return all_finite(logits, K) ? Status::kOk : Status::kNonFiniteOutput;
}

}  // namespace fwref
