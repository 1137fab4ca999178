// fuzz/fuzz_windows.cpp -- scope: the windows file of fwref_infer / fwref_pair (host::read_windows: raw
// float32 (n, W, C), a whole number of windows, every value finite) as hostile bytes, read through a real
// path (a memfd), then the first windows it accepts run through the four models of the fuzz model
// (fuzz_common.hpp) as fwref_infer runs them: any finite float32, however large, must give a Status, never
// an out-of-bounds access or undefined behaviour (the int8 paths' quantization clamps included).
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "fuzz_common.hpp"
#include "host_common.hpp"

namespace {

struct Models {
  std::unique_ptr<fwref::host::Model> m[4];  // cnode fp32, cnode int8, gru fp32, gru int8
};

Models& models() {
  static Models* ms = [] {
    auto* out = new Models();
    fwref::Status status;
    std::string error;
    for (int i = 0; i < 4; ++i) {
      out->m[i] = fwref::host::bind_model(fuzz::model_file(), i < 2 ? "cnode" : "gru", i % 2 == 1, &status, &error);
      fuzz::require(out->m[i] != nullptr, "the fuzz model binds", error);
    }
    return out;
  }();
  return *ms;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static fuzz::MemFile file;
  Models& ms = models();
  const std::string path = file.hold(data, size);
  std::vector<float> x;
  std::string error;
  // the models' own (W, C), as fwref_infer reads it
  if (!fwref::host::read_windows(path, ms.m[0]->window, ms.m[0]->channels, &x, &error)) {
    fuzz::one_line(error);
  } else {
    const std::size_t per = std::size_t(ms.m[0]->window) * ms.m[0]->channels;
    fuzz::require(x.size() % per == 0 && !x.empty(), "whole windows", path);
    float logits[fwref::kMaxClasses];
    for (std::size_t k = 0; k < x.size() / per && k < 3; ++k) {
      for (auto& m : ms.m) m->run(&x[k * per], logits);
    }
  }
  // another (W, C) from the first two bytes: the size checks on shapes the models do not have
  if (size >= 2) {
    const int w = 1 + data[0] % 64, c = 1 + data[1] % 32;
    if (!fwref::host::read_windows(path, w, c, &x, &error)) fuzz::one_line(error);
    else fuzz::require(x.size() % (std::size_t(w) * c) == 0, "whole windows", path);
  }
  return 0;
}
