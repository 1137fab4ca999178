// fwref/motor.hpp -- scope: the optional motor head (models.motor; docs/formats.md "weights.bin",
// the motor sections): which of the four rotors a rotor-side fault is on.
//
//   motor_logits (M = 4) = W f + b,   f = what the class head reads (CNODE z1 (L), GRU h_W (H))
//
// int8: f quantized with the class head's activation scale (act.z1.scale / act.h.scale) and one
// int8 product with per-row weight scales (pattern A), the arithmetic of the class head, so the
// result is bit-identical to ONNX Runtime's. Column m is rotor m + 1 (docs/ingest.md, motor
// numbering). The weights are the optional sections "cnode_motor" / "gru_motor" of weights.bin;
// a file without them is a model without the head. Inference: infer_motor below.
#pragma once

#include "fwref/config.hpp"
#include "fwref/linalg.hpp"
#include "fwref/status.hpp"

namespace fwref {

// Net 1 = CNODE, 2 = GRU: distinct types, one weights.bin section each.
template <int Net>
struct MotorDimsT {
  int features;  // F: the CNODE latent L or the GRU hidden H
  int motors;    // M: kMotors
};

template <int Net>
struct MotorF32T {
  MotorDimsT<Net> dims;
  MatF w;         // (M, F)
  const float* b; // (M)
};

template <int Net>
struct MotorI8T {
  MotorDimsT<Net> dims;
  MatQ w;         // (M, F) int8, one scale per row
  const float* b; // (M)
};

using CnodeMotorDims = MotorDimsT<1>;
using CnodeMotorF32 = MotorF32T<1>;
using CnodeMotorI8 = MotorI8T<1>;
using GruMotorDims = MotorDimsT<2>;
using GruMotorF32 = MotorF32T<2>;
using GruMotorI8 = MotorI8T<2>;

// Dimensions (M == kMotors, 0 < F <= the net's maximum), views and values (finite bias, positive
// finite scales, int8 weights in [-127, 127]).
Status check(const CnodeMotorF32& m);
Status check(const CnodeMotorI8& m);
Status check(const GruMotorF32& m);
Status check(const GruMotorI8& m);

// The class logits and, from the same inference, the motor head's ``motor`` (kMotors) logits, on what the
// class head read; kDimsInvalid if the head does not read this model's width. One definition (src/motor.cpp)
// for the (model, head, workspace) triples of fwref/cnode.hpp and fwref/gru.hpp: (CnodeF32, CnodeMotorF32,
// CnodeWorkspace), (CnodeI8, CnodeMotorI8, CnodeWorkspace) and the same for the GRU; another triple does not link.
template <class Model, class Head, class Workspace>
Status infer_motor(const Model& m, const Head& head, const float* window, float* logits, float* motor, Workspace& ws);

}  // namespace fwref
