// src/cnode_w8.hpp -- scope: the host CNODE int8 inference on the packed int8 copies for vpdpbusd
// (src/cnode_w8.cpp), which infer(const CnodeI8&) sends every call to when the run-time int8 kernel is
// avx512vnni. Nothing here exists outside x86-64 (FWREF_HAS_W8_VNNI): the Cortex-M build never sees it.
#pragma once

#include "fwref/cnode.hpp"
#include "fwref/kernels_w8_vnni.hpp"

namespace fwref {
namespace detail {

#if defined(FWREF_HAS_W8_VNNI)
// infer(const CnodeI8&)'s operations in its order with every product's int32 accumulators from the
// packed int8 copies (kernel ``fn``, gemv_w8_kernel()); the same integers, so the same logits and trace.
// ``x`` and ``logits`` are not null (infer checked them).
Status infer_i8_w8(const CnodeI8& m, const float* x, float* logits, CnodeWorkspace& ws, CnodeTrace* tr, GemvW8Fn fn);
#endif

}  // namespace detail
}  // namespace fwref
