// mcu/stream_main.cpp -- scope: the streaming runtime (fwref/stream.hpp) on the Cortex-M under
// QEMU: the four compiled-in models (fwref_weights_*.cpp), with their motor heads when the export has
// them (infer_motor), and the streaming GRU when the export has it (fwref_stream_data.cpp,
// quadfdi.runtimes.mcu_stream_src: one step per sample) and the streaming CNODE when it has that (its weights files
// bound in place, fwref/scnode_file.hpp), each replay the compiled-in flights sample by sample
// with reset() between flights, counting instructions per push (SysTick under -icount). Output over
// semihosting, parsed by quadfdi.runtimes.mcu_stream (quadfdi parity), which holds the strides against the host's fwref_stream:
//   STREAM cpu=<cpu> flights=<n> instructions_per_tick=<r>
//   STRIDE <model> <prec> <flight> <index> <status> <logit bits (u32) x K> <vote> <active> <cls> <motor> <wmotor>
//   PERF <model> <prec> <flight> samples=<n> push_n=<n> push_sum=<i> push_max=<i> decide_n=<n> decide_sum=<i>
//        decide_max=<i> other_n=<n> other_sum=<i> other_max=<i>
//   GAP <model> <prec> <flight> <sample> advanced=<n> refused=<0|1> strides=<n> instructions=<i>
//   RESULT DONE
// (push: a push without a stride; decide: a push whose stride ran the model; other: a stride
// without a decision: nohover or skipped. GAP: a push whose timestamp was not the next period -- the
// stream's index advanced by more than one (a gap, or a new clock) or the time was refused -- with its
// instruction count: fwref/stream.hpp bounds it by one decision, tests/test_stream_gaps.py checks it.)
#include <cstdint>
#include <cstring>

#include "board.hpp"
#include "fwref/cnode_step.hpp"
#include "fwref/scnode_file.hpp"
#include "fwref_stream_data.hpp"
#include "fwref_weights.hpp"

#ifndef FWREF_CPU_NAME
#define FWREF_CPU_NAME "unknown"
#endif

