// src/motor.cpp -- scope: the motor head's weight checks (fwref/motor.hpp).
#include "fwref/motor.hpp"

#include "model_common.hpp"

namespace fwref {

namespace {

template <class Head>
Status check_head(const Head& m, int max_features) {
  const int F = m.dims.features, M = m.dims.motors;
  if (F <= 0 || M != kMotors) return Status::kDimsInvalid;
  if (F > max_features) return Status::kDimsTooLarge;
  if (!detail::view_ok(m.w, M, F) || m.b == nullptr) return Status::kBadShape;
  return detail::all_finite(m.b, M) ? Status::kOk : Status::kBadWeights;
}

}  // namespace

Status check(const CnodeMotorF32& m) { return check_head(m, kMaxLatent); }
Status check(const CnodeMotorI8& m) { return check_head(m, kMaxLatent); }
Status check(const GruMotorF32& m) { return check_head(m, kMaxGruHidden); }
Status check(const GruMotorI8& m) { return check_head(m, kMaxGruHidden); }

}  // namespace fwref
