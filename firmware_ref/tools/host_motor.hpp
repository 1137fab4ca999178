// tools/host_motor.hpp -- scope: a net with its motor head (fwref/motor.hpp) behind one interface
// for the host programs: class logits and motor logits from one inference.
#pragma once

#include <memory>
#include <string>

#include "host_common.hpp"

namespace fwref {
namespace host {

class MotorModel {
 public:
  virtual ~MotorModel() = default;
  virtual Status run(const float* window, float* logits, float* motor) = 0;
};

template <class M, class H, class Workspace>
class BoundMotorModel final : public MotorModel {
 public:
  BoundMotorModel(const M& m, const H& h) : m_(m), h_(h), ws_(new Workspace()) {}
  Status run(const float* x, float* logits, float* motor) override {
    NoHeapGuard guard;
    return infer_motor(m_, h_, x, logits, motor, *ws_);
  }

 private:
  M m_;
  H h_;
  std::unique_ptr<Workspace> ws_;
};

template <class M, class H, class Workspace>
std::unique_ptr<MotorModel> bind_pair(WeightsFile& wf, Status* status, std::string* error) {
  M m{};
  H h{};
  if ((*status = wf.bind(&m, error)) != Status::kOk) return nullptr;
  if ((*status = wf.bind(&h, error)) != Status::kOk) {
    if (*status == Status::kMissingSection) *error += " (the model has no motor head)";
    return nullptr;
  }
  return std::unique_ptr<MotorModel>(new BoundMotorModel<M, H, Workspace>(m, h));
}

// Bind (model, precision) and its motor-head section; null with ``*error`` set on failure.
inline std::unique_ptr<MotorModel> bind_motor_model(WeightsFile& wf, const std::string& kind, bool int8,
                                                    Status* status, std::string* error) {
  if (kind == "cnode") {
    return int8 ? bind_pair<CnodeI8, CnodeMotorI8, CnodeWorkspace>(wf, status, error)
                : bind_pair<CnodeF32, CnodeMotorF32, CnodeWorkspace>(wf, status, error);
  }
  return int8 ? bind_pair<GruI8, GruMotorI8, GruWorkspace>(wf, status, error)
              : bind_pair<GruF32, GruMotorF32, GruWorkspace>(wf, status, error);
}

}  // namespace host
}  // namespace fwref
