// tools/fwref_pair.cpp -- scope: one model's fp32 and int8 inference timed in one process, taking turns
// (bench/cpp_pairs.py; docs/bench.md "One `make run` on an idle machine"):
//
//   fwref_pair --weights <weights.bin> --model cnode|gru --in <windows.f32> --per-round K --timings <seconds.f64>
//
// windows.f32 as fwref_infer's: raw little-endian float32 (n, W, C), n from the file size, n >= K. First each
// precision runs every window once, untimed (without it the fp32 CNODE's first ~12 rounds of 4 took 12-19 us
// against ~7 us after: its one-time weight copies and first touches). Then the n windows make n / K rounds of K
// consecutive windows. Round r: fp32 first when r is even, int8 first when odd; each
// precision runs one untimed call (on the round's first window: its weights and workspace back in cache after
// the other precision's turn) and then the round's K windows, each timed (steady clock around the call).
// timings.f64: (rounds, 2, K) float64 seconds, [r][0] fp32 and [r][1] int8. Why one process: on the shared
// machines a process lands in one of two speed modes and stays there, and the mode hits both precisions in a
// process alike, so the ratio of two calls a few microseconds apart is free of it; two processes' p50s are not.
// A wrong input size, NaN or Inf in a window, a bad weights file or a model the file does not hold in both
// precisions: one line on stderr, exit 2, nothing written. A usage error: exit 1. --timings must be absent or a
// regular file other than the inputs; --weights and --in regular files within fwref/read_limits.hpp's maxima.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <string>
#include <vector>

#include "host_common.hpp"
#include "host_files.hpp"

namespace {

const fwref::host::Cli kCli("fwref_pair",
                            "usage: fwref_pair --weights <weights.bin> --model cnode|gru --in <windows.f32> "
                            "--per-round K --timings <seconds.f64>");

}  // namespace

int main(int argc, char** argv) try {
  std::string weights, model, in, timings, per;
  const int parsed = kCli.parse(argc, argv, {{"--weights", &weights}, {"--model", &model}, {"--in", &in},
                                             {"--timings", &timings}, {"--per-round", &per}});
  if (parsed >= 0) return parsed;
  if (weights.empty() || model.empty() || in.empty() || timings.empty() || per.empty()) {
    return kCli.usage_error("--weights, --model, --in, --per-round and --timings are required");
  }
  if (model != "cnode" && model != "gru") {
    return kCli.usage_error("--model must be cnode or gru, found '" + model + "'");
  }
  char* end = nullptr;
  const long k_per = std::strtol(per.c_str(), &end, 10);
  if (*end != '\0' || k_per < 1 || k_per > 100000) return kCli.usage_error("--per-round must be a positive integer");

  std::string error;
  if (!fwref::host::output_allowed(timings, {weights, in}, {"--weights file", "--in file"}, &error)) {
    return kCli.fail(error);
  }
  fwref::WeightsFile wf;
  if (wf.load(weights, &error) != fwref::Status::kOk) return kCli.fail(error);
  fwref::Status status;
  std::unique_ptr<fwref::host::Model> m[2];
  for (int p = 0; p < 2; ++p) {
    m[p] = fwref::host::bind_model(wf, model, p == 1, &status, &error);
    if (!m[p]) return kCli.fail(error);
  }
  std::vector<float> x;
  if (!fwref::host::read_windows(in, m[0]->window, m[0]->channels, &x, &error)) return kCli.fail(error);
  const std::size_t per_window = std::size_t(m[0]->window) * m[0]->channels, n = x.size() / per_window;
  const std::size_t K = std::size_t(k_per);
  if (n < K) {
    return kCli.fail("input " + in + " holds " + std::to_string(n) + " windows, fewer than --per-round " + per);
  }
  const std::size_t rounds = n / K;
  std::vector<float> logits(std::size_t(m[0]->classes > m[1]->classes ? m[0]->classes : m[1]->classes));
  std::vector<double> seconds(rounds * 2 * K);
  for (int p = 0; p < 2; ++p) {  // warm-up: the one-time weight copies, the workspace, the clock
    for (std::size_t w = 0; w < n; ++w) {
      if ((status = m[p]->run(&x[w * per_window], logits.data())) != fwref::Status::kOk) {
        return kCli.fail("window " + std::to_string(w) + " of " + in + ": " + fwref::status_name(status));
      }
    }
  }
  for (std::size_t r = 0; r < rounds; ++r) {
    for (int turn = 0; turn < 2; ++turn) {
      const int p = (r % 2 == 0) ? turn : 1 - turn;
      const float* first = &x[r * K * per_window];
      if ((status = m[p]->run(first, logits.data())) != fwref::Status::kOk) {
        return kCli.fail("window " + std::to_string(r * K) + " of " + in + ": " + fwref::status_name(status));
      }
      for (std::size_t j = 0; j < K; ++j) {
        const auto t0 = std::chrono::steady_clock::now();
        status = m[p]->run(first + j * per_window, logits.data());
        const auto t1 = std::chrono::steady_clock::now();
        if (status != fwref::Status::kOk) {
          return kCli.fail("window " + std::to_string(r * K + j) + " of " + in + ": " + fwref::status_name(status));
        }
        seconds[(r * 2 + p) * K + j] = std::chrono::duration<double>(t1 - t0).count();
      }
    }
  }
  if (!fwref::host::write_atomic(timings, seconds.data(), seconds.size() * sizeof(double), &error)) {
    return kCli.fail(error);
  }
  return 0;
} catch (const std::exception& e) {
  return fwref::host::fail_exception("fwref_pair", e);
}
