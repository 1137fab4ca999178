// fuzz/fuzz_common.hpp -- scope: what the harnesses share: the model they run inputs through (a
// weights.bin, $FWREF_FUZZ_WEIGHTS or the committed corpus/weights seed), a CRC fixer that lets mutations
// reach past the container's CRC-32s, bytes as a regular file (memfd) for the readers that take a path,
// and the invariants every reader keeps: a refusal is one non-empty line, and a finding is a crash.
#pragma once

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include <sys/mman.h>
#include <unistd.h>

#include "fwref/container.hpp"
#include "fwref/weights_file.hpp"

namespace fuzz {

// Crash (a finding) unless ``c`` holds.
inline void require(bool c, const char* what, const std::string& detail = "") {
  if (!c) {
    std::fprintf(stderr, "fuzz invariant broken: %s %s\n", what, detail.c_str());
    std::abort();
  }
}

// A refusal's message: one line, not empty.
inline void one_line(const std::string& error) {
  require(!error.empty() && error.find('\n') == std::string::npos, "a refusal is one non-empty line", error);
}

inline std::uint32_t u32(const std::vector<unsigned char>& b, std::size_t at) {
  return std::uint32_t(b[at]) | std::uint32_t(b[at + 1]) << 8 | std::uint32_t(b[at + 2]) << 16 |
         std::uint32_t(b[at + 3]) << 24;
}

inline void put_u32(std::vector<unsigned char>& b, std::size_t at, std::uint32_t v) {
  for (int i = 0; i < 4; ++i) b[at + i] = static_cast<unsigned char>(v >> (8 * i));
}

// ``data`` with its header's file size and every CRC-32 it can locate made right (sections walked by their
// own size fields, at most 64), so that the fuzzer explores the parsing past the checksums.
inline std::vector<unsigned char> with_fixed_crcs(const std::uint8_t* data, std::size_t size) {
  std::vector<unsigned char> b(data, data + size);
  if (b.size() < 28) return b;
  const std::uint64_t n = b.size();
  put_u32(b, 16, static_cast<std::uint32_t>(n));
  put_u32(b, 20, static_cast<std::uint32_t>(n >> 32));
  const std::size_t end = b.size() - 4;
  std::size_t pos = 24;
  for (std::uint32_t i = 0; i < u32(b, 12) && i < 64; ++i) {
    if (end - pos < 56) break;
    const std::uint32_t sz = u32(b, pos + 4);
    if (sz < 56 || sz > end - pos) break;
    put_u32(b, pos + sz - 4, fwref::crc32(b.data() + pos, sz - 4));
    pos += sz;
  }
  put_u32(b, end, fwref::crc32(b.data(), end));
  return b;
}

// The weights file the harnesses that need a model run: $FWREF_FUZZ_WEIGHTS, else the committed seed.
inline fwref::WeightsFile& model_file() {
  static fwref::WeightsFile* wf = [] {
    const char* env = std::getenv("FWREF_FUZZ_WEIGHTS");
    const std::string path = env != nullptr && *env != '\0' ? env : FWREF_FUZZ_CORPUS "/fuzz_weights/flightlog_min.bin";
    auto* w = new fwref::WeightsFile();
    std::string error;
    if (w->load(path, &error) != fwref::Status::kOk) {
      std::fprintf(stderr, "fuzz: cannot load the model (%s): %s\n", path.c_str(), error.c_str());
      std::exit(2);
    }
    return w;
  }();
  return *wf;
}

// Bytes as a regular file with a path (/proc/self/fd/N of a memfd), for readers that open a path.
class MemFile {
 public:
  MemFile() : fd_(::memfd_create("fuzz", 0)) { require(fd_ >= 0, "memfd_create"); }
  ~MemFile() { ::close(fd_); }
  std::string hold(const std::uint8_t* data, std::size_t size) {
    require(::ftruncate(fd_, 0) == 0 && (size == 0 || ::pwrite(fd_, data, size, 0) == ssize_t(size)), "memfd write");
    return "/proc/self/fd/" + std::to_string(fd_);
  }

 private:
  int fd_;
};

}  // namespace fuzz
