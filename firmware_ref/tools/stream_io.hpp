// tools/stream_io.hpp -- scope: fwref_stream's input and output files. A stream is read from a path
// (a regular file, or a FIFO: a stream may be piped in) or stdin ("-"); devices, folders and sockets
// are refused in one line (/dev/zero or /dev/urandom would never end). A regular file is checked whole
// before its first sample (a whole number of samples after its header), so that a broken file writes
// nothing. Outputs go through a temp file as they are produced (tools/host_output.hpp): memory does not
// grow with the flight, and a failed write (EFBIG under `ulimit -f`, a full disk) leaves no file.
#pragma once

#include <cerrno>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <utility>
#include <vector>

#include <fcntl.h>
#include <poll.h>
#include <sys/stat.h>
#include <unistd.h>

#include "fwref/file_read.hpp"
#include "host_output.hpp"
#include "stream_file.hpp"

namespace fwref {
namespace host {

// One --in: opened, its header read and checked; then samples one at a time.
class StreamInput {
 public:
  StreamInput() = default;
  StreamInput(const StreamInput&) = delete;
  StreamInput& operator=(const StreamInput&) = delete;
  StreamInput(StreamInput&& o) noexcept { *this = std::move(o); }
  StreamInput& operator=(StreamInput&& o) noexcept {
    std::swap(fd_, o.fd_);
    std::swap(path_, o.path_);
    std::swap(header_, o.header_);
    std::swap(samples_, o.samples_);
    return *this;
  }
  ~StreamInput() {
    if (fd_ > 0) ::close(fd_);  // never stdin
  }

  bool open(const std::string& path, const OnboardRecord& rec, std::string* error) {
    path_ = path;
    if (path == "-") {
      fd_ = 0;
    } else if (!open_path(error)) {
      return false;
    }
    unsigned char fixed[kStreamFixedHeader];
    if (!read_exact(fixed, sizeof fixed)) return *error = "stream " + path_ + " is shorter than its header", false;
    if (!parse_stream_fixed(fixed, path_, &header_, error)) return false;
    std::vector<char> rest(header_.bytes - kStreamFixedHeader);
    if (!read_exact(rest.data(), rest.size())) return *error = "stream " + path_ + " is truncated in its header", false;
    if (!parse_stream_names(rest.data(), rest.size(), path_, &header_, error)) return false;
    if (!check_stream_header(header_, path_, rec, error)) return false;
    if (samples_ >= 0) {  // a regular file: whole samples, checked before the first is read
      const std::uint64_t body = std::uint64_t(samples_) - header_.bytes, rec_bytes = header_.sample_bytes();
      if (std::uint64_t(samples_) < header_.bytes || body % rec_bytes != 0) {
        char buf[200];
        std::snprintf(buf, sizeof buf, " ends inside sample %llu: its %llu bytes after the header are not whole "
                      "samples of %llu bytes", static_cast<unsigned long long>(body / rec_bytes),
                      static_cast<unsigned long long>(body), static_cast<unsigned long long>(rec_bytes));
        return *error = "stream " + path_ + buf, false;
      }
      samples_ = static_cast<std::int64_t>(body / rec_bytes);
    }
    return true;
  }

  const StreamHeader& header() const { return header_; }
  // The next sample's bytes (header().sample_bytes()) into ``rec``: 1 read, 0 at the end, -1 a partial sample.
  int next(unsigned char* rec) {
    const std::size_t n = header_.sample_bytes();
    std::size_t got = 0;
    while (got < n) {
      const ssize_t r = ::read(fd_, rec + got, n - got);
      if (r < 0 && errno == EINTR) continue;
      if (r <= 0) break;
      got += static_cast<std::size_t>(r);
    }
    return got == n ? 1 : got == 0 ? 0 : -1;
  }

 private:
  // A path: a regular file (its size kept in samples_ until the header is read) or a FIFO (the open does
  // not block; the first read waits for the writer); anything else refused.
  bool open_path(std::string* error) {
    fd_ = ::open(path_.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY);
    struct stat st {};
    if (fd_ < 0 || ::fstat(fd_, &st) != 0) {
      *error = errno == ENOENT ? "stream " + path_ + " does not exist" : "cannot open stream " + path_ + ": " +
                                                                          std::strerror(errno);
      return false;
    }
    if (S_ISREG(st.st_mode)) {
      samples_ = static_cast<std::int64_t>(st.st_size);
      return true;
    }
    if (!S_ISFIFO(st.st_mode)) {
      *error = "stream " + path_ + " is " + file_kind(st.st_mode) + ", not a regular file, a FIFO or stdin (-)";
      return false;
    }
    // A FIFO's read end returns end-of-file while no writer has opened it, blocking or not: wait until
    // its writer has written (or come and gone), then read blocking.
    struct pollfd ready {fd_, POLLIN, 0};
    while (::poll(&ready, 1, -1) < 0 && errno == EINTR) {
    }
    const int flags = ::fcntl(fd_, F_GETFL);
    if (flags < 0 || ::fcntl(fd_, F_SETFL, flags & ~O_NONBLOCK) != 0) {
      return *error = "cannot read stream " + path_ + ": " + std::strerror(errno), false;
    }
    return true;
  }

  bool read_exact(void* dst, std::size_t n) {
    unsigned char* p = static_cast<unsigned char*>(dst);
    while (n > 0) {
      const ssize_t r = ::read(fd_, p, n);
      if (r < 0 && errno == EINTR) continue;
      if (r <= 0) return false;
      p += r;
      n -= static_cast<std::size_t>(r);
    }
    return true;
  }

  int fd_ = -1;
  std::string path_;
  StreamHeader header_;
  std::int64_t samples_ = -1;  // a regular file's: its size, then its sample count; -1 for a pipe
};

// An output: stdout (path "") or a file written through a temp file; put() buffers, finish() commits.
class StreamOutput {
 public:
  bool open(const std::string& path, std::string* error) {
    ignore_sigxfsz();
    to_file_ = !path.empty();
    return !to_file_ || file_.create(path, error);
  }
  // False once a write failed (error() says why).
  bool put(const void* data, std::size_t n) {
    if (failed_) return false;
    if (!to_file_) {
      if (std::fwrite(data, 1, n, stdout) != n) return fail(std::string("cannot write stdout: ") + std::strerror(errno));
      return true;
    }
    buf_.append(static_cast<const char*>(data), n);
    return buf_.size() < (1u << 16) || flush();
  }
  bool put(const std::string& s) { return put(s.data(), s.size()); }
  bool finish(std::string* error) {
    if (!to_file_) {
      if (!failed_ && std::fflush(stdout) != 0) fail(std::string("cannot write stdout: ") + std::strerror(errno));
    } else if (flush()) {
      if (!file_.commit(&error_)) failed_ = true;
    }
    if (failed_) *error = error_;
    return !failed_;
  }
  void abort() { file_.abort(); }
  bool failed() const { return failed_; }

 private:
  bool flush() {
    if (failed_) return false;
    const bool ok = file_.write(buf_.data(), buf_.size(), &error_);
    buf_.clear();
    failed_ = !ok;
    return ok;
  }
  bool fail(const std::string& e) {
    error_ = e;
    failed_ = true;
    return false;
  }
  AtomicFile file_;
  std::string buf_, error_;
  bool to_file_ = false, failed_ = false;
};

}  // namespace host
}  // namespace fwref
