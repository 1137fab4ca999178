// tools/fwref_scnode.cpp -- scope: the streaming CNODE's one step (fwref/cnode_step.hpp) replayed over a
// recorded flight, for tests/test_stream_cnode.py to hold it against ONNX Runtime's scnode_step graphs:
//
//   fwref_scnode IN.bin OUT.f32
//
// IN.bin: export/scnode_run.py's scnode_fw.bin or scnode_fw_i8.bin, bound by fwref/scnode_file.hpp (its layout).
// OUT.f32: for every sample, logits (K) then z (L), float32; the stream starts at z = 0, its first sample
// held as its own predecessor. Exit 0 on success, 1 with a one-line message otherwise.
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "fwref/cnode_step.hpp"
#include "fwref/scnode_file.hpp"
#include "host_common.hpp"
#include "host_files.hpp"

namespace {

int fail(const char* what) { return std::fprintf(stderr, "fwref_scnode: %s\n", what), 1; }

}  // namespace

int main(int argc, char** argv) try {
  if (argc != 3) return fail("usage: fwref_scnode IN.bin OUT.f32");
  std::string error;
  if (!fwref::host::output_allowed(argv[2], {argv[1]}, {"input"}, &error)) return fail(error.c_str());
  std::vector<unsigned char> bytes;
  if (!fwref::host::read_file(argv[1], "input", fwref::limits::kToolInputBytes, &bytes, &error)) {
    return fail(error.c_str());
  }
  fwref::ScnodeFile file;
  const fwref::Status bound = fwref::bind_scnode_file(bytes.data(), bytes.size(), &file);
  if (bound == fwref::Status::kBadMagic) {
    return fail("not a streaming CNODE replay file (magic QSCNODE): write it with `quadfdi export scnode`");
  }
  if (bound == fwref::Status::kBadVersion) return fail("version is not 1: re-run `quadfdi export scnode`");
  if (bound == fwref::Status::kBadSize) return fail("the file size disagrees with its dimensions");
  if (bound != fwref::Status::kOk) return fail((std::string("bad file: ") + fwref::status_name(bound)).c_str());
  if (file.samples == 0) return fail("the file holds weights only (scnode_weights.bin), no flight to replay");
  const bool i8 = file.int8;
  const long T = file.samples;
  const long C = i8 ? file.i8.dims.channels : file.f32.dims.channels;
  const long K = i8 ? file.i8.dims.classes : file.f32.dims.classes;
  const long L = i8 ? file.i8.dims.latent : file.f32.dims.latent;
  if (4 * std::uint64_t(T) * std::uint64_t(K + L) > fwref::limits::kToolInputBytes) {
    return fail("the output (T x (K + L) float32) would exceed limits::kToolInputBytes");
  }
  const fwref::ScnodeF32& m = file.f32;
  const fwref::ScnodeI8& q = file.i8;
  const float* tel = file.telemetry;
  static fwref::ScnodeStepState s;
  if (i8) fwref::reset(q, s); else fwref::reset(m, s);
  std::vector<float> out(static_cast<size_t>(T * (K + L)));
  for (long t = 0; t < T; ++t) {
    float* row = out.data() + t * (K + L);
    const fwref::Status st = i8 ? fwref::step(q, tel + t * C, s, row) : fwref::step(m, tel + t * C, s, row);
    if (st != fwref::Status::kOk) return fail("a step failed (non-finite sample or output)");
    for (long j = 0; j < L; ++j) row[K + j] = s.z[j];
  }
  if (!fwref::host::write_atomic(argv[2], out.data(), out.size() * 4, &error)) return fail(error.c_str());
  return 0;
} catch (const std::exception& e) {
  return fwref::host::fail_exception("fwref_scnode", e);
}
