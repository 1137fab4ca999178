// fwref/gru.hpp -- scope: the GRU baseline (paper Eq. 11, PyTorch's cell: the reset gate applied
// after the recurrent product, ONNX linear_before_reset=1), fp32 and int8, one window at a time:
//
//   x_norm_t = (x_t - mean) / std
//   gx = W_ih x_norm_t + b_ih,  gh = W_hh h + b_hh          (3H) rows r, z, n
//   r = sigmoid(gx_r + gh_r);  z = sigmoid(gx_z + gh_z)
//   n = tanh(gx_n + gh_n * r); h = (h - n) * z + n          h0 = 0, t = 0 .. W-1
//   logits = head(h_W)
//
// The int8 graph computes GX for all steps with one product; here it is computed step by step
// (the same sums, so the same numbers) so that no (W, 3H) buffer is needed. No allocation during
// inference: every buffer is in the caller's GruWorkspace.
#pragma once

#include <cstdint>

#include "fwref/config.hpp"
#include "fwref/kernels_w8_vnni.hpp"
#include "fwref/linalg.hpp"
#include "fwref/motor.hpp"
#include "fwref/status.hpp"

namespace fwref {

struct GruDims {
  int channels;  // C
  int window;    // W
  int classes;   // K
  int hidden;    // H
};

struct GruF32 {
  GruDims dims;
  const float* mean;    // (C)
  const float* std;     // (C)
  MatF w_ih;            // (3H, C) gate rows r, z, n
  MatF w_hh;            // (3H, H)
  const float* b_ih;    // (3H)
  const float* b_hh;    // (3H)
  MatF head_w;          // (K, H)
  const float* head_b;  // (K)
};

struct GruI8 {
  GruDims dims;
  const float* mean;    // (C)
  const float* std;     // (C)
  MatQ w_ih;            // (3H, C) folded with act.x_norm.scale (pattern B)
  MatQ w_hh;            // (3H, H) pattern A with act.h.scale
  const float* b_ih;    // (3H)
  const float* b_hh;    // (3H)
  MatQ head_w;          // (K, H) pattern A with act.h.scale
  const float* head_b;  // (K)
  const float* s_x;     // (C) act.x_norm.scale
  float s_h;            // act.h.scale (1/127: |h| < 1)
};

struct GruTrace {
  float* x_norm;  // (W, C)
  float* h;       // (W, H): the hidden state after every step
};

struct GruWorkspace {
  using Hid = VecN<kMaxGruHidden>;
  using Gates = VecN<kMaxGruGates>;
  using In = VecN<kMaxChannels>;
  Hid h;
  Gates gx, gh;
  In xn;
  std::int8_t xq[kMaxChannels];
  std::int8_t hq[kMaxGruHidden];
#if defined(FWREF_GRU_WHH_INT16)
  // Option FWREF_GRU_WHH_INT16 (on in firmware_ref/mcu and in the host build): W_hh and W_ih
  // sign-extended to int16 (rows padded to a multiple of 8) and packed for the platform's int16
  // kernel (fwref/kernels_i8.hpp: LDM + SMLAD on Cortex-M, vpmaddwd on x86-64), made by the first
  // int8 inference of a model: 2 * 3H * (pad8(H) + pad8(C)) bytes of RAM for speed. w16_of records
  // which weights they hold BY ADDRESS: a caller that frees a model's weights and loads others at
  // the same address into a workspace it keeps must set w16_of = nullptr first.
  alignas(8) std::int16_t whh16[kMaxGruGates * ((kMaxGruHidden + 7) & ~7)];  // LDRD needs word alignment
  alignas(8) std::int16_t wih16[kMaxGruGates * ((kMaxChannels + 7) & ~7)];
  const std::int8_t* w16_of = nullptr;
#endif
#if defined(FWREF_HAS_W8_VNNI)
  // x86-64 hosts, fp32: the input gates gx = W_ih x_norm_t + b_ih of kGxSteps steps, computed before
  // those steps' recurrent products (src/gru.cpp), so W_ih stays in L1 for the block and only W_hh
  // streams during the recurrence: the same products, so the same bits as one step at a time.
  static constexpr int kGxSteps = 8;
  float gx_block[kGxSteps * kMaxGruGates];
  // x86-64 hosts whose int8 kernel is avx512vnni (chosen at run time, fwref/kernels_i8.hpp): W_ih and
  // W_hh packed for vpdpbusd (fwref/kernels_w8_vnni.hpp), made at the first int8 inference of a
  // model; w8_of: which weights, by address, as w16_of.
  alignas(64) std::uint8_t wih8[w8_bytes(kMaxGruGates, kMaxChannels)];
  alignas(64) std::uint8_t whh8[w8_bytes(kMaxGruGates, kMaxGruHidden)];
  const std::int8_t* w8_of = nullptr;
#endif
};

Status check(const GruF32& m);
Status check(const GruI8& m);

Status infer(const GruF32& m, const float* window, float* logits, GruWorkspace& ws, GruTrace* trace = nullptr);
Status infer(const GruI8& m, const float* window, float* logits, GruWorkspace& ws, GruTrace* trace = nullptr);

}  // namespace fwref

