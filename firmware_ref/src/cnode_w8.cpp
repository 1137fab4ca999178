// src/cnode_w8.cpp -- scope: the host CNODE int8 inference whose products (encoder, lin1_u, lin1_z,
// lin2, head) run on packed int8 copies of the weights with vpdpbusd (fwref/kernels_w8_vnni.hpp), on
// an x86-64 CPU whose run-time int8 kernel is avx512vnni. Every other operation is src/cnode.cpp's
// int8 path's, in its order (fwref/vmath_i8.hpp's helpers, bit-identical to numerics.hpp's scalar
// expressions); the products are exact integers whichever kernel forms them, so the logits and every
// traced tensor are the same bits as FWREF_I8_KERNEL=avx2 or portable give (tests/test_firmware.py).
#include "cnode_w8.hpp"

#if defined(FWREF_HAS_W8_VNNI)

#include "fwref/controls_avx512.hpp"
#include "fwref/field_w8_vnni.hpp"
#include "fwref/numerics.hpp"
#include "fwref/vmath_f32.hpp"
#include "fwref/vmath_i8.hpp"
#include "cnode_controls.hpp"
#include "model_common.hpp"

namespace fwref {
namespace detail {

namespace {

// Accumulators of any product's rows (H, L, K) and of U's channel sums (C).
constexpr int kAccLen = max_of(max_of(kMaxChannels, kMaxClasses), max_of(kMaxLatent, kMaxCnodeHidden));

// The packed copies, made at the first int8 inference of a model (ws.w8_of: which weights, by address).
void w8_copies(const CnodeI8& m, CnodeWorkspace& ws) {
  if (ws.w8_of == m.lin1_z.q) return;
  const CnodeDims& d = m.dims;
  pack_i8_w8(m.encoder_w.q, d.latent, d.channels, ws.enc8);
  pack_i8_w8(m.lin1_u.q, d.hidden, d.channels, ws.lin1u8);
  pack_i8_w8(m.lin1_z.q, d.hidden, d.latent, ws.lin1z8);
  pack_i8_w8(m.lin2_w.q, d.latent, d.hidden, ws.lin2w8);
  pack_i8_w8(m.head_w.q, d.classes, d.latent, ws.head8);
  ws.w8_of = m.lin1_z.q;
}

// acc[r] = sum_c W[r][c] * q[c] for all rows of the copy ``w8`` of a (rows, cols) matrix: the int8 codes
// offset to u8 here (code + 128), the padding up to w8_cols(cols) read against zero weights.
struct W8Product {
  GemvW8Fn fn;
  void operator()(const std::uint8_t* w8, int rows, int cols, const std::int8_t* q, std::int32_t* acc) const {
    gemv_w8_codes(fn, w8, rows, cols, q, acc);
  }
};

// src/cnode.cpp's control_path_i8 with the encoder and lin1_u products on the copies: U's codes row by
// row (control_row_avx512 when C <= 32: the same codes as the helpers of cnode_controls.hpp), z0 = tanh(f32(acc) * s_w' + b) (linear_i8_folded's operations: rescale_bias_n
// with the folded scales as multipliers), V[s] = f32(acc) * s_w' + b1 for every row s.
void control_path_w8(const CnodeI8& m, const float* x, const W8Product& prod, CnodeWorkspace& ws, CnodeTrace* tr) {
  const CnodeDims& d = m.dims;
  const int C = d.channels, S = d.stage_times, L = d.latent, H = d.hidden;
  alignas(64) std::int32_t acc[kAccLen];
  if (C <= 32) {  // U's codes row by row with the channels in registers (fwref/controls_avx512.hpp)
    for (int s = 0; s < S; ++s) {
      float* const u = tr != nullptr && tr->u != nullptr ? tr->u + s * C : nullptr;
      control_row_avx512(m.interp.q + s * d.window, d.window, x, C, m.mean, m.std, m.s_x, m.interp.scale[s], m.s_u, u,
                         ws.uq + s * C);
    }
  } else {
    quantize_stage_controls(m, x, acc, ws, tr);
  }
  ws.z.resize(L);
  prod(ws.enc8, L, C, ws.uq, acc);
  rescale_bias_n(acc, m.encoder_w.scale, m.encoder_b, L, ws.z.data());
  tanh_n(ws.z.data(), L);
  if (tr != nullptr && tr->z0 != nullptr) {
    for (int i = 0; i < L; ++i) tr->z0[i] = ws.z[i];
  }
  for (int s = 0; s < S; ++s) {
    prod(ws.lin1u8, H, C, ws.uq + s * C, acc);
    rescale_bias_n(acc, m.lin1_u.scale, m.lin1_b, H, ws.v + s * H);
  }
}

}  // namespace

Status infer_i8_w8(const CnodeI8& m, const float* x, float* logits, CnodeWorkspace& ws, CnodeTrace* tr, GemvW8Fn fn) {
  const CnodeDims& d = m.dims;
  const int C = d.channels, W = d.window, H = d.hidden, L = d.latent, K = d.classes;
  if (!all_finite_n(x, W * C)) return Status::kNonFiniteInput;
  if (tr != nullptr && tr->x_norm != nullptr) {
    for (int i = 0; i < W * C; ++i) tr->x_norm[i] = normalise(x[i], m.mean[i % C], m.std[i % C]);
  }
  w8_copies(m, ws);
  const W8Product prod{fn};
  control_path_w8(m, x, prod, ws, tr);
  float lin2_mult[kMaxLatent];
  for (int o = 0; o < L; ++o) lin2_mult[o] = m.s_hidden * m.lin2_w.scale[o];  // rescale_i32's multiplier
  alignas(64) std::int32_t acc[kAccLen];
  // One evaluation: the stage's QuantizeLinear, lin1 (all H rows) then rescale + V + tanh + the hidden
  // QuantizeLinear, lin2 (all L rows) then rescale + bias: lin1_tanh_quantize's and stage_lin2's operations.
  const FieldW8 fused{ws.lin1z8, ws.lin2w8, H, L, m.lin1_z.scale, m.s_hidden, lin2_mult, m.lin2_b};
  auto field = [&](int e, const CnodeWorkspace::Lat& z, CnodeWorkspace::Lat& k) {
    const float s_z = m.s_stage[e];
    k.resize(L);
    if (field_w8_avx512vnni(fused, z.data(), s_z, ws.v + m.stage_index[e] * H, k.data())) return;  // H, L <= 64
    quantize_n(z.data(), L, s_z, ws.q_lat);
    prod(ws.lin1z8, H, L, ws.q_lat, acc);
    rescale_tanh_quantize_n(acc, s_z, m.lin1_z.scale, ws.v + m.stage_index[e] * H, m.s_hidden, H, ws.q_hid);
    prod(ws.lin2w8, L, H, ws.q_hid, acc);
    rescale_bias_n(acc, lin2_mult, m.lin2_b, L, k.data());
  };
  rk4_integrate(m.rk4, d.steps, ws.z, ws.k1, ws.k2, ws.k3, ws.k4, ws.state, field, tr != nullptr ? tr->stages : nullptr);
  if (tr != nullptr && tr->z1 != nullptr) {
    for (int i = 0; i < L; ++i) tr->z1[i] = ws.z[i];
  }
  quantize_n(ws.z.data(), L, m.s_z1, ws.q_lat);  // the head: linear_i8_tensor's operations
  prod(ws.head8, K, L, ws.q_lat, acc);
  for (int o = 0; o < K; ++o) logits[o] = rescale_i32(acc[o], m.s_z1, m.head_w.scale[o]) + m.head_b[o];
  return all_finite(logits, K) ? Status::kOk : Status::kNonFiniteOutput;
}

}  // namespace detail
}  // namespace fwref

#endif
