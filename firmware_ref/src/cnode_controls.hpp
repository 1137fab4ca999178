// src/cnode_controls.hpp -- scope: the int8 CNODE's control samples, shared by the scalar/AVX2 path
// (cnode.cpp control_path_i8) and the packed-VNNI path (cnode_w8.cpp control_path_w8): for every stage
// time s, U[s] = P_q[s] @ x_norm over the nonzero interpolation codes, rescaled and quantized to int8
// (docs/formats.md); the float row goes to the trace when one is asked for.
#pragma once

#include <cstdint>

#include "fwref/cnode.hpp"
#include "fwref/controls_avx2.hpp"
#include "fwref/field_w16_avx2.hpp"
#include "fwref/vmath_i8.hpp"

namespace fwref {
namespace detail {

// ``acc`` holds at least m.dims.channels int32s; writes ws.uq (S, C) and, with a trace, tr->u. Where the
// run-time int8 kernel is avx2field and C <= 32, row by row with the channels in registers
// (fwref/controls_avx2.hpp: the same codes and floats).
inline void quantize_stage_controls(const CnodeI8& m, const float* x, std::int32_t* acc, CnodeWorkspace& ws,
                                    CnodeTrace* tr) {
  const int C = m.dims.channels, W = m.dims.window, S = m.dims.stage_times;
#if defined(FWREF_HAS_CONTROLS_AVX2) && defined(FWREF_HAS_FIELD_W16_AVX2)
  if (C <= 32 && field_w16_avx2_active()) {
    for (int s = 0; s < S; ++s) {
      float* const u = tr != nullptr && tr->u != nullptr ? tr->u + s * C : nullptr;
      control_row_avx2(m.interp.q + s * W, W, x, C, m.mean, m.std, m.s_x, m.interp.scale[s], m.s_u, u, ws.uq + s * C);
    }
    return;
  }
#endif
  for (int s = 0; s < S; ++s) {
    for (int c = 0; c < C; ++c) acc[c] = 0;
    for_each_nonzero(m.interp.q + s * W, W, [&](int w, std::int32_t p) {
      accumulate_codes(x + w * C, m.mean, m.std, m.s_x, C, p, acc);
    });
    float* const u = tr != nullptr && tr->u != nullptr ? tr->u + s * C : nullptr;
    rescale_quantize_row(acc, m.interp.scale[s], m.s_x, m.s_u, C, u, ws.uq + s * C);
  }
}

}  // namespace detail
}  // namespace fwref
