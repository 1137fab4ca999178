// tools/fwref_scnode.cpp -- scope: the streaming CNODE's one step (fwref/cnode_step.hpp) replayed over a
// recorded flight, for tests/test_stream_cnode.py to hold it against ONNX Runtime's scnode_step graphs:
//
//   fwref_scnode IN.bin OUT.f32
//
// IN.bin (export/scnode_run.py ``fw_bytes``, docs/formats.md "scnode_fw.bin"), little-endian: the 8 bytes
// "QSCNODE\0", int32 version (1), precision (1 fp32, 2 int8), C, L, H, K, T, decay (0 or 1), then
//   fp32: float32 mean (C), std (C), rk4 (4), lin1_z (H, L), lin1_u (H, C), lin1_b (H), lin2_w (L, H),
//         lin2_b (L), decay (L, when decay is 1), head_w (K, L), head_b (K), telemetry (T, C);
//   int8: float32 mean, std, rk4, s_x (C), s_z (1), s_hidden (1), lin1_u scale (H), lin1_b (H), lin1_z scale (H),
//         lin2 scale (L), lin2_b (L), decay (L, when 1), head scale (K), head_b (K), telemetry (T, C), then
//         int8 lin1_u (H, C) folded, lin1_z (H, L), lin2 (L, H), head (K, L).
// OUT.f32: for every sample, logits (K) then z (L), float32; the stream starts at z = 0, its first sample
// held as its own predecessor. Exit 0 on success, 1 with a one-line message otherwise.
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "fwref/cnode_step.hpp"
#include "host_common.hpp"
#include "host_files.hpp"

namespace {

int fail(const char* what) { return std::fprintf(stderr, "fwref_scnode: %s\n", what), 1; }

constexpr std::size_t kHeader = 8 + 8 * 4;

}  // namespace

int main(int argc, char** argv) try {
  if (argc != 3) return fail("usage: fwref_scnode IN.bin OUT.f32");
  std::string error;
  if (!fwref::host::output_allowed(argv[2], {argv[1]}, {"input"}, &error)) return fail(error.c_str());
  std::vector<unsigned char> bytes;
  if (!fwref::host::read_file(argv[1], "input", fwref::limits::kToolInputBytes, &bytes, &error)) {
    return fail(error.c_str());
  }
  if (bytes.size() < kHeader || std::memcmp(bytes.data(), "QSCNODE\0", 8) != 0) {
    return fail("not a streaming CNODE replay file (magic QSCNODE): write it with `quadfdi export scnode`");
  }
  std::int32_t h[8];
  std::memcpy(h, bytes.data() + 8, sizeof h);
  if (h[0] != 1) return fail("version is not 1: re-run `quadfdi export scnode`");
  const bool i8 = h[1] == 2, leak = h[7] == 1;
  const long C = h[2], L = h[3], H = h[4], K = h[5], T = h[6];
  if ((h[1] != 1 && h[1] != 2) || (h[7] != 0 && h[7] != 1)) return fail("precision or decay flag out of range");
  if (C <= 0 || L <= 0 || H <= 0 || K <= 0 || T <= 0 || C > fwref::kMaxChannels || L > fwref::kMaxLatent ||
      H > fwref::kMaxCnodeHidden || K > fwref::kMaxClasses || T > (1L << 24)) {
    return fail("dimensions out of range");
  }
  const long d = leak ? L : 0;
  const long nf = i8 ? 3 * C + 4 + 2 + 2 * H + H + 2 * L + d + 2 * K + T * C
                     : 2 * C + 4 + H * L + H * C + H + L * H + L + d + K * L + K + T * C;
  const long nq = i8 ? H * C + H * L + L * H + K * L : 0;
  if (bytes.size() != kHeader + 4 * std::size_t(nf) + std::size_t(nq)) return fail("the file size disagrees with its dimensions");
  if (4 * std::uint64_t(T) * std::uint64_t(K + L) > fwref::limits::kToolInputBytes) {
    return fail("the output (T x (K + L) float32) would exceed limits::kToolInputBytes");
  }
  std::vector<float> buf(static_cast<size_t>(nf));
  std::vector<std::int8_t> qbuf(static_cast<size_t>(nq));
  std::memcpy(buf.data(), bytes.data() + kHeader, 4 * buf.size());
  std::memcpy(qbuf.data(), bytes.data() + kHeader + 4 * buf.size(), qbuf.size());
  const float* p = buf.data();
  auto take = [&p](long count) { const float* q = p; p += count; return q; };
  const std::int8_t* pq = qbuf.data();
  auto takeq = [&pq](long count) { const std::int8_t* q = pq; pq += count; return q; };
  const fwref::ScnodeDims dims{int(C), int(L), int(H), int(K)};
  fwref::ScnodeF32 m{};
  fwref::ScnodeI8 q{};
  const float* tel = nullptr;
  if (i8) {
    q.dims = dims;
    q.mean = take(C);
    q.std = take(C);
    q.rk4 = take(4);
    q.s_x = take(C);
    q.s_z = *take(1);
    q.s_hidden = *take(1);
    const float* s_u = take(H);
    q.lin1_b = take(H);
    const float* s_z1 = take(H);
    const float* s_2 = take(L);
    q.lin2_b = take(L);
    q.decay = leak ? take(L) : nullptr;
    const float* s_h = take(K);
    q.head_b = take(K);
    tel = take(T * C);
    q.lin1_u = {takeq(H * C), s_u, int(H), int(C)};
    q.lin1_z = {takeq(H * L), s_z1, int(H), int(L)};
    q.lin2_w = {takeq(L * H), s_2, int(L), int(H)};
    q.head_w = {takeq(K * L), s_h, int(K), int(L)};
    if (fwref::check(q) != fwref::Status::kOk) return fail("the weights do not pass fwref::check");
  } else {
    m.dims = dims;
    m.mean = take(C);
    m.std = take(C);
    m.rk4 = take(4);
    m.lin1_z = {take(H * L), int(H), int(L)};
    m.lin1_u = {take(H * C), int(H), int(C)};
    m.lin1_b = take(H);
    m.lin2_w = {take(L * H), int(L), int(H)};
    m.lin2_b = take(L);
    m.decay = leak ? take(L) : nullptr;
    m.head_w = {take(K * L), int(K), int(L)};
    m.head_b = take(K);
    tel = take(T * C);
    if (fwref::check(m) != fwref::Status::kOk) return fail("the weights do not pass fwref::check");
  }
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
