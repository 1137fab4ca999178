// fwref/parity.hpp -- scope: the parity tolerances, in one place for the host program
// (tools/fwref_parity.cpp), the microcontroller harness (mcu/parity_main.cpp) and the Python
// parity stage (parity/compare.py mirrors them; docs/firmware.md explains them).
//
// fp32 (against PyTorch in reference.bin, against ONNX Runtime in `quadfdi parity`): a tensor
//   passes when max |diff| <= kF32RelTol * max(1, max |reference|). Summation order (Eigen's
//   blocked products against MKL/MLAS sgemm) and the rational tanh/sigmoid (a few ulps from the
//   exact function) give differences near 1e-6 at |value| ~ 1; 1e-4 is two orders above that and
//   far below a logit margin that could move an argmax.
// int8 (against ONNX Runtime's int8 graph): differences are measured in quantisation steps, the
//   scale of the int8 code the tensor is quantized to (x_norm: act.x_norm.scale[c]; u:
//   act.u.scale[c]; a CNODE stage state: act.stage.scale[e]; z1: act.z1.scale; the GRU's h:
//   act.h.scale). A logit is not requantized; its step is the largest change one step of one
//   head input can make, s_in * max_i |W_head[o, i]| = 127 * s_in * s_w[o]. The reference
//   reproduces ONNX Runtime's kernels bit for bit on an x86-64 CPU with FMA3 (identical integer
//   sums: 0 steps, measured on all 1188 paper-scale test windows). kI8TolSteps covers an ONNX
//   Runtime whose tanh/sigmoid round differently by an ulp (another CPU's kernels): such a
//   difference flips a single int8 code now and then, and the GRU carries it through its 80
//   steps. Measured with libm's tanh/exp in place of ORT's (cmake -DFWREF_LIBM_ACTIVATIONS=ON):
//   CNODE 0 steps, GRU up to 5.4 logit steps on 5 of 1188 windows, argmax unchanged.
#pragma once

namespace fwref {

constexpr double kF32RelTol = 1e-4;
constexpr double kI8TolSteps = 8.0;

}  // namespace fwref
