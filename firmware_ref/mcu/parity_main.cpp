// mcu/parity_main.cpp -- scope: the QEMU parity harness. It runs the four compiled-in models
// (fwref_weights_*.cpp, generated from weights.bin) on the compiled-in reference windows
// (fwref_reference.cpp, from reference.bin), one at a time, compares every intermediate tensor with
// the reference under the rule of fwref/parity.hpp, measures instructions per inference
// (SysTick under -icount) and peak stack (painting), prints one line per result over semihosting
// and exits QEMU with 0 (all OK), 1 (a tensor NOT OK) or 2 (a model fails its check).
//
// Output lines (parsed by parity/mcu.py):
//   FWREF-MCU cpu=<cpu> windows=<n>
//   CALIB iterations=<n> ticks=<t> instructions_per_tick=<r>
//   TENSOR <model> <precision> <name> maxdiff=<d> tol=<t> [steps=<s>] OK|NOT_OK
//   PERF <model> <precision> window=<k> instructions=<i> stack_bytes=<b>
//   RESULT PASS|FAIL tensors=<n> failed=<f>
#include <cmath>
#include <cstdint>
#include <cstring>

#include "board.hpp"
#include "fwref/cnode.hpp"
#include "fwref/gru.hpp"
#include "fwref/parity.hpp"
#include "fwref_reference.hpp"
#include "fwref_weights.hpp"

#ifndef FWREF_CPU_NAME
#define FWREF_CPU_NAME "unknown"
#endif

namespace {

using fwref::kMaxChannels;
using fwref::kMaxWindow;

using Line = board::Line<256>;

// ---------------------------------------------------------------------------- comparison
int g_checked = 0, g_failed = 0;
double g_instr_per_tick = 0.0;

const fwref_ref::Tensor* find(const char* model, const char* prec, const char* name) {
  for (int i = 0; i < fwref_ref::kTensorCount; ++i) {
    const fwref_ref::Tensor& t = fwref_ref::kTensors[i];
    if (!std::strcmp(t.model, model) && !std::strcmp(t.precision, prec) && !std::strcmp(t.name, name)) return &t;
  }
  return nullptr;
}

// Running comparison of one tensor over the windows (the rule: fwref/parity.hpp).
struct Acc {
  const char* name;
  int per_window;  // elements per window
  fwref::TensorDiff diff;
  bool missing = false;
};

// step(i) of element i within a window (0 for fp32)
template <class StepFn>
void accumulate(Acc& a, const char* model, const char* prec, int window, const float* ours, StepFn step) {
  const fwref_ref::Tensor* t = find(model, prec, a.name);
  if (t == nullptr || t->count != a.per_window * fwref_ref::kWindows) {
    a.missing = true;
    return;
  }
  const float* want = t->data + window * a.per_window;
  for (int i = 0; i < a.per_window; ++i) a.diff.add(ours[i], want[i], step(i));
}

void report(const Acc& a, const char* model, const char* prec, bool int8) {
  Line l;
  l.s("TENSOR ").s(model).s(" ").s(prec).s(" ").s(a.name).s(" ");
  const bool ok = !a.missing && a.diff.ok(int8);
  if (a.missing) {
    l.s("missing-from-reference");
  } else {
    l.s("maxdiff=").e(a.diff.max_diff).s(" tol=").e(a.diff.tol(int8));
    if (int8) l.s(" steps=").f3(a.diff.max_steps);
  }
  l.s(ok ? " OK" : " NOT_OK").out();
  ++g_checked;
  g_failed += ok ? 0 : 1;
}

// One timed inference without trace (instructions, peak stack), printed as a PERF line.
template <class Model, class Workspace>
__attribute__((noinline)) fwref::Status timed(const Model& m, const float* x, float* logits, Workspace& ws,
                                              const char* model, const char* prec, int window) {
  const void* top = board::stack_pointer();
  board::paint_stack(top);
  const std::uint64_t t0 = board::ticks();
  const fwref::Status s = fwref::infer(m, x, logits, ws);
  const std::uint64_t t1 = board::ticks();
  const std::uint32_t stack = board::stack_used(top);
  Line l;
  l.s("PERF ").s(model).s(" ").s(prec).s(" window=").u(window).s(" instructions=")
      .u(std::uint64_t(double(t1 - t0) * g_instr_per_tick + 0.5)).s(" stack_bytes=").u(stack).out();
  return s;
}

// ---------------------------------------------------------------------------- models
fwref::CnodeWorkspace g_cnode_ws;
fwref::GruWorkspace g_gru_ws;
float g_x_norm[kMaxWindow * kMaxChannels];
float g_u[fwref::kMaxStageTimes * kMaxChannels];
float g_z0[fwref::kMaxLatent], g_z1[fwref::kMaxLatent];
float g_stages[fwref::kMaxEvals * fwref::kMaxLatent];
float g_h[kMaxWindow * fwref::kMaxGruHidden];
float g_logits[fwref::kMaxClasses];

// ``q`` is the model itself when it is the int8 one (its scales give the steps), null for fp32.
template <class Model>
bool run_cnode(const Model& m, const char* prec, const fwref::CnodeI8* q) {
  const fwref::CnodeDims& d = m.dims;
  const int C = d.channels, W = d.window, L = d.latent, E = d.evals();
  Acc x_norm{"x_norm", W * C}, u{"u", d.stage_times * C}, z0{"z0", L}, stages{"stages", E * L}, z1{"z1", L},
      logits{"logits", d.classes};
  for (int k = 0; k < fwref_ref::kWindows; ++k) {
    const float* x = fwref_ref::kTelemetry + k * W * C;
    if (timed(m, x, g_logits, g_cnode_ws, "cnode", prec, k) != fwref::Status::kOk) return false;
    fwref::CnodeTrace tr{g_x_norm, g_u, g_z0, g_stages, g_z1};
    if (fwref::infer(m, x, g_logits, g_cnode_ws, &tr) != fwref::Status::kOk) return false;
    accumulate(x_norm, "cnode", prec, k, g_x_norm, [&](int i) { return q ? double(q->s_x[i % C]) : 0.0; });
    accumulate(u, "cnode", prec, k, g_u, [&](int i) { return q ? double(q->s_u[i % C]) : 0.0; });
    accumulate(z0, "cnode", prec, k, g_z0, [&](int) { return q ? double(q->s_stage[0]) : 0.0; });
    accumulate(stages, "cnode", prec, k, g_stages, [&](int i) { return q ? double(q->s_stage[i / L]) : 0.0; });
    accumulate(z1, "cnode", prec, k, g_z1, [&](int) { return q ? double(q->s_z1) : 0.0; });
    accumulate(logits, "cnode", prec, k, g_logits,
               [&](int o) { return q ? fwref::logit_step(q->head_w.scale, q->s_z1, o) : 0.0; });
  }
  for (const Acc* a : {&x_norm, &u, &z0, &stages, &z1, &logits}) report(*a, "cnode", prec, q != nullptr);
  return true;
}

template <class Model>
bool run_gru(const Model& m, const char* prec, const fwref::GruI8* q) {
  const fwref::GruDims& d = m.dims;
  const int C = d.channels, W = d.window, H = d.hidden;
  Acc x_norm{"x_norm", W * C}, h{"h", W * H}, logits{"logits", d.classes};
  for (int k = 0; k < fwref_ref::kWindows; ++k) {
    const float* x = fwref_ref::kTelemetry + k * W * C;
    if (timed(m, x, g_logits, g_gru_ws, "gru", prec, k) != fwref::Status::kOk) return false;
    fwref::GruTrace tr{g_x_norm, g_h};
    if (fwref::infer(m, x, g_logits, g_gru_ws, &tr) != fwref::Status::kOk) return false;
    accumulate(x_norm, "gru", prec, k, g_x_norm, [&](int i) { return q ? double(q->s_x[i % C]) : 0.0; });
    accumulate(h, "gru", prec, k, g_h, [&](int) { return q ? double(q->s_h) : 0.0; });
    accumulate(logits, "gru", prec, k, g_logits,
               [&](int o) { return q ? fwref::logit_step(q->head_w.scale, q->s_h, o) : 0.0; });
  }
  for (const Acc* a : {&x_norm, &h, &logits}) report(*a, "gru", prec, q != nullptr);
  return true;
}

}  // namespace