namespace {

using Line = board::Line<512>;

// Keeps the strides of one push (at most one: fwref/stream.hpp) so that printing is not timed.
class Keep final : public fwref::StrideSink {
 public:
  void on_stride(const fwref::Decision& d) override {
    if (n < 8) held[n++] = d;
  }
  fwref::Decision held[8];
  int n = 0;
};

struct Stat {
  std::uint64_t n = 0, sum = 0, max = 0;
  void add(std::uint64_t v) { ++n, sum += v, max = v > max ? v : max; }
};

fwref::Stream g_stream;
fwref::CnodeWorkspace g_cnode_ws;
fwref::GruWorkspace g_gru_ws;
fwref::GruStepState g_step;
fwref::ScnodeStepState g_scnode_step;
double g_ratio = 0.0;

// Every flight through the stream with model ``sm``: init() for the first flight, reset() between
// flights (as a flight controller between flights; the cell count is the flight's, so init again
// when it changes).
bool replay(const fwref::StreamModel& sm, const char* model, const char* prec) {
  using namespace fwref_stream_data;
  // the model's own alarm policy (the record's alarm.models row, quadfdi.runtimes.mcu_stream_src), as fwref_stream --model
  const fwref::StreamParams& params = std::strcmp(model, "cnode") == 0 ? kParamsCnode
                                      : std::strcmp(model, "gru") == 0  ? kParamsGru
                                      : std::strcmp(model, "sgru") == 0 ? kParamsSgru
                                                                        : kParamsScnode;
  const int R = params.raw_channels, K = params.classes;
  for (int f = 0; f < kFlightCount; ++f) {
    const Flight& fl = kFlights[f];
    if (f > 0 && fl.cells == kFlights[f - 1].cells) {
      g_stream.reset();
      if (g_stream.set_carried(fl.carried) != fwref::Status::kOk) return false;  // the channels this flight has
    } else if (g_stream.init(params, fl.cells, sm, fl.carried) != fwref::Status::kOk) {
      return false;
    }
    // the flight's vehicle record (its stream file's, compiled in), loaded at reset as fwref_stream does
    if (fl.vehicle == nullptr) {
      g_stream.clear_vehicle();
    } else if (g_stream.set_vehicle(*fl.vehicle) != fwref::Status::kOk) {
      return false;
    }
    Stat push, decide, other;
    for (int k = 0; k < fl.samples; ++k) {
      Keep keep;
      const std::int64_t before = g_stream.samples();
      const std::uint64_t t0 = board::ticks();
      const fwref::Status st = g_stream.push(fl.values + k * R, fl.t[k], &keep);
      const std::uint64_t ins = std::uint64_t(double(board::ticks() - t0) * g_ratio + 0.5);
      const std::int64_t advanced = g_stream.samples() - before;
      if (k > 0 && (advanced != 1 || st != fwref::Status::kOk)) {
        Line().s("GAP ").s(model).s(" ").s(prec).s(" ").u(f).s(" ").u(k).s(" advanced=").u(std::uint64_t(advanced))
            .s(" refused=").u(st != fwref::Status::kOk).s(" strides=").u(keep.n).s(" instructions=").u(ins).out();
      }
      bool decided = false;
      for (int j = 0; j < keep.n; ++j) {
        const fwref::Decision& d = keep.held[j];
        decided = decided || d.status == fwref::StrideStatus::kDecided;
        Line l;
        // the index unsigned: it passes 2^31 after a long gap, and long is 32-bit here
        l.s("STRIDE ").s(model).s(" ").s(prec).s(" ").u(f).s(" ").u(std::uint64_t(d.index)).s(" ")
            .s(fwref::stride_status_name(d.status));
        for (int c = 0; c < K; ++c) {
          std::uint32_t bits;
          std::memcpy(&bits, &d.logits[c], 4);
          l.s(" ").u(bits);
        }
        l.s(" ").u(d.alarm.vote).s(" ").u(d.alarm.active).s(" ").i(d.alarm.cls).s(" ").i(d.alarm.motor).s(" ")
            .i(d.motor).out();
      }
      (keep.n == 0 ? push : decided ? decide : other).add(ins);
    }
    Line().s("PERF ").s(model).s(" ").s(prec).s(" ").u(f).s(" samples=").u(fl.samples).s(" push_n=").u(push.n)
        .s(" push_sum=").u(push.sum).s(" push_max=").u(push.max).s(" decide_n=").u(decide.n).s(" decide_sum=")
        .u(decide.sum).s(" decide_max=").u(decide.max).s(" other_n=").u(other.n).s(" other_sum=").u(other.sum)
        .s(" other_max=").u(other.max).out();
  }
  return true;
}

template <class Model, class Workspace>
bool replay_window(const Model& m, Workspace& ws, const char* model, const char* prec) {
  fwref::WindowRunner<Model, Workspace> runner{&m, &ws};
  fwref::StreamModel sm;
  sm.window = &fwref::WindowRunner<Model, Workspace>::run;
  sm.ctx = &runner;
  return replay(sm, model, prec);
}

template <class Model, class Head, class Workspace>
bool replay_motor(const Model& m, const Head& h, Workspace& ws, const char* model, const char* prec) {
  fwref::WindowMotorRunner<Model, Head, Workspace> runner{&m, &h, &ws};
  fwref::StreamModel sm;
  sm.window_motor = &fwref::WindowMotorRunner<Model, Head, Workspace>::run;
  sm.ctx = &runner;
  return replay(sm, model, prec);
}

template <class Model>
bool replay_step(const Model& m, const char* prec) {
  fwref::StepRunner<Model, fwref::GruStepState> runner{&m, &g_step};
  fwref::StreamModel sm;
  sm.step = &fwref::StepRunner<Model, fwref::GruStepState>::step;
  sm.reset = &fwref::StepRunner<Model, fwref::GruStepState>::reset;
  sm.ctx = &runner;
  return replay(sm, "sgru", prec);
}

#if FWREF_STREAM_HAS_SCNODE
// The streaming CNODE of one precision: its weights file bound in place from flash, one step per sample.
bool replay_scnode(const fwref_stream_data::Blob& blob, const char* prec) {
  static fwref::ScnodeFile f;
  if (fwref::bind_scnode_file(blob.data, blob.size, &f) != fwref::Status::kOk) return false;
  fwref::StreamModel sm;
  if (f.int8) {
    static fwref::StepRunner<fwref::ScnodeI8, fwref::ScnodeStepState> runner{&f.i8, &g_scnode_step};
    sm.step = &fwref::StepRunner<fwref::ScnodeI8, fwref::ScnodeStepState>::step;
    sm.reset = &fwref::StepRunner<fwref::ScnodeI8, fwref::ScnodeStepState>::reset;
    sm.ctx = &runner;
  } else {
    static fwref::StepRunner<fwref::ScnodeF32, fwref::ScnodeStepState> runner{&f.f32, &g_scnode_step};
    sm.step = &fwref::StepRunner<fwref::ScnodeF32, fwref::ScnodeStepState>::step;
    sm.reset = &fwref::StepRunner<fwref::ScnodeF32, fwref::ScnodeStepState>::reset;
    sm.ctx = &runner;
  }
  return replay(sm, "scnode", prec);
}
#endif

bool replay_all() {
  using namespace fwref_data;
  using namespace fwref_stream_data;
#if FWREF_STREAM_HAS_CNODE_MOTOR
  bool ok = replay_motor(kCnodeF32, kCnodeMotorF32, g_cnode_ws, "cnode", "fp32") &&
            replay_motor(kCnodeI8, kCnodeMotorI8, g_cnode_ws, "cnode", "int8");
#else
  bool ok = replay_window(kCnodeF32, g_cnode_ws, "cnode", "fp32") && replay_window(kCnodeI8, g_cnode_ws, "cnode", "int8");
#endif
#if FWREF_STREAM_HAS_GRU_MOTOR
  ok = ok && replay_motor(kGruF32, kGruMotorF32, g_gru_ws, "gru", "fp32") &&
       replay_motor(kGruI8, kGruMotorI8, g_gru_ws, "gru", "int8");
#else
  ok = ok && replay_window(kGruF32, g_gru_ws, "gru", "fp32") && replay_window(kGruI8, g_gru_ws, "gru", "int8");
#endif
#if FWREF_STREAM_HAS_SGRU
  ok = ok && replay_step(kSgruF32, "fp32") && replay_step(kSgruI8, "int8");
#endif
#if FWREF_STREAM_HAS_SCNODE
  ok = ok && replay_scnode(kScnodeF32, "fp32") && replay_scnode(kScnodeI8, "int8");
#endif
  return ok;
}

}  // namespace

int main() {
  board::ticks_start();
  // SysTick's current value reads 0 until its first reload: board::ticks() taken at once after
  // ticks_start() is one reload short (calibrate() then came out negative). The first line gives it time.
  Line().s("STREAM-START cpu=").s(FWREF_CPU_NAME).out();
  std::uint64_t loop_ticks = 0;
  g_ratio = board::calibrate(2000000, &loop_ticks);
  Line l;
  l.s("STREAM cpu=").s(FWREF_CPU_NAME).s(" flights=").u(fwref_stream_data::kFlightCount)
      .s(" calib_ticks=").u(loop_ticks).s(" instructions_per_tick_x1000=").u(std::uint64_t(g_ratio * 1000.0 + 0.5))
      .out();
  const bool ok = replay_all();
  Line().s(ok ? "RESULT DONE" : "RESULT FAIL stream init").out();
  return ok ? 0 : 2;
}
