// fwref/scnode_file.hpp -- scope: the streaming CNODE's weights-and-flight file (export/scnode_run.py
// ``fw_bytes``, docs/formats.md "scnode_fw.bin") bound in place: the model's views point into the
// caller's buffer (4-byte aligned: a host read into a vector, a const array in flash), nothing copied,
// nothing allocated; every size is checked against the header before anything is read.
//
//   bytes 0-7   "QSCNODE\0"
//   int32 x 8   version (1), precision (1 fp32, 2 int8), C, L, H, K, T (0: weights only), leak (0 or 1)
//   fp32: float32 mean (C), std (C), rk4 (4), lin1_z (H, L), lin1_u (H, C), lin1_b (H), lin2_w (L, H),
//         lin2_b (L), decay (L, with the leak), head_w (K, L), head_b (K), telemetry (T, C)
//   int8: float32 mean, std, rk4, s_x (C), s_z (1), s_hidden (1), lin1_u scale (H), lin1_b (H),
//         lin1_z scale (H), lin2 scale (L), lin2_b (L), decay (L, with the leak), head scale (K), head_b (K),
//         telemetry (T, C); then int8 lin1_u (H, C) folded, lin1_z (H, L), lin2 (L, H), head (K, L)
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>

#include "fwref/cnode_step.hpp"

namespace fwref {

struct ScnodeFile {
  bool int8 = false;
  ScnodeF32 f32{};
  ScnodeI8 i8{};
  const float* telemetry = nullptr;  // (T, C) raw samples; nullptr in a weights-only file (T = 0)
  long samples = 0;                  // T
};

constexpr std::size_t kScnodeFileHeader = 8 + 8 * 4;
constexpr std::int32_t kScnodeFileVersion = 1;

// kBadMagic, kBadVersion, kBadHeader (flags out of range, or a buffer not 4-byte aligned), kDimsInvalid /
// kDimsTooLarge, kBadSize (the bytes disagree with the header); then the model's check().
inline Status bind_scnode_file(const unsigned char* data, std::size_t n, ScnodeFile* out) {
  if (data == nullptr || out == nullptr) return Status::kNullArgument;
  if (n < kScnodeFileHeader || std::memcmp(data, "QSCNODE\0", 8) != 0) return Status::kBadMagic;
  std::int32_t h[8];
  std::memcpy(h, data + 8, sizeof h);
  if (h[0] != kScnodeFileVersion) return Status::kBadVersion;
  if ((h[1] != 1 && h[1] != 2) || (h[7] != 0 && h[7] != 1) || reinterpret_cast<std::uintptr_t>(data) % 4 != 0) {
    return Status::kBadHeader;
  }
  const long C = h[2], L = h[3], H = h[4], K = h[5], T = h[6];
  if (C <= 0 || L <= 0 || H <= 0 || K <= 0 || T < 0) return Status::kDimsInvalid;
  if (C > kMaxChannels || L > kMaxLatent || H > kMaxCnodeHidden || K > kMaxClasses || T > (1L << 24)) {
    return Status::kDimsTooLarge;
  }
  const bool i8 = h[1] == 2;
  const long d = h[7] == 1 ? L : 0;
  const long nf = i8 ? 3 * C + 4 + 2 + 3 * H + 2 * L + d + 2 * K + T * C
                     : 2 * C + 4 + H * L + H * C + H + L * H + L + d + K * L + K + T * C;
  const long nq = i8 ? H * C + H * L + L * H + K * L : 0;
  if (n != kScnodeFileHeader + 4 * std::size_t(nf) + std::size_t(nq)) return Status::kBadSize;
  const float* p = reinterpret_cast<const float*>(data + kScnodeFileHeader);
  auto take = [&p](long count) { const float* q = p; p += count; return q; };
  const std::int8_t* pq = reinterpret_cast<const std::int8_t*>(data + kScnodeFileHeader + 4 * std::size_t(nf));
  auto takeq = [&pq](long count) { const std::int8_t* q = pq; pq += count; return q; };
  const ScnodeDims dims{int(C), int(L), int(H), int(K)};
  out->int8 = i8;
  out->samples = T;
  if (i8) {
    ScnodeI8& q = out->i8;
    q.dims = dims;
    q.mean = take(C);
    q.std = take(C);
    q.rk4 = take(4);
    q.s_x = take(C);
    q.s_z = *take(1);
    q.s_hidden = *take(1);
    const float* s_u = take(H);
    q.lin1_b = take(H);
    const float* s_1 = take(H);
    const float* s_2 = take(L);
    q.lin2_b = take(L);
    q.decay = d ? take(L) : nullptr;
    const float* s_h = take(K);
    q.head_b = take(K);
    out->telemetry = T ? take(T * C) : nullptr;
    q.lin1_u = {takeq(H * C), s_u, int(H), int(C)};
    q.lin1_z = {takeq(H * L), s_1, int(H), int(L)};
    q.lin2_w = {takeq(L * H), s_2, int(L), int(H)};
    q.head_w = {takeq(K * L), s_h, int(K), int(L)};
    return check(q);
  }
  ScnodeF32& m = out->f32;
  m.dims = dims;
  m.mean = take(C);
  m.std = take(C);
  m.rk4 = take(4);
  m.lin1_z = {take(H * L), int(H), int(L)};
  m.lin1_u = {take(H * C), int(H), int(C)};
  m.lin1_b = take(H);
  m.lin2_w = {take(L * H), int(L), int(H)};
  m.lin2_b = take(L);
  m.decay = d ? take(L) : nullptr;
  m.head_w = {take(K * L), int(K), int(L)};
  m.head_b = take(K);
  out->telemetry = T ? take(T * C) : nullptr;
  return check(m);
}

}  // namespace fwref
