// src/file_read.cpp -- scope: fwref/file_read.hpp, the bounded opening and reading of an input file.
#include "fwref/file_read.hpp"

#include <cerrno>
#include <cstring>

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include "fwref/container.hpp"  // fmt

namespace fwref {

const char* file_kind(unsigned mode) {
  switch (mode & S_IFMT) {
    case S_IFREG: return "a regular file";
    case S_IFDIR: return "a folder";
    case S_IFIFO: return "a FIFO";
    case S_IFCHR: return "a character device";
    case S_IFBLK: return "a block device";
    case S_IFSOCK: return "a socket";
    case S_IFLNK: return "a symlink";
  }
  return "a special file";
}

RegularFile::~RegularFile() { close(); }

void RegularFile::close() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

Status RegularFile::open(const std::string& path, const char* what, std::uint64_t max_bytes, std::string* error,
                         const char* missing) {
  close();
  size_ = 0;
  where_ = std::string(what) + " " + path;
  fd_ = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC | O_NOCTTY);
  if (fd_ < 0) {
    const int e = errno;
    *error = e == ENOENT ? fmt("%s does not exist%s", where_.c_str(), missing)
                         : fmt("cannot read %s: %s", where_.c_str(), std::strerror(e));
    return Status::kFileOpen;
  }
  struct stat st {};
  if (::fstat(fd_, &st) != 0) {
    *error = fmt("cannot read %s: %s", where_.c_str(), std::strerror(errno));
    close();
    return Status::kFileOpen;
  }
  if (!S_ISREG(st.st_mode)) {
    *error = fmt("%s is %s, not a regular file: refusing to read it", where_.c_str(), file_kind(st.st_mode));
    close();
    return Status::kFileOpen;
  }
  if (static_cast<std::uint64_t>(st.st_size) > max_bytes) {
    *error = fmt("%s holds %llu bytes, more than the %llu MiB this reader accepts (fwref/read_limits.hpp)",
                 where_.c_str(), static_cast<unsigned long long>(st.st_size),
                 static_cast<unsigned long long>(max_bytes >> 20));
    close();
    return Status::kBadSize;
  }
  size_ = static_cast<std::uint64_t>(st.st_size);
  return Status::kOk;
}

Status RegularFile::read_all(void* dst, std::string* error) {
  unsigned char* p = static_cast<unsigned char*>(dst);
  std::uint64_t got = 0;
  while (got < size_) {
    const ssize_t r = ::read(fd_, p + got, static_cast<std::size_t>(size_ - got));
    if (r < 0 && errno == EINTR) continue;
    if (r < 0) {
      *error = fmt("cannot read %s: %s", where_.c_str(), std::strerror(errno));
      return Status::kFileOpen;
    }
    if (r == 0) break;
    got += static_cast<std::uint64_t>(r);
  }
  unsigned char extra;
  ssize_t more;
  do {
    more = got == size_ ? ::read(fd_, &extra, 1) : 0;
  } while (more < 0 && errno == EINTR);
  if (got != size_ || more > 0) {
    *error = fmt("%s changed while it was read (%llu bytes when opened)", where_.c_str(),
                 static_cast<unsigned long long>(size_));
    return Status::kTruncated;
  }
  return Status::kOk;
}

Status read_regular_file(const std::string& path, const char* what, std::uint64_t max_bytes,
                         std::vector<unsigned char>* out, std::string* error, const char* missing) {
  out->clear();
  RegularFile f;
  Status s = f.open(path, what, max_bytes, error, missing);
  if (s != Status::kOk) return s;
  out->resize(static_cast<std::size_t>(f.size()));
  s = f.read_all(out->data(), error);
  if (s != Status::kOk) out->clear();
  return s;
}

}  // namespace fwref
