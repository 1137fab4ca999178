// src/cnode_field16.hpp -- scope: src/cnode.cpp's hook for the int8 CNODE field in one call on AVX2
// (fwref/field_w16_avx2.hpp): a callable that runs it on the int16 copies when this build has it and the
// run-time int8 kernel is avx2field, and otherwise (any other kernel, shape or build, the Cortex-M one
// included) returns false so that the caller runs its separate steps.
#pragma once

#include <cstdint>

#include "fwref/cnode.hpp"
#include "fwref/field_w16_avx2.hpp"

namespace fwref {
namespace detail {

#if defined(FWREF_HAS_FIELD_W16_AVX2)
struct Field16 {
  FieldW16 f;
  bool on;
  // k = the field at z (L floats) with the stage's V row v; false (nothing written) when not run.
  bool operator()(const float* z, float s_z, const float* v, float* k) const {
    return on && field_w16_avx2(f, z, s_z, v, k);
  }
};
// ``w1``, ``w2``: the int16 copies of lin1_z and lin2 (null: off); ``mult2``: lin2's rescale multipliers.
inline Field16 field16(const CnodeI8& m, const std::int16_t* w1, const std::int16_t* w2, const float* mult2) {
  const FieldW16 f{w1, w2, m.dims.hidden, m.dims.latent, m.lin1_z.scale, m.s_hidden, mult2, m.lin2_b};
  return {f, w1 != nullptr && w2 != nullptr && field_w16_avx2_active()};
}
#else
struct Field16 {
  bool operator()(const float*, float, const float*, float*) const { return false; }
};
inline Field16 field16(const CnodeI8&, const std::int16_t*, const std::int16_t*, const float*) { return {}; }
#endif

}  // namespace detail
}  // namespace fwref
