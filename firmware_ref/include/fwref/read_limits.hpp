// fwref/read_limits.hpp -- scope: the largest input each host reader accepts, in one place. A reader
// opens its file once, refuses anything but a regular file (a FIFO would block it, a device such as
// /dev/zero or /dev/urandom never ends), takes the sizes from the file's header and checks them
// against the file's real size and the maximum below BEFORE it allocates: a hostile or broken input is
// one line and exit 2, never a 34 GB allocation. The maxima are far above what the project writes
// (a paper-scale export: weights.bin 0.19 MB, reference.bin 0.41 MB, manifest.json 48 kB) and far below
// what would exhaust a host. The Cortex-M build reads no file (its weights and streams are compiled in).
#pragma once

#include <cstdint>

namespace fwref {
namespace limits {

constexpr std::uint64_t kMiB = std::uint64_t(1) << 20;

// weights.bin and sgru_weights.bin (the largest model this build binds, fwref/config.hpp, is ~5 MB).
constexpr std::uint64_t kWeightsFileBytes = 64 * kMiB;
// reference.bin: its windows and every intermediate (stages: 4N x L floats per window).
constexpr std::uint64_t kReferenceFileBytes = 256 * kMiB;
// manifest.json, read for the sha256 it records for weights.bin (--manifest).
constexpr std::uint64_t kManifestFileBytes = 16 * kMiB;
// windows.f32 of fwref_infer and fwref_pair: raw float32 (n, W, C), a whole number of windows.
constexpr std::uint64_t kWindowsFileBytes = 1024 * kMiB;
// The inputs of the test programs (fwref_activations, fwref_hover, fwref_alarm, fwref_sgru).
constexpr std::uint64_t kToolInputBytes = 1024 * kMiB;

// A vehicle record file (fwref/vehicle_record.hpp): opened within this bound, then refused unless it is
// exactly vehicle::kFileBytes (112) long.
constexpr std::uint64_t kVehicleRecordFileBytes = kMiB;

// A stream file (docs/formats.md "Stream file"), read by fwref_stream sample by sample: its header
// (header_bytes: 128 fixed bytes and the channel names) and its channel count. The samples are not
// bounded: a stream is as long as its flight, and fwref_stream's memory does not grow with it.
constexpr std::uint32_t kStreamHeaderBytes = 64 * 1024;
constexpr std::uint32_t kStreamChannels = 1024;
// The pack's cell count a stream header may give (0: not given); v_cell = V_b / cells.
constexpr std::uint32_t kStreamCells = 64;
// The stream's sample period must be the on-board record's within this relative tolerance (the record
// holds it as float32: 0.04 is 0.0399999991, 2.2e-8 apart).
constexpr double kStreamPeriodRelTol = 1e-6;

}  // namespace limits
}  // namespace fwref
