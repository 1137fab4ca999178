// fwref/file_read.hpp -- scope: opening an input file on the host the one way every reader does
// (fwref/read_limits.hpp says why): opened once, without blocking (O_NONBLOCK: a FIFO cannot hang the
// open), fstat()ed, refused unless it is a regular file of at most the reader's maximum, then read
// exactly the size fstat() gave, and refused if it changed meanwhile. Each failure is a Status and one
// line naming the file. Host only (POSIX).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "fwref/status.hpp"

namespace fwref {

// "a FIFO", "a folder", "a character device", ... for an st_mode that is not a regular file.
const char* file_kind(unsigned mode);

class RegularFile {
 public:
  RegularFile() = default;
  RegularFile(const RegularFile&) = delete;
  RegularFile& operator=(const RegularFile&) = delete;
  ~RegularFile();

  // Open ``path`` (``what`` names it in messages: "weights file"); kFileOpen when it cannot be opened
  // or is not a regular file (``missing`` appended when it does not exist), kBadSize when it holds more
  // than ``max_bytes``.
  Status open(const std::string& path, const char* what, std::uint64_t max_bytes, std::string* error,
              const char* missing = "");
  std::uint64_t size() const { return size_; }
  const std::string& where() const { return where_; }  // "weights file <path>"
  // Exactly size() bytes into ``dst`` and nothing after them (kTruncated otherwise: the file changed).
  Status read_all(void* dst, std::string* error);
  void close();

 private:
  int fd_ = -1;
  std::uint64_t size_ = 0;
  std::string where_;
};

// The whole of a regular file of at most ``max_bytes`` into ``out``.
Status read_regular_file(const std::string& path, const char* what, std::uint64_t max_bytes,
                         std::vector<unsigned char>* out, std::string* error, const char* missing = "");

}  // namespace fwref
