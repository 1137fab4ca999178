// fwref/status.hpp -- scope: the error codes every fwref function returns (no exceptions anywhere:
// the microcontroller build has none) and their one-line names.
#pragma once

#include <cstdint>

namespace fwref {

enum class Status : std::uint8_t {
  kOk = 0,
  // inference (model code, also on the microcontroller)
  kNullArgument,     // a required pointer is null
  kDimsInvalid,      // a dimension is not positive or dimensions disagree (e.g. S != 2N + 1)
  kDimsTooLarge,     // a dimension exceeds its compile-time maximum (fwref/config.hpp)
  kBadWeights,       // a value the arithmetic cannot use (scale <= 0, stage index out of range, NaN)
  kNonFiniteInput,   // the telemetry window holds NaN or Inf
  kNonFiniteOutput,  // the logits came out NaN or Inf (weights that overflow float32)
  // weights.bin / reference.bin (host reader)
  kFileOpen,         // cannot open or read the file
  kTruncated,        // fewer bytes than a header or a size field says
  kBadMagic,         // not a quadfdi file of the expected kind
  kBadVersion,       // another format version
  kBadCrc,           // a CRC-32 does not match
  kBadHeader,        // a section or tensor header holds impossible values
  kBadSize,          // a size field disagrees with the shape or with the bytes present
  kMissingSection,   // the file holds no section for the model/precision asked for
  kMissingTensor,    // a section lacks a tensor the model needs
  kBadShape,         // a tensor's dtype or shape disagrees with the section's dimensions
  // fwref_infer / fwref_parity input
  kBadInput,         // the windows file has the wrong size
  kWriteFailed,      // the output could not be written
};

// A short English name of ``s`` (static string, never null).
const char* status_name(Status s);

}  // namespace fwref
