// src/status.cpp -- scope: the names of fwref::Status codes.
#include "fwref/status.hpp"

namespace fwref {

const char* status_name(Status s) {
  switch (s) {
    case Status::kOk: return "ok";
    case Status::kNullArgument: return "null argument";
    case Status::kDimsInvalid: return "invalid dimensions";
    case Status::kDimsTooLarge: return "dimensions above the compile-time maxima";
    case Status::kBadWeights: return "unusable weight values";
    case Status::kNonFiniteInput: return "NaN or Inf in the input window";
    case Status::kNonFiniteOutput: return "NaN or Inf in the logits";
    case Status::kFileOpen: return "cannot open or read the file";
    case Status::kTruncated: return "truncated file";
    case Status::kBadMagic: return "not a quadfdi file of this kind";
    case Status::kBadVersion: return "unsupported format version";
    case Status::kBadCrc: return "CRC-32 mismatch";
    case Status::kBadHeader: return "bad header";
    case Status::kBadSize: return "size mismatch";
    case Status::kMissingSection: return "missing section";
    case Status::kMissingTensor: return "missing tensor";
    case Status::kBadShape: return "tensor dtype or shape mismatch";
    case Status::kBadInput: return "bad input file";
    case Status::kWriteFailed: return "cannot write the output";
  }
  return "unknown status";
}

}  // namespace fwref
