// fwref/container.hpp -- scope: the host-side reader of the tensor-record container that
// weights.bin and reference.bin share (formats/binfmt.py, docs/formats.md). It checks the
// magic, the version, the file size against the real size, the file and section CRC-32s, and every
// size field against the bytes left before it reads them; each failure is a Status plus a one-line
// message naming the file. The file is read by fwref/file_read.hpp (a regular file of at most the
// caller's maximum, fwref/read_limits.hpp); parse_bytes() checks bytes already in memory (a fuzzer's
// input, or a file whose sha256 was checked first). Host only (std::vector, std::string): the
// microcontroller build has its weights compiled in and never parses a file.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "fwref/contracts_gen.hpp"  // the section codes kModel* / kPrec* (core/contracts.py MODEL_CODES)
#include "fwref/status.hpp"

namespace fwref {

enum class DType : std::uint32_t { kF32 = 1, kI8 = 2, kI32 = 3 };
const char* dtype_name(DType t);

const char* model_name(std::uint32_t model);
const char* precision_name(std::uint32_t precision);

struct TensorInfo {
  std::string name;
  DType dtype;
  int ndim;
  int shape[4];
  int axis;                              // -1 per tensor / not quantized, 0 one scale per row
  int n_scales;                          // 0, 1 or shape[0]
  std::size_t count;                     // prod(shape)
  std::size_t data_offset;               // into the file's bytes
  std::size_t scales_offset;             // float32 scales, then int32 zero points
  std::string shape_text() const;        // "(40, 64)"
};

struct SectionInfo {
  std::uint32_t model;
  std::uint32_t precision;
  std::uint32_t dims[8];
  std::vector<TensorInfo> tensors;
  const TensorInfo* find(const std::string& name) const;
  std::string label() const;             // "cnode int8"
};

// printf into a std::string (one line of an error message; at most 511 characters).
std::string fmt(const char* f, ...) __attribute__((format(printf, 1, 2)));

// zlib's CRC-32 (polynomial 0xEDB88320), as Python's zlib.crc32.
std::uint32_t crc32(const unsigned char* data, std::size_t n, std::uint32_t crc = 0);

class Container {
 public:
  // Read and check ``path``, a regular file of at most ``max_bytes``; ``magic`` is 8 bytes, ``what``
  // names the kind ("weights file").
  Status load(const std::string& path, const char* magic, std::uint32_t version, const char* what,
              std::uint64_t max_bytes, std::string* error);
  // Check ``bytes``, the contents of ``path`` (named in messages only).
  Status parse_bytes(std::vector<unsigned char> bytes, const std::string& path, const char* magic,
                     std::uint32_t version, const char* what, std::string* error);

  const std::vector<SectionInfo>& sections() const { return sections_; }
  const SectionInfo* find(std::uint32_t model, std::uint32_t precision) const;
  const std::string& where() const { return where_; }  // "weights file <path>"
  const std::vector<unsigned char>& bytes() const { return bytes_; }

  // Copy a tensor's values (little-endian in the file) into typed storage.
  void copy_f32(const TensorInfo& t, float* out) const;
  void copy_i8(const TensorInfo& t, std::int8_t* out) const;
  void copy_i32(const TensorInfo& t, std::int32_t* out) const;
  void copy_scales(const TensorInfo& t, float* out) const;
  std::int32_t zero_point(const TensorInfo& t, int i) const;

 private:
  Status parse(const char* magic, std::uint32_t version, const char* what, std::string* error);
  Status parse_section(std::size_t& pos, std::size_t end, int index, std::string* error);
  Status parse_tensor(std::size_t& pos, std::size_t end, const std::string& what, TensorInfo* t, std::string* error);

  std::vector<unsigned char> bytes_;
  std::vector<SectionInfo> sections_;
  std::string where_;
};

}  // namespace fwref
