// tools/host_output.hpp -- scope: how the host programs write a file: into a temp file in the same
// folder, renamed over the output only once every byte is written and synced, so that a reader never
// sees a partial output and a failure leaves nothing behind. A write that fails (a full disk, EFBIG
// under `ulimit -f`) removes the temp file and is one line; SIGXFSZ is ignored so that a file-size limit
// makes write() fail with EFBIG instead of killing the program with its temp file left; SIGINT, SIGTERM
// and SIGHUP remove the live temp files before the program dies of them.
#pragma once

#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include <sys/stat.h>
#include <unistd.h>

namespace fwref {
namespace host {

namespace detail {

constexpr int kLiveTemps = 8;  // outputs a program has open at once (fwref_infer: 3)
constexpr std::size_t kTempPathBytes = 4096;
inline char g_live_temps[kLiveTemps][kTempPathBytes];  // "" = a free slot; read by the signal handler

inline void remove_temps_and_die(int sig) {
  for (int i = 0; i < kLiveTemps; ++i) {
    if (g_live_temps[i][0] != '\0') ::unlink(g_live_temps[i]);  // async-signal-safe
  }
  std::signal(sig, SIG_DFL);
  std::raise(sig);
}

inline void install_handlers() {
  static bool done = false;
  if (done) return;
  done = true;
  std::signal(SIGXFSZ, SIG_IGN);
  for (int sig : {SIGINT, SIGTERM, SIGHUP}) {
    if (std::signal(sig, remove_temps_and_die) == SIG_IGN) std::signal(sig, SIG_IGN);  // keep nohup's choice
  }
}

}  // namespace detail

// SIGXFSZ ignored: a write past `ulimit -f` fails with EFBIG (and is reported) instead of killing the
// program. Every program that writes a file or stdout calls it (AtomicFile does).
inline void ignore_sigxfsz() { detail::install_handlers(); }

// One output written through a temp file: create(), write()..., commit(); destroyed or abort()ed before
// commit() it removes the temp file.
class AtomicFile {
 public:
  AtomicFile() = default;
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;
  ~AtomicFile() { abort(); }

  bool create(const std::string& path, std::string* error) {
    abort();
    detail::install_handlers();
    path_ = path;
    std::string tmp = path + ".tmp.XXXXXX";
    if (tmp.size() >= detail::kTempPathBytes) return fail("the path is too long", error);
    std::vector<char> name(tmp.begin(), tmp.end());
    name.push_back('\0');
    fd_ = ::mkstemp(name.data());
    if (fd_ < 0) return fail(std::strerror(errno), error);
    tmp_.assign(name.data());
    for (slot_ = 0; slot_ < detail::kLiveTemps && detail::g_live_temps[slot_][0] != '\0'; ++slot_) {
    }
    if (slot_ < detail::kLiveTemps) std::memcpy(detail::g_live_temps[slot_], name.data(), name.size());
    const mode_t mask = ::umask(0);  // mkstemp makes 0600: give the file the user's umask instead
    ::umask(mask);
    ::fchmod(fd_, 0666 & ~mask);
    return true;
  }

  bool write(const void* data, std::size_t n, std::string* error) {
    const char* p = static_cast<const char*>(data);
    while (n > 0) {
      const ssize_t w = ::write(fd_, p, n);
      if (w < 0 && errno == EINTR) continue;
      if (w <= 0) return fail(w < 0 ? std::strerror(errno) : "nothing written", error);
      p += w;
      n -= static_cast<std::size_t>(w);
    }
    return true;
  }

  // fsync, close and rename over the output; on failure the temp file is removed.
  bool commit(std::string* error) {
    if (::fsync(fd_) != 0) return fail(std::strerror(errno), error);
    const int fd = fd_;
    fd_ = -1;
    if (::close(fd) != 0) return fail(std::strerror(errno), error);
    if (std::rename(tmp_.c_str(), path_.c_str()) != 0) return fail(std::strerror(errno), error);
    release_slot();
    tmp_.clear();
    return true;
  }

  void abort() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
    if (!tmp_.empty()) ::unlink(tmp_.c_str());
    release_slot();
    tmp_.clear();
  }

 private:
  bool fail(const char* why, std::string* error) {
    *error = "cannot write " + path_ + ": " + why;
    abort();
    return false;
  }
  void release_slot() {
    if (slot_ >= 0 && slot_ < detail::kLiveTemps) detail::g_live_temps[slot_][0] = '\0';
    slot_ = -1;
  }
  std::string path_, tmp_;
  int fd_ = -1;
  int slot_ = -1;
};

// ``n`` bytes to ``path`` through a temp file and a rename; false with one line in ``error``, nothing left.
inline bool write_atomic(const std::string& path, const void* data, std::size_t n, std::string* error) {
  AtomicFile f;
  return f.create(path, error) && f.write(data, n, error) && f.commit(error);
}

}  // namespace host
}  // namespace fwref
