// mcu/scnode_main.cpp -- scope: the streaming CNODE's step (fwref/cnode_step.hpp) on the Cortex-M under QEMU:
// the export's scnode_fw.bin and scnode_fw_i8.bin compiled in (quadfdi.runtimes.mcu_scnode_src, bound in
// place from flash by fwref/scnode_file.hpp), each flight replayed sample by sample from z = 0 (at most
// FWREF_SCNODE_STEPS samples), the instructions of every step counted (SysTick under -icount). Output over
// semihosting, parsed by quadfdi.runtimes.mcu_scnode:
//   SCNODE cpu=<cpu> files=<n> calib_ticks=<t> instructions_per_tick_x1000=<r>
//   STEP <fp32|int8> <t> <instructions> <logit bits (u32) x K>
//   RESULT DONE | RESULT FAIL <what>
#include <cstdint>
#include <cstring>

#include "board.hpp"
#include "fwref/scnode_file.hpp"
#include "fwref_scnode_data.hpp"

#ifndef FWREF_CPU_NAME
#define FWREF_CPU_NAME "unknown"
#endif
#ifndef FWREF_SCNODE_STEPS
#define FWREF_SCNODE_STEPS (1L << 24)
#endif

namespace {

using Line = board::Line<256>;

fwref::ScnodeStepState g_state;
double g_ratio = 0.0;

// One file's flight through the step; false (and a RESULT FAIL line) when it does not bind or a step fails.
bool replay(const unsigned char* data, std::size_t size) {
  fwref::ScnodeFile f;
  const fwref::Status bound = fwref::bind_scnode_file(data, size, &f);
  if (bound != fwref::Status::kOk) {
    Line().s("RESULT FAIL bind ").s(fwref::status_name(bound)).out();
    return false;
  }
  const int C = f.int8 ? f.i8.dims.channels : f.f32.dims.channels;
  const int K = f.int8 ? f.i8.dims.classes : f.f32.dims.classes;
  if (f.int8) fwref::reset(f.i8, g_state); else fwref::reset(f.f32, g_state);
  const long steps = f.samples < FWREF_SCNODE_STEPS ? f.samples : FWREF_SCNODE_STEPS;
  float logits[fwref::kMaxClasses];
  for (long t = 0; t < steps; ++t) {
    const float* x = f.telemetry + t * C;
    const std::uint64_t t0 = board::ticks();
    const fwref::Status st = f.int8 ? fwref::step(f.i8, x, g_state, logits) : fwref::step(f.f32, x, g_state, logits);
    const std::uint64_t ins = std::uint64_t(double(board::ticks() - t0) * g_ratio + 0.5);
    if (st != fwref::Status::kOk) {
      Line().s("RESULT FAIL step ").s(fwref::status_name(st)).out();
      return false;
    }
    Line l;
    l.s("STEP ").s(f.int8 ? "int8 " : "fp32 ").u(std::uint64_t(t)).s(" ").u(ins);
    for (int k = 0; k < K; ++k) {
      std::uint32_t bits;
      std::memcpy(&bits, &logits[k], 4);
      l.s(" ").u(bits);
    }
    l.out();
  }
  return true;
}

}  // namespace

int main() {
  board::ticks_start();
  // SysTick reads 0 until its first reload (mcu/stream_main.cpp): the first line gives it time.
  Line().s("SCNODE-START cpu=").s(FWREF_CPU_NAME).out();
  std::uint64_t loop_ticks = 0;
  g_ratio = board::calibrate(2000000, &loop_ticks);
  Line().s("SCNODE cpu=").s(FWREF_CPU_NAME).s(" files=").u(fwref_scnode_data::kFileCount).s(" calib_ticks=")
      .u(loop_ticks).s(" instructions_per_tick_x1000=").u(std::uint64_t(g_ratio * 1000.0 + 0.5)).out();
  for (int i = 0; i < fwref_scnode_data::kFileCount; ++i) {
    if (!replay(fwref_scnode_data::kFiles[i].data, fwref_scnode_data::kFiles[i].size)) return 2;
  }
  Line().s("RESULT DONE").out();
  return 0;
}
