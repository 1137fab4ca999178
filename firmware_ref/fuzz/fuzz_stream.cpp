// fuzz/fuzz_stream.cpp -- scope: fwref_stream's input as hostile bytes, and the on-board loop it feeds.
// An input that starts with the stream magic is a whole stream file, read through a real path (a memfd)
// by host::StreamInput (tools/stream_io.hpp: the bounded header, its check against the on-board record,
// whole samples); any other input is a body of samples behind a valid header made from the record, whose
// time field is a step count (int32, periods) with a sub-period jitter, or, marked, a raw float64 (NaN,
// infinities, 1e300, backwards). The samples run through fwref::Stream with one of three models of the
// fuzz model (fuzz_common.hpp) chosen by the input's size. Invariants: refusals are one line, a push
// reports at most one stride and the sample index never goes back; libFuzzer's -timeout catches a push
// that stalls (filling a long gap sample by sample did).
#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "fuzz_common.hpp"
#include "fwref/onboard.hpp"
#include "fwref/stream.hpp"
#include "host_common.hpp"
#include "host_motor.hpp"
#include "stream_io.hpp"

namespace {

struct Setup {
  fwref::OnboardRecord rec;
  std::unique_ptr<fwref::host::Model> window[2];  // cnode int8, gru fp32
  std::unique_ptr<fwref::host::MotorModel> motor;  // cnode fp32 with its head, when the file has one
  fwref::Stream stream;
};

fwref::Status run_window(void* ctx, const float* window, float* logits) {
  return static_cast<fwref::host::Model*>(ctx)->run(window, logits);
}

fwref::Status run_motor(void* ctx, const float* window, float* logits, float* motor) {
  return static_cast<fwref::host::MotorModel*>(ctx)->run(window, logits, motor);
}

Setup& setup() {
  static Setup* s = [] {
    auto* out = new Setup();
    std::string error;
    fwref::WeightsFile& wf = fuzz::model_file();
    fuzz::require(fwref::read_onboard(wf, &out->rec, &error) == fwref::Status::kOk, "the fuzz model's record", error);
    fwref::Status status;
    out->window[0] = fwref::host::bind_model(wf, "cnode", true, &status, &error);
    out->window[1] = fwref::host::bind_model(wf, "gru", false, &status, &error);
    fuzz::require(out->window[0] && out->window[1], "the fuzz model binds", error);
    if (wf.container().find(fwref::kModelCnodeMotor, fwref::kPrecF32) != nullptr) {
      out->motor = fwref::host::bind_motor_model(wf, "cnode", false, &status, &error);
      fuzz::require(out->motor != nullptr, "the fuzz model's motor head binds", error);
    }
    return out;
  }();
  return *s;
}

// Counts the strides each push reports.
class Count final : public fwref::StrideSink {
 public:
  void on_stride(const fwref::Decision& d) override {
    ++n;
    fuzz::require(d.index >= last, "stride indices never go back");
    last = d.index;
  }
  int n = 0;
  std::int64_t last = -1;
};

// The stream initialised for this input: model by ``pick``, the record's parameters and policy.
bool start(Setup& s, std::size_t pick, std::uint32_t cells) {
  fwref::StreamModel m;
  const int which = int(pick % 3);
  if (which == 2 && s.motor) {
    m.window_motor = run_motor;
    m.ctx = s.motor.get();
  } else {
    m.window = run_window;
    m.ctx = s.window[which == 1 ? 1 : 0].get();
  }
  const fwref::host::Model& bound = which == 1 ? *s.window[1] : *s.window[0];
  fwref::StreamParams p = s.rec.params;
  p.alarm = fwref::policy_for(s.rec, which == 1 ? fwref::kModelGru : fwref::kModelCnode);
  p.classes = p.alarm.classes = bound.classes;
  return s.stream.init(p, int(cells), m) == fwref::Status::kOk;
}

void push(Setup& s, const float* sample, double t, Count& count) {
  const std::int64_t before = s.stream.samples(), strides = count.n;
  s.stream.push(sample, t, &count);
  fuzz::require(count.n - strides <= 1, "a push reports at most one stride");
  fuzz::require(s.stream.samples() >= before, "the sample index never goes back");
}

void from_file(Setup& s, const std::uint8_t* data, std::size_t size) {
  static fuzz::MemFile file;
  fwref::host::StreamInput in;
  std::string error;
  if (!in.open(file.hold(data, size), s.rec, &error)) return fuzz::one_line(error);
  const fwref::host::StreamHeader& h = in.header();
  if (!start(s, size, h.cells)) return;
  std::vector<unsigned char> rec(h.sample_bytes());
  std::vector<float> sample(h.channels);
  Count count;
  for (int got; (got = in.next(rec.data())) == 1;) {
    push(s, sample.data(), fwref::host::decode_sample(rec.data(), h.channels, sample.data()), count);
  }
}

void from_body(Setup& s, const std::uint8_t* data, std::size_t size) {
  const int R = s.rec.params.raw_channels;
  const std::size_t per = 8 + 4 * std::size_t(R);
  if (!start(s, size, 4)) return;
  const double dt = s.rec.params.sample_dt_s;
  std::vector<float> sample(static_cast<std::size_t>(R));
  double t = 0.0;
  Count count;
  for (std::size_t off = 0; off + per <= size; off += per) {
    const std::uint8_t* p = data + off;
    if (p[5] == 0xA5) {
      std::memcpy(&t, p, 8);  // a raw time, whatever it is
    } else {
      std::int32_t steps;
      std::memcpy(&steps, p, 4);
      t += double(steps) * dt + (double(std::int8_t(p[4])) / 256.0) * dt;
    }
    std::memcpy(sample.data(), p + 8, 4 * std::size_t(R));
    push(s, sample.data(), t, count);
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  Setup& s = setup();
  if (size >= 8 && std::memcmp(data, fwref::host::kStreamMagic, 8) == 0) {
    from_file(s, data, size);
  } else {
    from_body(s, data, size);
  }
  return 0;
}
