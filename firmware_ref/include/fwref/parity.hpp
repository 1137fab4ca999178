// fwref/parity.hpp -- scope: the parity rule, written once for the host program
// (tools/fwref_parity.cpp) and the microcontroller harness (mcu/parity_main.cpp). The tolerances
// are core/contracts.py's, through the generated fwref/contracts_gen.hpp (parity/compare.py
// imports the same values; docs/firmware.md explains them).
//
// fp32 (against PyTorch in reference.bin): a tensor passes when
//   max |diff| <= kFp32CppRelTol * max(1, max |reference|).
// int8 (against ONNX Runtime's int8 graph): differences are measured in quantisation steps, the
//   scale of the int8 code the tensor is quantized to (x_norm: act.x_norm.scale[c]; u:
//   act.u.scale[c]; a CNODE stage state: act.stage.scale[e]; z1: act.z1.scale; the GRU's h:
//   act.h.scale). A logit is not requantized; its step is the largest change one step of one
//   head input can make, s_in * max_i |W_head[o, i]| = 127 * s_in * s_w[o] (logit_step). A tensor
//   passes when its largest difference is at most kInt8TolSteps steps.
// A NaN anywhere is the largest difference there is.
#pragma once

#include <cmath>

#include "fwref/contracts_gen.hpp"

namespace fwref {

constexpr double kF32RelTol = contracts::kFp32CppRelTol;
constexpr double kI8TolSteps = contracts::kInt8TolSteps;

// Step of logit o of an int8 head with input scale s_in and per-row weight scales s_w.
inline double logit_step(const float* s_w, float s_in, int o) { return 127.0 * double(s_in) * double(s_w[o]); }

// Running comparison of one tensor (over one or many windows) under the parity rule.
struct TensorDiff {
  double max_diff = 0.0, max_ref = 0.0, max_steps = 0.0;

  // ``step`` is the element's quantisation step (int8), 0 for fp32.
  void add(float ours, float want, double step) {
    double d = std::fabs(double(ours) - double(want));
    if (std::isnan(d)) d = INFINITY;
    if (d > max_diff) max_diff = d;
    if (std::fabs(double(want)) > max_ref) max_ref = std::fabs(double(want));
    if (step > 0.0 && d / step > max_steps) max_steps = d / step;
  }

  // fp32: the absolute bound; int8: the bound in steps.
  double tol(bool int8) const { return int8 ? kI8TolSteps : kF32RelTol * (max_ref > 1.0 ? max_ref : 1.0); }
  bool ok(bool int8) const { return int8 ? max_steps <= tol(true) : max_diff <= tol(false); }
};

}  // namespace fwref
