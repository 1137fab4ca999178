// fuzz/fuzz_reference.cpp -- scope: reference.bin as hostile bytes: the container parser with the reference
// magic and version (fwref/container.hpp), every tensor's values, scales and zero points copied out as
// fwref_parity reads them, and fwref_parity's lookup of the (n, W, C) telemetry inputs and of each model
// section's dims. Each input as it is and with its CRCs made right. Refusals must be one line.
#include <cstdint>
#include <string>
#include <vector>

#include "fuzz_common.hpp"
#include "fwref/weights_layout_gen.hpp"

namespace {

void parse(std::vector<unsigned char> bytes) {
  fwref::Container ref;
  std::string error;
  if (ref.parse_bytes(std::move(bytes), "fuzz.bin", fwref::layout::kReferenceMagic, fwref::layout::kReferenceVersion,
                      "reference file", &error) != fwref::Status::kOk) {
    return fuzz::one_line(error);
  }
  std::vector<unsigned char> scratch;
  for (const fwref::SectionInfo& sec : ref.sections()) {
    for (const fwref::TensorInfo& t : sec.tensors) {
      fuzz::require(t.data_offset + t.count * (t.dtype == fwref::DType::kI8 ? 1 : 4) <= ref.bytes().size(),
                    "a tensor's data lies inside the file", t.name);
      scratch.resize(t.count * 4 + 4);
      if (t.dtype == fwref::DType::kF32) ref.copy_f32(t, reinterpret_cast<float*>(scratch.data()));
      if (t.dtype == fwref::DType::kI32) ref.copy_i32(t, reinterpret_cast<std::int32_t*>(scratch.data()));
      if (t.dtype == fwref::DType::kI8) ref.copy_i8(t, reinterpret_cast<std::int8_t*>(scratch.data()));
      std::vector<float> scales(std::size_t(t.n_scales) + 1);
      ref.copy_scales(t, scales.data());
      for (int i = 0; i < t.n_scales; ++i) ref.zero_point(t, i);
    }
  }
  // fwref_parity: the inputs section's float32 (n, W, C) telemetry, and each model section's (W, C) the same
  const fwref::SectionInfo* inputs = ref.find(fwref::kModelNone, fwref::kPrecNone);
  const fwref::TensorInfo* tel = inputs ? inputs->find("telemetry") : nullptr;
  if (tel == nullptr || tel->dtype != fwref::DType::kF32 || tel->ndim != 3) return;
  for (const fwref::SectionInfo& sec : ref.sections()) {
    if (sec.model == fwref::kModelNone) continue;
    if (sec.dims[1] != std::uint32_t(tel->shape[1]) || sec.dims[0] != std::uint32_t(tel->shape[2])) return;
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  parse(std::vector<unsigned char>(data, data + size));
  parse(fuzz::with_fixed_crcs(data, size));
  return 0;
}
