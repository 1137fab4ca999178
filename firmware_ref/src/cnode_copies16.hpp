// src/cnode_copies16.hpp -- scope: the int8 CNODE's int16 weight copies in the workspace (fwref/cnode.hpp's
// CnodeWorkspace, FWREF_CNODE_W_INT16 / FWREF_CNODE_U_INT16): made by the first int8 inference of a model
// (src/cnode.cpp), and which of them this build has.
#pragma once

#include <cstdint>

#include "fwref/cnode.hpp"
#include "fwref/kernels_i8.hpp"

namespace fwref {
namespace detail {

// The int16 copies of the weights (null where this build has none), made by the first int8
// inference of a model (ws.w16_of: which weights they are).
struct StageWeights16 {
  const std::int16_t* lin1z = nullptr;
  const std::int16_t* lin2 = nullptr;
  const std::int16_t* lin1u = nullptr;
  const std::int16_t* enc = nullptr;
};

inline StageWeights16 int16_copies(const CnodeI8& m, CnodeWorkspace& ws) {
  StageWeights16 w;
#if defined(FWREF_CNODE_W_INT16) && defined(FWREF_HAS_W16_KERNEL)
  const CnodeDims& d = m.dims;
  if (ws.w16_of != m.lin1_z.q) {
    expand_i8_to_i16(m.lin1_z.q, d.hidden, d.latent, ws.lin1z16);
    expand_i8_to_i16(m.lin2_w.q, d.latent, d.hidden, ws.lin2w16);
#if defined(FWREF_CNODE_U_INT16)
    expand_i8_to_i16(m.lin1_u.q, d.hidden, d.channels, ws.lin1u16);
    expand_i8_to_i16(m.encoder_w.q, d.latent, d.channels, ws.enc16);
#endif
    ws.w16_of = m.lin1_z.q;
  }
  w.lin1z = ws.lin1z16;
  w.lin2 = ws.lin2w16;
#if defined(FWREF_CNODE_U_INT16)
  w.lin1u = ws.lin1u16;
  w.enc = ws.enc16;
#endif
#else
  (void)m, (void)ws;
#endif
  return w;
}

}  // namespace detail
}  // namespace fwref
