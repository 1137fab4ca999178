// src/cnode_f32_t.hpp -- scope: the fp32 CNODE's field on an AVX-512F host, or on an AVX2 + FMA one whose
// fp32 choice is avx2field (src/cnode.cpp's infer): the column-major copies of lin1_z, lin2 (and lin1_u on
// AVX-512F) in the workspace and one evaluation of the field on them (fwref/kernels_f32_avx512.hpp,
// fwref/field_f32_avx2.hpp); with avx2field also the control path on zero-padded copies of lin1_u and the
// encoder. Host-only: nothing here exists without FWREF_HAS_F32_AVX512.
#pragma once

#include "fwref/cnode.hpp"
#include "fwref/controls_f32_avx2.hpp"
#include "fwref/field_f32_avx2.hpp"
#include "fwref/kernels_f32_avx512.hpp"
#include "fwref/vmath_f32.hpp"

#if defined(FWREF_HAS_F32_AVX512)
#if !defined(FWREF_HAS_F32_FIELD_AVX2)
#error "the AVX-512F copies' build condition is the AVX2 field's (x86-64, AVX2 + FMA, not portable / libm)"
#endif
namespace fwref {
namespace detail {

// The column-major copies of the fp32 field's weights (fwref/kernels_f32_avx512.hpp) when the run-time
// fp32 choice is AVX-512F or the AVX2 field (fwref/field_f32_avx2.hpp), made at the first inference of a
// model (ws.t_of); else all null. On the AVX2 field lin1u stays null (gemv_f32_t_avx512 is AVX-512 code:
// lin1_u keeps the row-major product, on the zero-padded copy ws.lin1u_p made here too: control_path_avx2).
struct F32Copies {
  const float* lin1z = nullptr;
  const float* lin2 = nullptr;
  const float* lin1u = nullptr;
  bool avx512 = false;
};

// dst (rows, (cols + 7) & ~7) row-major = w (rows, cols) with zero columns after the last.
inline void pack_rows_padded(const MatF& w, float* dst) {
  const int cp = (w.cols + 7) & ~7;
  for (int o = 0; o < w.rows; ++o) {
    for (int i = 0; i < cp; ++i) dst[o * cp + i] = i < w.cols ? w.data[o * w.cols + i] : 0.0f;
  }
}

inline F32Copies f32_copies(const CnodeF32& m, CnodeWorkspace& ws) {
  const bool z512 = gemv_f32_avx512_active();
  if (!z512 && !field_f32_avx2_active()) return {};
  if (ws.t_of != m.lin1_z.data) {
    pack_f32_t(m.lin1_z.data, m.lin1_z.rows, m.lin1_z.cols, ws.lin1z_t);
    pack_f32_t(m.lin2_w.data, m.lin2_w.rows, m.lin2_w.cols, ws.lin2_t);
    pack_f32_t(m.lin1_u.data, m.lin1_u.rows, m.lin1_u.cols, ws.lin1u_t);
    pack_rows_padded(m.lin1_u, ws.lin1u_p);
    pack_rows_padded(m.encoder_w, ws.enc_p);
    ws.t_of = m.lin1_z.data;
  }
  return {ws.lin1z_t, ws.lin2_t, z512 ? ws.lin1u_t : nullptr, z512};
}

// The control path where the fp32 choice is the AVX2 field and 8 <= C <= 32 (else false, nothing written):
// U's rows into ws.u_p with zero columns up to cp = C rounded up to 8 (fwref/controls_f32_avx2.hpp: the bits of
// src/cnode.cpp's interp_row_f32), then V[s] = lin1_u U[s] + b1 per row and z0 = tanh(encoder U[0] + b) by
// gemv_f32_fma on the zero-padded copies (ws.lin1u_p, ws.enc_p): whole 8-column packets instead of a masked
// last one. Each padded column adds fma(+0, +0, a_j), exactly what gemv_f32_fma's masked lane adds for the
// unpadded row (cols >= 8: the first packet is a product either way), so V and z0 are the row-major products'
// bits (measured on this AVX2 EPYC: 17 x (64 x 23) 1,070 -> 822 ns; masked loads are slow there). C < 8 keeps
// src/cnode.cpp's path (there the one masked packet starts fma(w, x, +0), not a product as a padded one would).
inline bool control_path_avx2(const CnodeF32& m, const F32Copies& t, const float* x, CnodeWorkspace& ws,
                              CnodeTrace* tr) {
  const CnodeDims& d = m.dims;
  const int C = d.channels, S = d.stage_times, H = d.hidden, cp = (C + 7) & ~7;
  if (t.lin1z == nullptr || t.avx512 || C < 8) return false;
  if (!control_rows_f32_avx2(m.interp.data, S, d.window, x, C, m.mean, m.std, ws.u_p, cp)) return false;  // C > 32
  for (int s = 0; s < S; ++s) {
    if (tr != nullptr && tr->u != nullptr) {
      for (int c = 0; c < C; ++c) tr->u[s * C + c] = ws.u_p[s * cp + c];
    }
    gemv_f32_fma(ws.lin1u_p, H, cp, ws.u_p + s * cp, m.lin1_b, ws.v + s * H);
  }
  ws.z.resize(d.latent);
  gemv_f32_fma(ws.enc_p, d.latent, cp, ws.u_p, m.encoder_b, ws.z.data());
  tanh_n(ws.z.data(), d.latent);
  return true;
}

// One evaluation of the vector field on the copies: a = tanh(lin1_z z + v), k = lin2 a + b2 (the
// operations of the field in src/cnode.cpp's infer, the products in the order of gemv_f32_t_avx512, or of
// field_f32_t_avx2 on an AVX2 host): fused in one call when H and L are at most 64 (the paper's 64 and 40),
// else the three steps (on AVX2 the row-major ones, FWREF_F32_KERNEL=avx2's).
template <class Lat, class Hid>
inline void field_t(const CnodeF32& m, const F32Copies& t, const float* v, const Lat& z, Hid& a, Lat& k) {
  const int H = m.dims.hidden, L = m.dims.latent;
  k.resize(L);
  if (!t.avx512) {
    if (field_f32_t_avx2(t.lin1z, t.lin2, H, L, z.data(), v, m.lin2_b, k.data())) return;  // H, L <= 64
    matvec_bias_f32(m.lin1_z, z, v, a);
    tanh_n(a.data(), H);
    matvec_bias_f32(m.lin2_w, a, m.lin2_b, k);
    return;
  }
  if (field_f32_t_avx512(t.lin1z, t.lin2, H, L, z.data(), v, m.lin2_b, k.data())) return;  // H, L <= 64
  a.resize(H);
  gemv_f32_t_avx512(t.lin1z, H, L, z.data(), v, a.data());
  tanh_n(a.data(), H);
  gemv_f32_t_avx512(t.lin2, L, H, a.data(), m.lin2_b, k.data());
}

}  // namespace detail
}  // namespace fwref
#endif
