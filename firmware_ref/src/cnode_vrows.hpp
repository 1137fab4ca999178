// src/cnode_vrows.hpp -- scope: making the rows of V = lin1_u U + b1 as the integration asks for them
// (fwref/cnode.hpp's kVRing, v_slot, v_fill_end), and the check that a model's stage order can be served.
#pragma once

#include <cstdint>

#include "fwref/cnode.hpp"

#if defined(FWREF_CNODE_V_RING) && \
    (defined(FWREF_HAS_W8_VNNI) || defined(FWREF_HAS_LINEAR_W16_AVX2) || defined(FWREF_HAS_F32_AVX512))
#error "FWREF_CNODE_V_RING is for the portable and Cortex-M paths: the x86-64 kernels make all S rows of V at once"
#endif

namespace fwref {
namespace detail {

// Rows [0, made) of V exist; ``fill(s0, s1)`` makes rows [s0, s1) at ws.v + v_slot(s) * H.
template <class Fill>
class VRows {
 public:
  VRows(float* v, int hidden, int stage_times, int made, Fill fill)
      : v_(v), h_(hidden), s_(stage_times), next_(made), fill_(fill) {}

  // Row s, made first when it is not yet (with the rows v_fill_end adds to it).
  const float* row(int s) {
    if (s >= next_) {
      const int end = v_fill_end(next_, s, s_);
      fill_(next_, end);
      next_ = end;
    }
    return v_ + v_slot(s) * h_;
  }

 private:
  float* v_;
  int h_, s_, next_;
  Fill fill_;
};

// Whether VRows serves the evaluations' stage times in their order: no row asked for after the ring
// dropped it (classic RK4 asks for 2k, 2k+1, 2k+1, 2k+2 in step k: always served).
inline bool v_rows_serve(const std::int32_t* stage_index, int evals, int stage_times) {
  int next = 0;
  for (int e = 0; e < evals; ++e) {
    const int s = stage_index[e];
    if (s >= next) next = v_fill_end(next, s, stage_times);
    if (s < next - kVRows) return false;
  }
  return true;
}

}  // namespace detail
}  // namespace fwref
