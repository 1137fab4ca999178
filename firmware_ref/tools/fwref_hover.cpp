// tools/fwref_hover.cpp -- scope: runs fwref/hover.hpp over recorded flights for tests/test_hover.py.
//
//   fwref_hover --in FLIGHTS.f32 --samples T --out EST.bin
//
// FLIGHTS.f32: F flights x T samples x 9 little-endian float32 (vz, roll, pitch, thr1..thr4, I_b,
// airborne as 0/1; NaN = no sample), a regular file of at most limits::kToolInputBytes. EST.bin: per
// flight cmd (float32), cur (float32), freeze (int32, -1 = never), the estimate's bits as computed, for a
// bit-for-bit comparison; written through a temp file, and never over --in (the same file under any
// path or hard link is refused before anything is read). Usage error: exit 1; bad input or a failed
// write: one line, exit 2, no output.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "fwref/hover.hpp"
#include "host_common.hpp"
#include "host_files.hpp"

namespace {

const fwref::host::Cli kCli("fwref_hover", "usage: fwref_hover --in FLIGHTS.f32 --samples T --out EST.bin");

}  // namespace

int main(int argc, char** argv) try {
  std::string in, out, samples_text;
  const int parsed = kCli.parse(argc, argv, {{"--in", &in}, {"--out", &out}, {"--samples", &samples_text}});
  if (parsed >= 0) return parsed;
  char* end = nullptr;
  const long long samples = std::strtoll(samples_text.c_str(), &end, 10);
  if (in.empty() || out.empty() || samples_text.empty() || *end != '\0' || samples <= 0 || samples > (1LL << 31)) {
    return kCli.usage_error("--in, --out and --samples (a positive integer) are required");
  }
  std::string error;
  if (!fwref::host::output_allowed(out, {in}, {"--in file"}, &error)) return kCli.fail(error);
  std::vector<unsigned char> bytes;
  if (!fwref::host::read_file(in, "input", fwref::limits::kToolInputBytes, &bytes, &error)) return kCli.fail(error);
  const std::size_t per = std::size_t(samples) * 9 * sizeof(float);
  if (bytes.empty() || bytes.size() % per != 0) {
    return kCli.fail("input " + in + " holds " + std::to_string(bytes.size()) + " bytes, not whole flights of " +
                     samples_text + " samples of 9 float32");
  }
  std::vector<float> data(bytes.size() / sizeof(float));
  std::memcpy(data.data(), bytes.data(), bytes.size());
  std::vector<unsigned char> est;
  for (std::size_t start = 0; start < data.size(); start += per / sizeof(float)) {
    fwref::HoverEstimator<50> h;
    for (long long t = 0; t < samples; ++t) {
      const float* s = &data[start + std::size_t(t) * 9];
      h.push(s[0], s[1], s[2], s + 3, s[7], s[8] != 0.0f);
    }
    const float cmd = h.cmd(), cur = h.cur();
    const std::int32_t fz = h.freeze_index();
    unsigned char row[12];
    std::memcpy(row, &cmd, 4);
    std::memcpy(row + 4, &cur, 4);
    std::memcpy(row + 8, &fz, 4);
    est.insert(est.end(), row, row + sizeof row);
  }
  if (!fwref::host::write_atomic(out, est.data(), est.size(), &error)) return kCli.fail(error);
  return 0;
} catch (const std::exception& e) {
  return fwref::host::fail_exception("fwref_hover", e);
}
