// tools/fwref_parity.cpp -- scope: tensor-by-tensor parity of the C++ reference against
// reference.bin (llm.c's test_gpt2 in spirit): for every model and precision the file holds, run
// its windows one at a time with every intermediate traced, and print per tensor the largest
// absolute difference and OK or NOT OK. Exit 0 when all pass, 1 when any fails, 2 when a file is
// unusable (not a regular file, past fwref/read_limits.hpp's maxima, or broken). The rule and its
// tolerances: fwref/parity.hpp.
//
//   fwref_parity --weights <weights.bin> --reference <reference.bin>
//   fwref_parity --kernel-info    the CPU's instruction-set flags and the int8 kernel that runs (exit 0)
#include <cstdio>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "fwref/parity.hpp"
#include "fwref/weights_layout_gen.hpp"
#include "host_common.hpp"
#include "kernel_info.hpp"

namespace {

using fwref::Container;
using fwref::SectionInfo;
using fwref::Status;
using fwref::TensorInfo;


int fail(const std::string& message) {
  std::fprintf(stderr, "fwref_parity: error: %s\n", message.c_str());
  return 2;
}


// One traced tensor over all windows: ``per_window`` values per window and, for int8, the
// quantisation step of each of them (empty for fp32).
struct Traced {
  Traced(const char* name_, std::size_t per_window_, std::vector<double> steps_ = {})
      : name(name_), per_window(per_window_), steps(std::move(steps_)) {}
  const char* name;
  std::size_t per_window;
  std::vector<double> steps;
  std::vector<float> data;
  float* at(int k) { return &data[std::size_t(k) * per_window]; }
};

struct Compare {
  int checked = 0;
  int failed = 0;

