// tools/fwref_sgru.cpp -- scope: the streaming GRU's one step (fwref/gru_step.hpp) replayed over a
// recorded flight, for tests/test_stream_gru.py to hold it against ONNX Runtime's sgru_step.onnx:
//
//   fwref_sgru IN.bin OUT.f32
//
// IN.bin (export/sgru_run.py, docs/firmware.md "Streaming GRU"), little-endian: the 8 bytes
// "QSGRU1\0\0", int32 C, H, K, T, then float32 mean (C), std (C), w_ih (3H, C), w_hh (3H, H),
// b_ih (3H), b_hh (3H), head_w (K, H), head_b (K), telemetry (T, C) raw samples.
// Or, int8 (sgru_fw_i8.bin): the 8 bytes "QSGRU8\0\0", int32 C, H, K, T, then float32 mean (C), std (C),
// s_x (C), s_h (1), b_ih (3H), b_hh (3H), head_b (K), w_ih scale (3H), w_hh scale (3H), head scale (K),
// telemetry (T, C), then int8 w_ih (3H, C) folded, w_hh (3H, H), head_w (K, H).
// OUT.f32: for every sample, logits (K) then h (H), float32; the stream starts at h = 0.
// IN.bin is a regular file of at most limits::kToolInputBytes whose size its dims give; OUT.f32 is written
// through a temp file, never over IN.bin. Exit 0 on success, 1 with a one-line message otherwise.
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "fwref/gru_step.hpp"
#include "host_common.hpp"
#include "host_files.hpp"

namespace {

int fail(const char* what) { return std::fprintf(stderr, "fwref_sgru: %s\n", what), 1; }

}  // namespace

int main(int argc, char** argv) try {
  if (argc != 3) return fail("usage: fwref_sgru IN.bin OUT.f32");
  std::string error;
  if (!fwref::host::output_allowed(argv[2], {argv[1]}, {"input"}, &error)) return fail(error.c_str());
  std::vector<unsigned char> bytes;
  if (!fwref::host::read_file(argv[1], "input", fwref::limits::kToolInputBytes, &bytes, &error)) {
    return fail(error.c_str());
  }
  char magic[8];
  std::int32_t dims[4];
  if (bytes.size() < 24 || (std::memcmp(bytes.data(), "QSGRU1\0\0", 8) != 0 &&
                            std::memcmp(bytes.data(), "QSGRU8\0\0", 8) != 0)) {
    return fail("not a streaming GRU replay file (magic QSGRU1 or QSGRU8)");
  }
  std::memcpy(magic, bytes.data(), 8);
  std::memcpy(dims, bytes.data() + 8, 16);
  const bool i8 = magic[5] == '8';
  const long C = dims[0], H = dims[1], K = dims[2], T = dims[3];
  if (C <= 0 || H <= 0 || K <= 0 || T <= 0 || C > fwref::kMaxChannels || H > fwref::kMaxGruHidden ||
      K > fwref::kMaxClasses || T > (1L << 24)) {
    return fail("dimensions out of range");
  }
  const long nf = i8 ? 3 * C + 1 + 6 * H + K + 6 * H + K + T * C
                     : 2 * C + 3 * H * C + 3 * H * H + 6 * H + K * H + K + T * C;
  const long nq = i8 ? 3 * H * C + 3 * H * H + K * H : 0;
  if (bytes.size() != 24 + 4 * std::size_t(nf) + std::size_t(nq)) return fail("the file size disagrees with its dimensions");
  if (4 * std::uint64_t(T) * std::uint64_t(K + H) > fwref::limits::kToolInputBytes) {
    return fail("the output (T x (K + H) float32) would exceed limits::kToolInputBytes");
  }
  std::vector<float> buf(static_cast<size_t>(nf));
  std::vector<std::int8_t> qbuf(static_cast<size_t>(nq));
  std::memcpy(buf.data(), bytes.data() + 24, 4 * buf.size());
  std::memcpy(qbuf.data(), bytes.data() + 24 + 4 * buf.size(), qbuf.size());
  const float* p = buf.data();
  auto take = [&p](long count) { const float* q = p; p += count; return q; };
  const std::int8_t* pq = qbuf.data();
  auto takeq = [&pq](long count) { const std::int8_t* q = pq; pq += count; return q; };
  const fwref::GruDims gd{static_cast<int>(C), 1, static_cast<int>(K), static_cast<int>(H)};
  const int h3 = static_cast<int>(3 * H);
  fwref::GruF32 m{};
  fwref::GruI8 q{};
  const float* tel = nullptr;
  if (i8) {
    q.dims = gd;
    q.mean = take(C);
    q.std = take(C);
    q.s_x = take(C);
    q.s_h = *take(1);
    q.b_ih = take(3 * H);
    q.b_hh = take(3 * H);
    q.head_b = take(K);
    q.w_ih = {takeq(3 * H * C), take(3 * H), h3, static_cast<int>(C)};
    q.w_hh = {takeq(3 * H * H), take(3 * H), h3, static_cast<int>(H)};
    q.head_w = {takeq(K * H), take(K), static_cast<int>(K), static_cast<int>(H)};
    tel = take(T * C);
    if (fwref::check(q) != fwref::Status::kOk) return fail("the weights do not pass fwref::check");
  } else {
    m.dims = gd;
    m.mean = take(C);
    m.std = take(C);
    m.w_ih = {take(3 * H * C), h3, static_cast<int>(C)};
    m.w_hh = {take(3 * H * H), h3, static_cast<int>(H)};
    m.b_ih = take(3 * H);
    m.b_hh = take(3 * H);
    m.head_w = {take(K * H), static_cast<int>(K), static_cast<int>(H)};
    m.head_b = take(K);
    tel = take(T * C);
    if (fwref::check(m) != fwref::Status::kOk) return fail("the weights do not pass fwref::check");
  }
  static fwref::GruStepState s;
  if (i8) fwref::reset(q, s); else fwref::reset(m, s);
  std::vector<float> out(static_cast<size_t>(T * (K + H)));
  for (long t = 0; t < T; ++t) {
    float* row = out.data() + t * (K + H);
    const fwref::Status st = i8 ? fwref::step(q, tel + t * C, s, row) : fwref::step(m, tel + t * C, s, row);
    if (st != fwref::Status::kOk) return fail("a step failed (non-finite sample or output)");
    for (long j = 0; j < H; ++j) row[K + j] = s.h[j];
  }
  if (!fwref::host::write_atomic(argv[2], out.data(), out.size() * 4, &error)) return fail(error.c_str());
  return 0;
} catch (const std::exception& e) {
  return fwref::host::fail_exception("fwref_sgru", e);
}
