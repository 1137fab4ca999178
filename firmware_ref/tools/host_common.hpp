// tools/host_common.hpp -- scope: what the host programs (fwref_infer, fwref_pair, fwref_parity, fwref_stream)
// share: the four bound models behind one interface, the no-heap guard around inference, the command line
// (usage, one-line errors and their exit codes), and the input helpers (a bounded whole-file read, the windows
// file: fwref/file_read.hpp, fwref/read_limits.hpp); outputs are written by tools/host_output.hpp.
#pragma once

#include <cerrno>
#include <cmath>
#include <initializer_list>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <memory>
#include <new>
#include <string>
#include <vector>

#include <sys/stat.h>
#include <unistd.h>

#include "fwref/cnode.hpp"
#include "fwref/file_read.hpp"
#include "fwref/gru.hpp"
#include "fwref/read_limits.hpp"
#include "fwref/weights_file.hpp"
#include "host_output.hpp"

#if !defined(__BYTE_ORDER__) || __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "the host programs read little-endian float32 files directly: build them on a little-endian host"
#endif

namespace fwref {
namespace host {

// While alive, any heap allocation by Eigen is an assertion failure (in builds with assertions:
// the sanitizer build); inference must not allocate.
struct NoHeapGuard {
  NoHeapGuard() {
#ifdef EIGEN_RUNTIME_NO_MALLOC
    Eigen::internal::set_is_malloc_allowed(false);
#endif
  }
  ~NoHeapGuard() {
#ifdef EIGEN_RUNTIME_NO_MALLOC
    Eigen::internal::set_is_malloc_allowed(true);
#endif
  }
};

// One bound model and its workspace (allocated once, before any inference).
class Model {
 public:
  virtual ~Model() = default;
  virtual Status run(const float* window, float* logits) = 0;
  int channels = 0, window = 0, classes = 0;
};

template <class M, class Workspace>
class BoundModel final : public Model {
 public:
  explicit BoundModel(const M& m) : m_(m), ws_(new Workspace()) {}
  Status run(const float* x, float* logits) override {
    NoHeapGuard guard;
    return infer(m_, x, logits, *ws_);
  }
  const M& model() const { return m_; }
  Workspace& workspace() { return *ws_; }

 private:
  M m_;
  std::unique_ptr<Workspace> ws_;
};

// Bind (model, precision) of ``wf``; null with ``*error`` set (and ``*status``) on failure.
inline std::unique_ptr<Model> bind_model(WeightsFile& wf, const std::string& kind, bool int8, Status* status,
                                         std::string* error) {
  std::unique_ptr<Model> out;
  if (kind == "cnode" && !int8) {
    CnodeF32 m{};
    if ((*status = wf.bind(&m, error)) == Status::kOk) out.reset(new BoundModel<CnodeF32, CnodeWorkspace>(m));
    if (out) out->channels = m.dims.channels, out->window = m.dims.window, out->classes = m.dims.classes;
  } else if (kind == "cnode") {
    CnodeI8 m{};
    if ((*status = wf.bind(&m, error)) == Status::kOk) out.reset(new BoundModel<CnodeI8, CnodeWorkspace>(m));
    if (out) out->channels = m.dims.channels, out->window = m.dims.window, out->classes = m.dims.classes;
  } else if (!int8) {
    GruF32 m{};
    if ((*status = wf.bind(&m, error)) == Status::kOk) out.reset(new BoundModel<GruF32, GruWorkspace>(m));
    if (out) out->channels = m.dims.channels, out->window = m.dims.window, out->classes = m.dims.classes;
  } else {
    GruI8 m{};
    if ((*status = wf.bind(&m, error)) == Status::kOk) out.reset(new BoundModel<GruI8, GruWorkspace>(m));
    if (out) out->channels = m.dims.channels, out->window = m.dims.window, out->classes = m.dims.classes;
  }
  return out;
}

// What a program's main() returns when an exception would otherwise escape it (an allocation the bounded
// sizes still allow, refused by the machine): one line on stderr, exit 2.
inline int fail_exception(const char* program, const std::exception& e) {
  const bool memory = dynamic_cast<const std::bad_alloc*>(&e) != nullptr;
  std::fprintf(stderr, "%s: error: %s%s\n", program, memory ? "out of memory: " : "", e.what());
  return 2;
}

// The whole regular file ``path`` of at most ``max_bytes`` into ``out``; false with one line in ``*error``
// (``what`` names it: "manifest").
inline bool read_file(const std::string& path, const char* what, std::uint64_t max_bytes,
                      std::vector<unsigned char>* out, std::string* error) {
  return read_regular_file(path, what, max_bytes, out, error) == Status::kOk;
}

// A host program's command line: options that take a value and flags, -h / --help; a usage error is one line
// on stderr and exit 1, a failure (bad input, a file that cannot be read or written) one line and exit 2.
class Cli {
 public:
  struct Value {
    const char* name;
    std::string* dst;
    std::vector<std::string>* every = nullptr;  // a repeatable option: each of its values in order
  };
  struct Flag {
    const char* name;
    bool* dst;
  };
  Cli(const char* program, const char* usage) : program_(program), usage_(usage) {}