int main() {
  board::ticks_start();
  Line().s("FWREF-MCU cpu=").s(FWREF_CPU_NAME).s(" windows=").u(fwref_ref::kWindows).out();
  std::uint64_t loop_ticks = 0;
  const std::uint32_t iterations = 2000000;
  g_instr_per_tick = board::calibrate(iterations, &loop_ticks);
  Line().s("CALIB iterations=").u(iterations).s(" ticks=").u(loop_ticks).s(" instructions_per_tick=")
      .f3(g_instr_per_tick).out();

  using namespace fwref_data;
  const fwref::Status checks[4] = {fwref::check(kCnodeF32), fwref::check(kCnodeI8), fwref::check(kGruF32),
                                   fwref::check(kGruI8)};
  for (fwref::Status s : checks) {
    if (s != fwref::Status::kOk) {
      Line().s("RESULT FAIL model check: ").s(fwref::status_name(s)).out();
      return 2;
    }
  }
  const bool ran = run_cnode(kCnodeF32, "fp32", nullptr) && run_cnode(kCnodeI8, "int8", &kCnodeI8) &&
                   run_gru(kGruF32, "fp32", nullptr) && run_gru(kGruI8, "int8", &kGruI8);
  if (!ran) {
    Line().s("RESULT FAIL inference returned an error").out();
    return 2;
  }
  Line().s(g_failed ? "RESULT FAIL" : "RESULT PASS").s(" tensors=").u(g_checked).s(" failed=").u(g_failed).out();
  return g_failed ? 1 : 0;
}
