// mcu/min_main.cpp -- scope: the minimal image whose size is reported for one model and precision:
// startup, the model's check and one inference on a window buffer, nothing else (no printf, no
// semihosting console, no harness). Built once per model and precision (FWREF_MIN_CNODE_F32,
// FWREF_MIN_CNODE_I8, FWREF_MIN_GRU_F32, FWREF_MIN_GRU_I8) and once as FWREF_MIN_BASELINE, the
// same image without the model: the difference is what the library and its weights cost.
#include <cstdint>

#include "fwref_weights.hpp"

namespace {

// The application's input (e.g. a ring buffer the telemetry driver fills) and output. Present in
// the baseline too, so they cancel out of the difference.
float g_window[fwref::kMaxWindow * fwref::kMaxChannels];
float g_logits[fwref::kMaxClasses];

#if defined(FWREF_MIN_CNODE_F32) || defined(FWREF_MIN_CNODE_I8)
fwref::CnodeWorkspace g_ws;
#elif defined(FWREF_MIN_GRU_F32) || defined(FWREF_MIN_GRU_I8)
fwref::GruWorkspace g_ws;
#endif

}  // namespace

int main() {
  // Keep the buffers: the baseline must hold them like the model images do.
  __asm volatile("" : : "r"(g_window), "r"(g_logits) : "memory");
#if defined(FWREF_MIN_BASELINE)
  return 0;
#else
#if defined(FWREF_MIN_CNODE_F32)
  const auto& m = fwref_data::kCnodeF32;
#elif defined(FWREF_MIN_CNODE_I8)
  const auto& m = fwref_data::kCnodeI8;
#elif defined(FWREF_MIN_GRU_F32)
  const auto& m = fwref_data::kGruF32;
#elif defined(FWREF_MIN_GRU_I8)
  const auto& m = fwref_data::kGruI8;
#else
#error "define one of FWREF_MIN_{CNODE,GRU}_{F32,I8} or FWREF_MIN_BASELINE"
#endif
  if (fwref::check(m) != fwref::Status::kOk) return 2;
  return fwref::infer(m, g_window, g_logits, g_ws) == fwref::Status::kOk ? 0 : 1;
#endif
}