  // -1 when the whole line was read into the options; else the exit code: 0 after printing the usage
  // (-h, --help), 1 after a usage error.
  int parse(int argc, char** argv, std::initializer_list<Value> values, std::initializer_list<Flag> flags = {}) const {
    for (int i = 1; i < argc; ++i) {
      const std::string a = argv[i];
      if (a == "-h" || a == "--help") return std::printf("%s\n", usage_), 0;
      const Flag* f = find(flags, a);
      if (f != nullptr) {
        *f->dst = true;
        continue;
      }
      const Value* v = find(values, a);
      if (v == nullptr) return usage_error("unknown argument '" + a + "'");
      if (i + 1 >= argc) return usage_error(a + " needs a value");
      *v->dst = argv[++i];
      if (v->every != nullptr) v->every->push_back(*v->dst);
    }
    return -1;
  }
  int usage_error(const std::string& problem) const {
    std::fprintf(stderr, "%s: %s; %s\n", program_, problem.c_str(), usage_);
    return 1;
  }
  int fail(const std::string& message) const {
    std::fprintf(stderr, "%s: error: %s\n", program_, message.c_str());
    return 2;
  }

 private:
  template <class Option>
  static const Option* find(std::initializer_list<Option> options, const std::string& name) {
    for (const Option& o : options) {
      if (name == o.name) return &o;
    }
    return nullptr;
  }
  const char* program_;
  const char* usage_;
};

// ``path``'s raw little-endian float32 windows (n, window, channels), n >= 1 from the file size, at most
// limits::kWindowsFileBytes, every value finite, into ``x``; false with a one-line reason in ``error`` (the first
// non-finite value named). The size is checked before anything is allocated.
inline bool read_windows(const std::string& path, int window, int channels, std::vector<float>* x, std::string* error) {
  RegularFile f;
  if (f.open(path, "input", limits::kWindowsFileBytes, error) != Status::kOk) return false;
  const std::size_t per_window = std::size_t(window) * channels, window_bytes = per_window * sizeof(float);
  char buf[512];
  if (f.size() == 0 || f.size() % window_bytes != 0) {
    std::snprintf(buf, sizeof buf,
                  "input %s holds %llu bytes, not a whole positive number of (%d, %d) float32 windows of %zu bytes "
                  "(the weights' window and channel count)",
                  path.c_str(), static_cast<unsigned long long>(f.size()), window, channels, window_bytes);
    *error = buf;
    return false;
  }
  x->assign(static_cast<std::size_t>(f.size() / sizeof(float)), 0.0f);
  if (f.read_all(x->data(), error) != Status::kOk) return false;
  for (std::size_t i = 0; i < x->size(); ++i) {
    if (!std::isfinite((*x)[i])) {
      const std::size_t in_window = i % per_window;
      std::snprintf(buf, sizeof buf, "input %s: window %zu holds NaN or Inf (first at sample %zu, channel %zu)",
                    path.c_str(), i / per_window, in_window / channels, in_window % channels);
      *error = buf;
      return false;
    }
  }
  return true;
}

}  // namespace host
}  // namespace fwref
