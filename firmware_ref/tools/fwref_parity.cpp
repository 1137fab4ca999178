// tools/fwref_parity.cpp -- scope: tensor-by-tensor parity of the C++ reference against
// reference.bin (llm.c's test_gpt2 in spirit): for every model and precision the file holds, run
// its windows one at a time with every intermediate traced, and print per tensor the largest
// absolute difference and OK or NOT OK. Exit 0 when all pass, 1 when any fails, 2 when a file is
// unusable. Tolerances: fwref/parity.hpp.
//
//   fwref_parity --weights <weights.bin> --reference <reference.bin>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "fwref/parity.hpp"
#include "host_common.hpp"

namespace {

using fwref::Container;
using fwref::SectionInfo;
using fwref::Status;
using fwref::TensorInfo;

constexpr char kReferenceMagic[9] = "QFDIREF";
constexpr std::uint32_t kReferenceVersion = 1;

int fail(const std::string& message) {
  std::fprintf(stderr, "fwref_parity: error: %s\n", message.c_str());
  return 2;
}


struct Compare {
  int checked = 0;
  int failed = 0;

  // ``ours`` and the reference tensor ``name`` of ``sec``; ``step`` null for fp32.
  bool tensor(const Container& ref, const SectionInfo& sec, const char* name, const std::vector<float>& ours,
              const std::vector<double>* steps, std::size_t step_period) {
    const TensorInfo* t = sec.find(name);
    if (t == nullptr || t->dtype != fwref::DType::kF32 || t->count != ours.size()) {
      std::printf("%-6s %-5s %-8s missing or of another shape in the reference file        NOT OK\n",
                  fwref::model_name(sec.model), fwref::precision_name(sec.precision), name);
      ++checked, ++failed;
      return false;
    }
    std::vector<float> want(t->count);
    ref.copy_f32(*t, want.data());
    double max_diff = 0.0, max_ref = 0.0, max_steps = 0.0;
    for (std::size_t i = 0; i < want.size(); ++i) {
      const double d = std::fabs(double(ours[i]) - double(want[i]));
      max_diff = std::max(max_diff, std::isnan(d) ? INFINITY : d);
      max_ref = std::max(max_ref, std::fabs(double(want[i])));
      if (steps != nullptr) max_steps = std::max(max_steps, d / (*steps)[i % step_period]);
    }
    bool ok;
    char verdict[128];
    if (steps == nullptr) {
      const double tol = fwref::kF32RelTol * std::max(1.0, max_ref);
      ok = max_diff <= tol;
      std::snprintf(verdict, sizeof verdict, "tol %.2e (1e-4 x max(1, %.3g))", tol, max_ref);
    } else {
      ok = max_steps <= fwref::kI8TolSteps;
      std::snprintf(verdict, sizeof verdict, "= %.3f steps, tol %.1f steps", max_steps, fwref::kI8TolSteps);
    }
    std::printf("%-6s %-5s %-8s %-14s max abs diff %.3e %-36s %s\n", fwref::model_name(sec.model),
                fwref::precision_name(sec.precision), name, t->shape_text().c_str(), max_diff, verdict,
                ok ? "OK" : "NOT OK");
    ++checked;
    failed += ok ? 0 : 1;
    return ok;
  }
};

std::vector<double> repeat_steps(const float* s, int n, double factor = 1.0) {
  std::vector<double> out(n);
  for (int i = 0; i < n; ++i) out[i] = factor * s[i];
  return out;
}

// logit step of class o: 127 * s_in * s_w[o] (the largest change one head-input step can make)
std::vector<double> logit_steps(const fwref::MatQ& head, float s_in) {
  std::vector<double> out(head.rows);
  for (int o = 0; o < head.rows; ++o) out[o] = 127.0 * double(s_in) * double(head.scale[o]);
  return out;
}

template <class M>
bool dims_match(const M& m, const SectionInfo& sec, int n) {
  return sec.dims[0] == std::uint32_t(m.dims.channels) && sec.dims[1] == std::uint32_t(m.dims.window) &&
         sec.dims[7] == std::uint32_t(n);
}

int run_cnode(fwref::WeightsFile& wf, const Container& ref, const SectionInfo& sec, const std::vector<float>& x,
              int n, Compare& cmp, std::string* error) {
  const bool int8 = sec.precision == fwref::kPrecI8;
  fwref::CnodeF32 mf{};
  fwref::CnodeI8 mq{};
  Status s = int8 ? wf.bind(&mq, error) : wf.bind(&mf, error);
  if (s != Status::kOk) return 2;
  const fwref::CnodeDims d = int8 ? mq.dims : mf.dims;
  if (!(int8 ? dims_match(mq, sec, n) : dims_match(mf, sec, n)) || sec.dims[5] != std::uint32_t(d.steps)) {
    *error = "reference file section " + sec.label() + " describes another model (dims differ from the weights)";
    return 2;
  }
  const int W = d.window, C = d.channels, S = d.stage_times, L = d.latent, K = d.classes, E = d.evals();
  std::vector<float> x_norm(std::size_t(n) * W * C), u(std::size_t(n) * S * C), z0(std::size_t(n) * L),
      stages(std::size_t(n) * E * L), z1(std::size_t(n) * L), logits(std::size_t(n) * K);
  std::unique_ptr<fwref::CnodeWorkspace> ws(new fwref::CnodeWorkspace());
  for (int k = 0; k < n; ++k) {
    fwref::CnodeTrace tr{&x_norm[std::size_t(k) * W * C], &u[std::size_t(k) * S * C], &z0[std::size_t(k) * L],
                         &stages[std::size_t(k) * E * L], &z1[std::size_t(k) * L]};
    {
      fwref::host::NoHeapGuard guard;
      s = int8 ? fwref::infer(mq, &x[std::size_t(k) * W * C], &logits[std::size_t(k) * K], *ws, &tr)
               : fwref::infer(mf, &x[std::size_t(k) * W * C], &logits[std::size_t(k) * K], *ws, &tr);
    }
    if (s != Status::kOk) {
      *error = "cnode " + std::string(int8 ? "int8" : "fp32") + " window " + std::to_string(k) + ": " +
               fwref::status_name(s);
      return 2;
    }
  }
  if (!int8) {
    cmp.tensor(ref, sec, "x_norm", x_norm, nullptr, 1);
    cmp.tensor(ref, sec, "u", u, nullptr, 1);
    cmp.tensor(ref, sec, "z0", z0, nullptr, 1);
    cmp.tensor(ref, sec, "stages", stages, nullptr, 1);
    cmp.tensor(ref, sec, "z1", z1, nullptr, 1);
    cmp.tensor(ref, sec, "logits", logits, nullptr, 1);
    return 0;
  }
  const std::vector<double> sx = repeat_steps(mq.s_x, C), su = repeat_steps(mq.s_u, C);
  const std::vector<double> s0(L, mq.s_stage[0]), s1(L, mq.s_z1);
  std::vector<double> se(std::size_t(E) * L);
  for (int e = 0; e < E; ++e) std::fill(se.begin() + std::size_t(e) * L, se.begin() + std::size_t(e + 1) * L, mq.s_stage[e]);
  const std::vector<double> sl = logit_steps(mq.head_w, mq.s_z1);
  cmp.tensor(ref, sec, "x_norm", x_norm, &sx, C);
  cmp.tensor(ref, sec, "u", u, &su, C);
  cmp.tensor(ref, sec, "z0", z0, &s0, L);
  cmp.tensor(ref, sec, "stages", stages, &se, se.size());
  cmp.tensor(ref, sec, "z1", z1, &s1, L);
  cmp.tensor(ref, sec, "logits", logits, &sl, K);
  return 0;
}

int run_gru(fwref::WeightsFile& wf, const Container& ref, const SectionInfo& sec, const std::vector<float>& x, int n,
            Compare& cmp, std::string* error) {
  const bool int8 = sec.precision == fwref::kPrecI8;
  fwref::GruF32 mf{};
  fwref::GruI8 mq{};
  Status s = int8 ? wf.bind(&mq, error) : wf.bind(&mf, error);
  if (s != Status::kOk) return 2;
  const fwref::GruDims d = int8 ? mq.dims : mf.dims;
  if (!(int8 ? dims_match(mq, sec, n) : dims_match(mf, sec, n)) || sec.dims[3] != std::uint32_t(d.hidden)) {
    *error = "reference file section " + sec.label() + " describes another model (dims differ from the weights)";
    return 2;
  }
  const int W = d.window, C = d.channels, H = d.hidden, K = d.classes;
  std::vector<float> x_norm(std::size_t(n) * W * C), h(std::size_t(n) * W * H), logits(std::size_t(n) * K);
  std::unique_ptr<fwref::GruWorkspace> ws(new fwref::GruWorkspace());
  for (int k = 0; k < n; ++k) {
    fwref::GruTrace tr{&x_norm[std::size_t(k) * W * C], &h[std::size_t(k) * W * H]};
    {
      fwref::host::NoHeapGuard guard;
      s = int8 ? fwref::infer(mq, &x[std::size_t(k) * W * C], &logits[std::size_t(k) * K], *ws, &tr)
               : fwref::infer(mf, &x[std::size_t(k) * W * C], &logits[std::size_t(k) * K], *ws, &tr);
    }
    if (s != Status::kOk) {
      *error = "gru " + std::string(int8 ? "int8" : "fp32") + " window " + std::to_string(k) + ": " +
               fwref::status_name(s);
      return 2;
    }
  }
  if (!int8) {
    cmp.tensor(ref, sec, "x_norm", x_norm, nullptr, 1);
    cmp.tensor(ref, sec, "h", h, nullptr, 1);
    cmp.tensor(ref, sec, "logits", logits, nullptr, 1);
    return 0;
  }
  const std::vector<double> sx = repeat_steps(mq.s_x, C), sh(H, mq.s_h), sl = logit_steps(mq.head_w, mq.s_h);
  cmp.tensor(ref, sec, "x_norm", x_norm, &sx, C);
  cmp.tensor(ref, sec, "h", h, &sh, H);
  cmp.tensor(ref, sec, "logits", logits, &sl, K);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  std::string weights, reference;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if ((a == "--weights" || a == "--reference") && i + 1 < argc) {
      (a == "--weights" ? weights : reference) = argv[++i];
    } else if (a == "-h" || a == "--help") {
      std::printf("usage: fwref_parity --weights <weights.bin> --reference <reference.bin>\n");
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
  if (ref.load(reference, kReferenceMagic, kReferenceVersion, "reference file", &error) != Status::kOk) return fail(error);
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
    const int rc = sec.model == fwref::kModelCnode ? run_cnode(wf, ref, sec, x, n, cmp, &error)
                                                   : run_gru(wf, ref, sec, x, n, cmp, &error);
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
}
