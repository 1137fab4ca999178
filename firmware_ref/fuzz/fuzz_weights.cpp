// fuzz/fuzz_weights.cpp -- scope: weights.bin (and sgru_weights.bin) as hostile bytes: the container
// parser (fwref/container.hpp), the binder of every section kind (fwref/weights_file.hpp: CNODE, GRU,
// motor heads, streaming GRU, fp32 and int8) and the on-board record reader (fwref/onboard.hpp). Each
// input is parsed as it is and with its CRCs made right (to reach past them); a model that binds runs
// two windows (and the streaming GRU one step), so a binder that lets through a tensor the arithmetic
// cannot use shows as an out-of-bounds read. Refusals must be one line.
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "fuzz_common.hpp"
#include "fwref/gru_step.hpp"
#include "fwref/motor.hpp"
#include "fwref/onboard.hpp"

namespace {

struct Work {
  fwref::CnodeWorkspace cnode;
  fwref::GruWorkspace gru;
  fwref::GruStepState step;
  float window[fwref::kMaxWindow * fwref::kMaxChannels];
  float logits[fwref::kMaxClasses], motor[fwref::kMotors];
};

Work& work() {
  static Work* w = new Work();
  return *w;
}

// Two windows: zeros, then a ramp over the float32 range (finite).
template <class Model, class Workspace>
void run(const Model& m, Workspace& ws) {
  Work& w = work();
  const int n = m.dims.window * m.dims.channels;
  for (int pass = 0; pass < 2; ++pass) {
    for (int i = 0; i < n; ++i) w.window[i] = pass == 0 ? 0.0f : float(i % 17 - 8) * 1e3f;
    fwref::infer(m, w.window, w.logits, ws);
  }
}

template <class Model, class Head, class Workspace>
void bind_all(fwref::WeightsFile& wf, Workspace& ws) {
  std::string error;
  Model m{};
  if (wf.bind(&m, &error) != fwref::Status::kOk) return fuzz::one_line(error);
  run(m, ws);
  Head h{};
  if (wf.bind(&h, &error) != fwref::Status::kOk) return fuzz::one_line(error);
  fwref::infer_motor(m, h, work().window, work().logits, work().motor, ws);
}

template <class Model>
void bind_sgru(fwref::WeightsFile& wf) {
  std::string error;
  Model m{};
  if (wf.bind_sgru(&m, &error) != fwref::Status::kOk) return fuzz::one_line(error);
  Work& w = work();
  fwref::reset(m, w.step);
  for (int i = 0; i < m.dims.channels; ++i) w.window[i] = float(i);
  fwref::step(m, w.window, w.step, w.logits);
}

void parse(std::vector<unsigned char> bytes) {
  fwref::WeightsFile wf;
  std::string error;
  if (wf.load_bytes(std::move(bytes), "fuzz.bin", &error) != fwref::Status::kOk) return fuzz::one_line(error);
  Work& w = work();
  bind_all<fwref::CnodeF32, fwref::CnodeMotorF32>(wf, w.cnode);
  bind_all<fwref::CnodeI8, fwref::CnodeMotorI8>(wf, w.cnode);
  bind_all<fwref::GruF32, fwref::GruMotorF32>(wf, w.gru);
  bind_all<fwref::GruI8, fwref::GruMotorI8>(wf, w.gru);
  bind_sgru<fwref::GruF32>(wf);
  bind_sgru<fwref::GruI8>(wf);
  fwref::OnboardRecord rec;
  if (fwref::read_onboard(wf, &rec, &error) != fwref::Status::kOk) return fuzz::one_line(error);
  for (std::uint32_t model : {fwref::kModelCnode, fwref::kModelGru, fwref::kModelSgru}) {
    const fwref::AlarmParams a = fwref::policy_for(rec, model);
    fuzz::require(a.k >= 1 && a.k <= a.n, "a policy the reader accepted is valid");
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  parse(std::vector<unsigned char>(data, data + size));
  parse(fuzz::with_fixed_crcs(data, size));
  return 0;
}
