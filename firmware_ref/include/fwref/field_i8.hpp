// fwref/field_i8.hpp -- scope: the operands of one evaluation of the int8 CNODE's vector field for the kernels
// that run it in one call (fwref/field_w16_avx2.hpp, fwref/field_w8_vnni.hpp): lin1_z and lin2 in the kernel's
// own copy of the weights, whose element type is all that tells the two apart, and the scales and bias.
#pragma once

namespace fwref {

template <class W>
struct FieldI8 {
  const W* lin1z;       // lin1_z (H, L) in the kernel's layout
  const W* lin2w;       // lin2 (L, H) in the kernel's layout
  int hidden;           // H
  int latent;           // L
  const float* s_w1;    // lin1_z's row scales (H)
  float s_hidden;       // the hidden codes' scale
  const float* mult2;   // f32(s_hidden * lin2's row scale) (L): rescale_i32's multipliers
  const float* b2;      // lin2's bias (L)
};

}  // namespace fwref
