// tools/stream_file.hpp -- scope: the stream file's header (docs/formats.md "Stream file", written by
// formats/stream.py) parsed from bytes and checked against weights.bin's on-board record: what
// fwref_stream reads before the first sample, and what fuzz/fuzz_stream.cpp feeds hostile bytes to.
// Every size is bounded (fwref/read_limits.hpp) before anything is allocated; every failure is one line.
//
//   0  char[8] magic "QFDISTR\0" | 8 u32 version 4, 3, 2 or 1 | 12 u32 header_bytes | 16 u32 n_channels R
//   20 u32 cells | 24 f64 sample_dt_s | 32 char[32] profile | 64 char[64] source | 128 R NUL-terminated
//   names, then (version >= 2) R carried flags u8 (1: the stream carries the channel, 0: the flight lacks it),
//   then (version 4) the vehicle record, 25 f32 (version 3: 24, kSag NaN; fwref/vehicle_record.hpp; a reference
//   profile only),
//   padding; then samples of 8 + 4R bytes: f64 t, f32 values[R]. Version 1 carries every channel.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "fwref/onboard.hpp"
#include "fwref/read_limits.hpp"
#include "fwref/vehicle_record.hpp"

namespace fwref {
namespace host {

constexpr char kStreamMagic[9] = "QFDISTR";  // + NUL: 8 bytes
constexpr std::uint32_t kStreamVersion = 4;  // 3 (a version 1 record), 2 (no record), 1 (every channel carried) too
constexpr std::size_t kStreamFixedHeader = 128;  // magic .. source; the channel names follow

struct StreamHeader {
  std::uint32_t channels = 0, cells = 0, bytes = 0;  // bytes: header_bytes, where the samples begin
  double dt = 0.0;
  std::string profile, source;
  std::vector<std::string> names;
  std::uint32_t version = 0;
  std::uint64_t carried = kAllCarried;  // bit c: the stream carries channel c (version 2's flags; c < 64)
  bool has_vehicle = false;             // version >= 3: the stream carries its vehicle record
  VehicleRecord vehicle{};
  std::size_t sample_bytes() const { return 8 + 4 * std::size_t(channels); }
};

// The fixed 128 bytes: magic, version, and header_bytes and n_channels within their maxima.
inline bool parse_stream_fixed(const unsigned char* fixed, const std::string& where, StreamHeader* h,
                               std::string* error) {
  if (std::memcmp(fixed, kStreamMagic, 8) != 0) return *error = "stream " + where + " is not a quadfdi stream file", false;
  std::uint32_t& version = h->version;
  std::memcpy(&version, fixed + 8, 4);
  std::memcpy(&h->bytes, fixed + 12, 4);
  std::memcpy(&h->channels, fixed + 16, 4);
  std::memcpy(&h->cells, fixed + 20, 4);
  std::memcpy(&h->dt, fixed + 24, 8);
  if (version < 1 || version > kStreamVersion) {
    return *error = "stream " + where + " has version " + std::to_string(version) + ", this reader reads 1 to " +
                    std::to_string(kStreamVersion), false;
  }
  if (h->bytes < kStreamFixedHeader || h->bytes > limits::kStreamHeaderBytes || h->channels == 0 ||
      h->channels > limits::kStreamChannels || h->bytes - kStreamFixedHeader < std::size_t(h->channels)) {
    char buf[256];
    std::snprintf(buf, sizeof buf, "has a bad header: header_bytes %u (128..%u) and %u channels (1..%u, each name at "
                  "least its NUL)", h->bytes, limits::kStreamHeaderBytes, h->channels, limits::kStreamChannels);
    return *error = "stream " + where + " " + buf, false;
  }
  h->profile.assign(reinterpret_cast<const char*>(fixed + 32), strnlen(reinterpret_cast<const char*>(fixed + 32), 32));
  h->source.assign(reinterpret_cast<const char*>(fixed + 64), strnlen(reinterpret_cast<const char*>(fixed + 64), 64));
  for (char& c : h->source) {
    if (static_cast<unsigned char>(c) < 32 || c == 127) c = '?';  // it goes into an output line
  }
  return true;
}

// The channel names: the header_bytes - 128 bytes after the fixed header.
inline bool parse_stream_names(const char* rest, std::size_t n, const std::string& where, StreamHeader* h,
                               std::string* error) {
  h->names.clear();
  std::size_t pos = 0;
  for (std::uint32_t c = 0; c < h->channels; ++c) {
    const std::size_t len = strnlen(rest + pos, n - pos);
    if (pos + len >= n) return *error = "stream " + where + " has unterminated channel names", false;
    h->names.emplace_back(rest + pos, len);
    pos += len + 1;
  }
  h->carried = kAllCarried;
  if (h->version < 2) return true;
  if (h->channels > 64 || n - pos < h->channels) {  // one flag per channel after the names
    return *error = "stream " + where + " has no room for its carried flags, or more than 64 channels", false;
  }
  for (std::uint32_t c = 0; c < h->channels; ++c) {
    const unsigned char flag = static_cast<unsigned char>(rest[pos + c]);
    if (flag > 1) return *error = "stream " + where + " has a carried flag that is not 0 or 1", false;
    if (flag == 0) h->carried &= ~(std::uint64_t(1) << c);
  }
  h->has_vehicle = false;
  if (h->version < 3) return true;
  pos += h->channels;
  const std::size_t floats = h->version >= 4 ? vehicle::kSize : vehicle::kSizeV1;
  if (n - pos < 4 * floats) return *error = "stream " + where + " has no room for its vehicle record", false;
  h->vehicle = no_vehicle();  // version 3: the fields a version 1 record lacks stay NaN
  std::memcpy(h->vehicle.v, rest + pos, 4 * floats);
  for (float x : h->vehicle.v) {
    if (std::isinf(x)) return *error = "stream " + where + " has an infinite field in its vehicle record", false;
  }
  h->has_vehicle = true;
  return true;
}

// The channels the header marks not carried, comma-separated.
inline std::string stream_lacking(const StreamHeader& h) {
  std::string out;
  for (std::size_t c = 0; c < h.names.size() && c < 64; ++c) {
    if (((h.carried >> c) & 1u) == 0) out += (out.empty() ? "" : ",") + h.names[c];
  }
  return out;
}

// The header against the on-board record: profile, channel names (hence their count), a sample period
// that is finite, positive and the record's within limits::kStreamPeriodRelTol, a cell count within
// limits::kStreamCells (and given when the record takes it from the stream and the stream carries V_b:
// the masked profile runs a flight without its battery group on no cell count).
inline bool check_stream_header(const StreamHeader& h, const std::string& where, const OnboardRecord& rec,
                                std::string* error) {
  const std::string want = profile_spec(rec.params.profile).name;
  if (h.profile != want) {
    std::string shown = h.profile;
    for (char& c : shown) c = (static_cast<unsigned char>(c) < 32 || c == 127) ? '?' : c;
    return *error = "stream " + where + " is for profile '" + shown + "', the model's is '" + want + "'", false;
  }
  if (h.has_vehicle && profile_spec(rec.params.profile).ref < 0) {
    return *error = "stream " + where + " carries a vehicle record, but profile '" + want + "' reads none", false;
  }
  if (h.names != rec.raw_names) {
    return *error = "stream " + where + ": its " + std::to_string(h.channels) + " channels are not the on-board "
                    "record's " + std::to_string(rec.raw_names.size()) + " raw channels", false;
  }
  const double dt = rec.params.sample_dt_s;
  char buf[256];
  if (!(std::isfinite(dt) && dt > 0.0)) {
    std::snprintf(buf, sizeof buf, "the on-board record's sample period %.9g s is not a positive finite number", dt);
    return *error = buf, false;
  }
  // the record holds the period as float32 (0.04 -> 0.0399999991): equal within float32's precision
  if (!(std::isfinite(h.dt) && h.dt > 0.0 && std::fabs(h.dt - dt) <= limits::kStreamPeriodRelTol * dt)) {
    std::snprintf(buf, sizeof buf, ": sample period %.9g s, the model's is %.9g s (within %g of it)", h.dt, dt,
                  limits::kStreamPeriodRelTol);
    return *error = "stream " + where + buf, false;
  }
  if (h.cells > limits::kStreamCells) {
    return *error = "stream " + where + " gives " + std::to_string(h.cells) + " cells, more than " +
                    std::to_string(limits::kStreamCells), false;
  }
  const bool battery = h.names.size() > 9 && h.names[9] == "V_b" && ((h.carried >> 9) & 1u) != 0;  // V_b: column 9
  if (rec.cells_from_stream && h.cells == 0 && battery) {
    return *error = "stream " + where + " does not give the pack's cell count", false;
  }
  return true;
}

// One sample record (8 + 4R bytes) into its time and values (R float32).
inline double decode_sample(const unsigned char* rec, std::uint32_t channels, float* values) {
  double t;
  std::memcpy(&t, rec, 8);
  std::memcpy(values, rec + 8, 4 * std::size_t(channels));
  return t;
}

}  // namespace host
}  // namespace fwref