  void tensor(const Container& ref, const SectionInfo& sec, const Traced& ours) {
    const bool int8 = !ours.steps.empty();
    const TensorInfo* t = sec.find(ours.name);
    if (t == nullptr || t->dtype != fwref::DType::kF32 || t->count != ours.data.size()) {
      std::printf("%-6s %-5s %-8s missing or of another shape in the reference file        NOT OK\n",
                  fwref::model_name(sec.model), fwref::precision_name(sec.precision), ours.name);
      ++checked, ++failed;
      return;
    }
    std::vector<float> want(t->count);
    ref.copy_f32(*t, want.data());
    fwref::TensorDiff diff;
    for (std::size_t i = 0; i < want.size(); ++i) {
      diff.add(ours.data[i], want[i], int8 ? ours.steps[i % ours.per_window] : 0.0);
    }
    const bool ok = diff.ok(int8);
    char verdict[128];
    if (int8) {
      std::snprintf(verdict, sizeof verdict, "= %.3f steps, tol %.1f steps", diff.max_steps, diff.tol(true));
    } else {
      std::snprintf(verdict, sizeof verdict, "tol %.2e (%g x max(1, %.3g))", diff.tol(false), fwref::kF32RelTol,
                    diff.max_ref);
    }
    std::printf("%-6s %-5s %-8s %-14s max abs diff %.3e %-36s %s\n", fwref::model_name(sec.model),
                fwref::precision_name(sec.precision), ours.name, t->shape_text().c_str(), diff.max_diff, verdict,
                ok ? "OK" : "NOT OK");
    ++checked;
    failed += ok ? 0 : 1;
  }
};

// ``n`` steps, element i's the scale s[i / every % period]: a per-channel scale repeats every
// ``period`` elements, a per-stage scale holds for ``every`` consecutive elements.
std::vector<double> steps_of(const float* s, std::size_t n, std::size_t period, std::size_t every = 1) {
  std::vector<double> out(n);
  for (std::size_t i = 0; i < n; ++i) out[i] = s[(i / every) % period];
  return out;
}

std::vector<double> logit_steps(const fwref::MatQ& head, float s_in) {
  std::vector<double> out(head.rows);
  for (int o = 0; o < head.rows; ++o) out[o] = fwref::logit_step(head.scale, s_in, o);
  return out;
}

// The tensors each model traces, in the order of its Trace struct (logits last), with the steps
// of the int8 model (q) or none (fp32: q null).
std::vector<Traced> traced(const fwref::CnodeDims& d, const fwref::CnodeI8* q) {
  const std::size_t C = d.channels, W = d.window, S = d.stage_times, L = d.latent, E = d.evals(), K = d.classes;
  if (q == nullptr) return {{"x_norm", W * C}, {"u", S * C}, {"z0", L}, {"stages", E * L}, {"z1", L}, {"logits", K}};
  return {{"x_norm", W * C, steps_of(q->s_x, W * C, C)}, {"u", S * C, steps_of(q->s_u, S * C, C)},
          {"z0", L, steps_of(q->s_stage, L, 1)}, {"stages", E * L, steps_of(q->s_stage, E * L, E, L)},
          {"z1", L, steps_of(&q->s_z1, L, 1)}, {"logits", K, logit_steps(q->head_w, q->s_z1)}};
}

std::vector<Traced> traced(const fwref::GruDims& d, const fwref::GruI8* q) {
  const std::size_t C = d.channels, W = d.window, H = d.hidden, K = d.classes;
  if (q == nullptr) return {{"x_norm", W * C}, {"h", W * H}, {"logits", K}};
  return {{"x_norm", W * C, steps_of(q->s_x, W * C, C)}, {"h", W * H, steps_of(&q->s_h, W * H, 1)},
          {"logits", K, logit_steps(q->head_w, q->s_h)}};
}

fwref::CnodeTrace trace_at(std::vector<Traced>& t, int k, const fwref::CnodeDims&) {
  return {t[0].at(k), t[1].at(k), t[2].at(k), t[3].at(k), t[4].at(k)};
}
fwref::GruTrace trace_at(std::vector<Traced>& t, int k, const fwref::GruDims&) { return {t[0].at(k), t[1].at(k)}; }

std::unique_ptr<fwref::CnodeWorkspace> workspace(const fwref::CnodeDims&) {
  return std::unique_ptr<fwref::CnodeWorkspace>(new fwref::CnodeWorkspace());
}
std::unique_ptr<fwref::GruWorkspace> workspace(const fwref::GruDims&) {
  return std::unique_ptr<fwref::GruWorkspace>(new fwref::GruWorkspace());
}

const fwref::CnodeI8* int8_of(const fwref::CnodeF32&) { return nullptr; }
const fwref::CnodeI8* int8_of(const fwref::CnodeI8& m) { return &m; }
const fwref::GruI8* int8_of(const fwref::GruF32&) { return nullptr; }
const fwref::GruI8* int8_of(const fwref::GruI8& m) { return &m; }

// Bind the model of ``sec`` from the weights, run the reference windows one at a time with every
// intermediate traced, and compare each traced tensor with the reference.
template <class Model>
int run_model(fwref::WeightsFile& wf, const Container& ref, const SectionInfo& sec, const std::vector<float>& x, int n,
              Compare& cmp, std::string* error) {
  Model m{};
  if (wf.bind(&m, error) != Status::kOk) return 2;
  const auto& d = m.dims;
  for (int i = 0; i < 8; ++i) {
    const std::uint32_t mine = i == 7 ? std::uint32_t(n) : wf.container().find(sec.model, sec.precision)->dims[i];
    if (sec.dims[i] != mine) {
      *error = "reference file section " + sec.label() + " describes another model (dims differ from the weights)";
      return 2;
    }
  }
  std::vector<Traced> t = traced(d, int8_of(m));
  for (Traced& tr : t) tr.data.resize(tr.per_window * std::size_t(n));
  auto ws = workspace(d);
  const std::size_t window = std::size_t(d.window) * d.channels;
  for (int k = 0; k < n; ++k) {
    auto tr = trace_at(t, k, d);
    Status s;
    {
      fwref::host::NoHeapGuard guard;
      s = fwref::infer(m, &x[std::size_t(k) * window], t.back().at(k), *ws, &tr);
    }
    if (s != Status::kOk) {
      *error = sec.label() + " window " + std::to_string(k) + ": " + fwref::status_name(s);
      return 2;
    }
  }
  for (const Traced& tr : t) cmp.tensor(ref, sec, tr);
  return 0;
}

int run_section(fwref::WeightsFile& wf, const Container& ref, const SectionInfo& sec, const std::vector<float>& x,
                int n, Compare& cmp, std::string* error) {
  const bool int8 = sec.precision == fwref::kPrecI8;
  if (sec.model == fwref::kModelCnode) {
    return int8 ? run_model<fwref::CnodeI8>(wf, ref, sec, x, n, cmp, error)
                : run_model<fwref::CnodeF32>(wf, ref, sec, x, n, cmp, error);
  }
  return int8 ? run_model<fwref::GruI8>(wf, ref, sec, x, n, cmp, error)
              : run_model<fwref::GruF32>(wf, ref, sec, x, n, cmp, error);
}

}  // namespace

