// fwref/vehicle_record.hpp -- scope: the vehicle record (core/vehicle_record.py: 25 float32 learned from
// the vehicle's own healthy flights) that a reference profile (``flightlog-ref``) reads beside the stream,
// and the per-sample arithmetic of its reference channels. Header-only POD and math, no heap; the host
// loader of a record file (formats/vehicle_record_bin.py) is src/vehicle_record.cpp.
//
// Layout and file constants: fwref/vehicle_record_gen.hpp, generated from core/vehicle_record.py.
// A record with NaN in share_a[0] is no reference (``has_reference``); a field that is NaN holds
// nothing, and the channel reading it takes its fill (fwref/profile.hpp applies the fills). The
// arithmetic, each step one float32 operation in this order (core/vehicle_record.py's contract; the
// build has -ffp-contract=off, so no multiply-add is fused):
//   vf  = min(max(vx_h, v_lo), v_hi)   (vx_h 0 when the flight lacks vel_h)
//   yr  = min(max(r, r_lo), r_hi)      (r 0 when the flight lacks rates)
//   s_k = (share_a[k] + share_v[k] * vf) + share_r[k] * yr;    m{k}_ref = m{k}_rel / s_k
//   vib_ref = vib - (floor + slope * c), c = ((((thr1 + thr2) + thr3) + thr4) * 0.25f)
//   rpm{k}_ref = rpm{k}_rel / rpm_share[k]
//   r_cell_ref = r_cell - sag           (flightlog-phys: fwref/profile.hpp's physics_prep)
// min / max as numpy's minimum / maximum: NaN in either operand gives NaN (std::fmin would drop it).
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>
#include <string>

#include "fwref/channels_gen.hpp"
#include "fwref/status.hpp"
#include "fwref/vehicle_record_gen.hpp"

namespace fwref {

struct VehicleRecord {
  float v[vehicle::kSize];
};
static_assert(sizeof(VehicleRecord) == 4 * vehicle::kSize, "the record is its kSize floats and nothing else");

// Every field NaN: no reference.
inline VehicleRecord no_vehicle() {
  VehicleRecord r;
  for (float& x : r.v) x = NAN;
  return r;
}

inline bool has_reference(const VehicleRecord* r) { return r != nullptr && std::isfinite(r->v[vehicle::kShareA]); }

// numpy's maximum / minimum on float32: NaN propagates from either side.
inline float np_max(float a, float b) { return (a != a || b != b) ? NAN : (a >= b ? a : b); }
inline float np_min(float a, float b) { return (a != a || b != b) ? NAN : (a <= b ? a : b); }

// The reference's expected command share of motor k (0..3) at forward speed vx_h and yaw rate r.
inline float expected_share(const VehicleRecord& rec, int k, float vx_h, float r) {
  const float* f = rec.v;
  const float vf = np_min(np_max(vx_h, f[vehicle::kVRange]), f[vehicle::kVRange + 1]);
  const float yr = np_min(np_max(r, f[vehicle::kRRange]), f[vehicle::kRRange + 1]);
  return (f[vehicle::kShareA + k] + f[vehicle::kShareV + k] * vf) + f[vehicle::kShareR + k] * yr;
}

// The vibration metric above the reference's floor at collective command c; ``field`` kVibFloor or kVibApFloor.
inline float vibration_excess(const VehicleRecord& rec, int field, float vib, float c) {
  return vib - (rec.v[field] + rec.v[field + 1] * c);
}

// Whether the record holds what reference channel j (0..9: m1..4_ref vib_ref vib_ap_ref rpm1..4_ref) reads.
inline bool reference_held(const VehicleRecord& rec, int j) {
  const float* f = rec.v;
  if (j < 4) return std::isfinite(f[vehicle::kShareA + j]);
  if (j == 4) return std::isfinite(f[vehicle::kVibFloor]) && std::isfinite(f[vehicle::kVibFloor + 1]);
  if (j == 5) return std::isfinite(f[vehicle::kVibApFloor]) && std::isfinite(f[vehicle::kVibApFloor + 1]);
  return std::isfinite(f[vehicle::kRpmShare + (j - 6)]);
}

// A record file's bytes (vehicle::kFileBytes: magic, version, profile id, kSize float32 LE; version 1:
// kFileBytesV1, kSizeV1 floats, kSag NaN) for profile ``expect``; kOk, or a Status with ``*why`` the reason
// (no heap: the Cortex-M may parse one too). An infinite field is refused (NaN is "holds nothing").
inline Status parse_vehicle_record(const unsigned char* bytes, std::size_t n, Profile expect, VehicleRecord* out,
                                   const char** why) {
  std::uint32_t version = 0, profile = 0;
  if (n < 8 || std::memcmp(bytes, vehicle::kFileMagic, 8) != 0) return *why = "is not a quadfdi vehicle record", Status::kBadMagic;
  if (n >= 12) std::memcpy(&version, bytes + 8, 4);
  const bool v1 = version == vehicle::kFileVersionV1;
  if (n != std::size_t(v1 ? vehicle::kFileBytesV1 : vehicle::kFileBytes)) {
    return *why = v1 ? "is not 112 bytes long (a version 1 record: truncated or with trailing bytes)"
                     : "is not 116 bytes long (truncated or with trailing bytes)", Status::kBadSize;
  }
  std::memcpy(&profile, bytes + 12, 4);
  if (!v1 && version != vehicle::kFileVersion) {
    return *why = "has a format version this reader does not read (it reads 1 and 2)", Status::kBadVersion;
  }
  if (profile != static_cast<std::uint32_t>(expect)) return *why = "is for another profile than the model's", Status::kDimsInvalid;
  VehicleRecord r = no_vehicle();  // a version 1 record: the fields after kSizeV1 NaN (it holds none)
  std::memcpy(r.v, bytes + vehicle::kFileHeaderBytes, 4 * std::size_t(v1 ? vehicle::kSizeV1 : vehicle::kSize));
  for (float x : r.v) {
    if (std::isinf(x)) return *why = "holds an infinite field", Status::kBadInput;
  }
  *out = r;
  return Status::kOk;
}

// Host: read and parse the record file ``path`` for profile ``expect`` (fwref/file_read.hpp's bounded open:
// a regular file of at most vehicle::kFileBytes, read into a fixed buffer); one line in ``*error``.
Status load_vehicle_record(const std::string& path, Profile expect, VehicleRecord* out, std::string* error);

}  // namespace fwref
