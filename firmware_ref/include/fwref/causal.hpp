// fwref/causal.hpp -- scope: the causal physics channels' recursions (core/causal.py), one sample at a
// time, float32 in Python's order of operations (no fused multiply-add: the build's -ffp-contract=off).
// Header-only, no heap. The constants (kAlpha, kBeta, kFloor2) come from fwref/causal_gen.hpp, generated
// from core/causal.py.
//
// Each recursion starts at the first sample whose input is finite; a sample whose input is not finite
// leaves the state as it was and gives NaN (its windows are undecided anyway). The stream keeps one
// PhysState per flight (fwref/stream.hpp: reset() starts it again; a gap's missing samples hold it).
//   ewma:  m <- x (first), then m <- m + kAlpha * (x - m)
//   sag:   dv = v - mv, di = i - mi; mv <- mv + kAlpha * dv; mi <- mi + kAlpha * di;
//          cvi <- kBeta * (cvi + (kAlpha * dv) * di); cii <- kBeta * (cii + (kAlpha * di) * di);
//          r = -cvi / (cii + kFloor2)   (first sample: mv = v, mi = i, cvi = cii = 0)
#pragma once

#include <cmath>

#include "fwref/causal_gen.hpp"

namespace fwref {

struct EwmaState {
  float m = 0.0f;
  bool started = false;
};

struct SagState {
  float mv = 0.0f, mi = 0.0f, cvi = 0.0f, cii = 0.0f;
  bool started = false;
};

// A physics profile's per-flight state: the sag and the six smoothed deviations (m1..4_ref, vib_ref, vib_ap_ref).
struct PhysState {
  SagState sag;
  EwmaState lp[6];
  void reset() { *this = PhysState(); }
};

inline float ewma_step(EwmaState& s, float x) {
  if (!std::isfinite(x)) return NAN;
  if (s.started) {
    s.m = s.m + causal::kAlpha * (x - s.m);
  } else {
    s.m = x;
    s.started = true;
  }
  return s.m;
}

// The sag per ampere per cell (ohm) after per-cell voltage v (V) and pack current i (A).
inline float sag_step(SagState& s, float v, float i) {
  if (!(std::isfinite(v) && std::isfinite(i))) return NAN;
  if (s.started) {
    const float dv = v - s.mv, di = i - s.mi;
    s.mv = s.mv + causal::kAlpha * dv;
    s.mi = s.mi + causal::kAlpha * di;
    s.cvi = causal::kBeta * (s.cvi + (causal::kAlpha * dv) * di);
    s.cii = causal::kBeta * (s.cii + (causal::kAlpha * di) * di);
  } else {
    s.mv = v;
    s.mi = i;
    s.cvi = 0.0f;
    s.cii = 0.0f;
    s.started = true;
  }
  return -s.cvi / (s.cii + causal::kFloor2);
}

}  // namespace fwref