int main(int argc, char** argv) try {
  std::string weights, reference;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if ((a == "--weights" || a == "--reference") && i + 1 < argc) {
      (a == "--weights" ? weights : reference) = argv[++i];
    } else if (a == "--kernel-info") {  // which int8 kernel runs here, the CPU's flags (tools/kernel_info.hpp)
      fwref::host::print_kernel_info(stdout);
      return 0;
    } else if (a == "-h" || a == "--help") {
      std::printf("usage: fwref_parity --weights <weights.bin> --reference <reference.bin> | --kernel-info\n");
      return 0;
    } else {
      std::fprintf(stderr, "fwref_parity: unknown or incomplete argument '%s'; usage: fwref_parity --weights "
                           "<weights.bin> --reference <reference.bin>\n", a.c_str());
      return 1;
    }
  }
  if (weights.empty() || reference.empty()) {
    std::fprintf(stderr, "fwref_parity: --weights and --reference are required; usage: fwref_parity --weights "
                         "<weights.bin> --reference <reference.bin>\n");
    return 1;
  }
  std::string error;
  fwref::WeightsFile wf;
  if (wf.load(weights, &error) != Status::kOk) return fail(error);
  Container ref;
  if (ref.load(reference, fwref::layout::kReferenceMagic, fwref::layout::kReferenceVersion, "reference file",
               fwref::limits::kReferenceFileBytes, &error) != Status::kOk) {
    return fail(error);
  }
  const SectionInfo* inputs = ref.find(fwref::kModelNone, fwref::kPrecNone);
  const TensorInfo* tel = inputs ? inputs->find("telemetry") : nullptr;
  if (tel == nullptr || tel->dtype != fwref::DType::kF32 || tel->ndim != 3) {
    return fail(ref.where() + " has no (n, W, C) float32 'telemetry' inputs");
  }
  const int n = tel->shape[0];
  std::vector<float> x(tel->count);
  ref.copy_f32(*tel, x.data());
  std::printf("fwref_parity: %s against %s, %d windows, one at a time\n", weights.c_str(), reference.c_str(), n);

  Compare cmp;
  int sections = 0;
  for (const SectionInfo& sec : ref.sections()) {
    if (sec.model == fwref::kModelNone) continue;
    if (sec.dims[1] != std::uint32_t(tel->shape[1]) || sec.dims[0] != std::uint32_t(tel->shape[2])) {
      return fail(ref.where() + ": section " + sec.label() + " disagrees with the inputs' (W, C)");
    }
    const int rc = run_section(wf, ref, sec, x, n, cmp, &error);
    if (rc != 0) return fail(error);
    ++sections;
  }
  if (sections == 0) return fail(ref.where() + " holds no model sections");
  if (cmp.failed == 0) {
    std::printf("fwref_parity: all %d tensors OK\n", cmp.checked);
    return 0;
  }
  std::printf("fwref_parity: %d of %d tensors NOT OK\n", cmp.failed, cmp.checked);
  return 1;
} catch (const std::exception& e) {
  return fwref::host::fail_exception("fwref_parity", e);
}
