// src/cnode_f32_t.hpp -- scope: the fp32 CNODE's field on an AVX-512F host, or on an AVX2 + FMA one whose
// fp32 choice is avx2field (src/cnode.cpp's infer): the column-major copies of lin1_z, lin2 (and lin1_u on
// AVX-512F) in the workspace and one evaluation of the field on them (fwref/kernels_f32_avx512.hpp,
// fwref/field_f32_avx2.hpp). Host-only: nothing here exists without FWREF_HAS_F32_AVX512.
#pragma once

#include "fwref/cnode.hpp"
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
// lin1_u keeps the row-major product).
struct F32Copies {
  const float* lin1z = nullptr;
  const float* lin2 = nullptr;
  const float* lin1u = nullptr;
  bool avx512 = false;
};

inline F32Copies f32_copies(const CnodeF32& m, CnodeWorkspace& ws) {
  const bool z512 = gemv_f32_avx512_active();
  if (!z512 && !field_f32_avx2_active()) return {};
  if (ws.t_of != m.lin1_z.data) {
    pack_f32_t(m.lin1_z.data, m.lin1_z.rows, m.lin1_z.cols, ws.lin1z_t);
    pack_f32_t(m.lin2_w.data, m.lin2_w.rows, m.lin2_w.cols, ws.lin2_t);
    pack_f32_t(m.lin1_u.data, m.lin1_u.rows, m.lin1_u.cols, ws.lin1u_t);
    ws.t_of = m.lin1_z.data;
  }
  return {ws.lin1z_t, ws.lin2_t, z512 ? ws.lin1u_t : nullptr, z512};
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
