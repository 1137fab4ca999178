// tools/fwref_infer.cpp -- scope: the command-line inference program (a contract: outside tools
// drive it, docs/firmware.md):
//
//   fwref_infer --weights <weights.bin> --model cnode|gru [--int8] --in <windows.f32> --out <logits.f32>
//               [--repeat R --timings <seconds.f64>] [--manifest <manifest.json>] [--motor-out <motor.f32>]
//
// windows.f32: raw little-endian float32 (n, W, C), n from the file size; logits.f32: (n, K)
// float32. Windows run one at a time (batch 1, as firmware does). A wrong input size, NaN or Inf in
// a window, a bad or truncated weights file or a model the file does not hold: one line on stderr,
// exit 2, no output file. A usage error: exit 1. Optional --timings writes (n, R) float64 seconds
// per inference (steady clock around each call; R = --repeat, default 1) for benchmarks.
// --manifest: weights.bin must have the sha256 export/manifest.json records for it. --out and
// --timings must be absent or regular files other than the inputs (a symlink, FIFO, device or an
// input is refused before anything runs); outputs are created with the user's umask.
// --motor-out: also the motor head's logits (n, 4) float32 (fwref/motor.hpp), from the same
// inference; a weights file without the net's motor section is refused (exit 2, no output).
// Without it the program and its outputs are what they were.
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

#include "host_common.hpp"
#include "host_files.hpp"
#include "host_motor.hpp"

namespace {

const char* const kUsage =
    "usage: fwref_infer --weights <weights.bin> --model cnode|gru [--int8] --in <windows.f32> --out <logits.f32> "
    "[--repeat R --timings <seconds.f64>] [--manifest <manifest.json>] [--motor-out <motor.f32>]";

int usage_error(const std::string& problem) {
  std::fprintf(stderr, "fwref_infer: %s; %s\n", problem.c_str(), kUsage);
  return 1;
}

int fail(const std::string& message) {
  std::fprintf(stderr, "fwref_infer: error: %s\n", message.c_str());
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  std::string weights, model, in, out, timings, manifest, motor_out;
  bool int8 = false;
  long repeat = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&](std::string* dst) -> bool {
      if (i + 1 >= argc) return false;
      *dst = argv[++i];
      return true;
    };
    std::string r;
    if (a == "-h" || a == "--help") {
      std::printf("%s\n", kUsage);
      return 0;
    } else if (a == "--int8") {
      int8 = true;
    } else if (a == "--weights" || a == "--model" || a == "--in" || a == "--out" || a == "--timings" ||
               a == "--manifest" || a == "--motor-out") {
      std::string* dst = a == "--weights" ? &weights : a == "--model" ? &model : a == "--in" ? &in
                         : a == "--out" ? &out : a == "--manifest" ? &manifest : a == "--motor-out" ? &motor_out
                         : &timings;
      if (!value(dst)) return usage_error(a + " needs a value");
    } else if (a == "--repeat") {
      char* end = nullptr;
      if (!value(&r)) return usage_error("--repeat needs a value");
      repeat = std::strtol(r.c_str(), &end, 10);
      if (*end != '\0' || repeat < 1 || repeat > 1000000) return usage_error("--repeat must be a positive integer");
    } else {
      return usage_error("unknown argument '" + a + "'");
    }
  }
  if (weights.empty() || model.empty() || in.empty() || out.empty()) {
    return usage_error("--weights, --model, --in and --out are required");
  }
  if (model != "cnode" && model != "gru") return usage_error("--model must be cnode or gru, found '" + model + "'");

  std::string error;
  const std::vector<std::string> what = {"--weights file", "--in file", "--manifest file", "--timings file"};
  if (!fwref::host::output_allowed(out, {weights, in, manifest, timings}, what, &error)) return fail(error);
  if (!timings.empty() && (timings == out ||
                           !fwref::host::output_allowed(timings, {weights, in, manifest, out},
                                                        {"--weights file", "--in file", "--manifest file",
                                                         "--out file"}, &error))) {
    return fail(timings == out ? "refusing to write --timings " + timings + ": it is also --out" : error);
  }
  if (!motor_out.empty() && (motor_out == out || motor_out == timings ||
                             !fwref::host::output_allowed(motor_out, {weights, in, manifest, out},
                                                          {"--weights file", "--in file", "--manifest file",
                                                           "--out file"}, &error))) {
    return fail(motor_out == out || motor_out == timings ? "refusing to write --motor-out " + motor_out +
                                                               ": it is also another output"
                                                         : error);
  }
  if (!manifest.empty()) {
    std::vector<unsigned char> text, wbytes;
    if (!fwref::host::read_file(manifest, "manifest", &text, &error)) return fail(error);
    if (!fwref::host::read_file(weights, "weights", &wbytes, &error)) return fail(error);
    const std::string expected = fwref::host::manifest_sha256(std::string(text.begin(), text.end()), "weights.bin");
    if (expected.empty()) return fail("manifest " + manifest + " has no sha256 for weights.bin (files.weights.bin.sha256)");
    const std::string found = fwref::host::sha256_hex(wbytes);
    if (found != expected) {
      return fail("weights " + weights + ": sha256 " + found.substr(0, 16) + "... differs from " +
                  expected.substr(0, 16) + "... recorded in " + manifest + " (files.weights.bin.sha256)");
    }
  }
  fwref::WeightsFile wf;
  if (wf.load(weights, &error) != fwref::Status::kOk) return fail(error);
  fwref::Status status;
  std::unique_ptr<fwref::host::Model> m = fwref::host::bind_model(wf, model, int8, &status, &error);
  if (!m) return fail(error);
  std::unique_ptr<fwref::host::MotorModel> mm;
  if (!motor_out.empty() && !(mm = fwref::host::bind_motor_model(wf, model, int8, &status, &error))) return fail(error);

  std::vector<unsigned char> bytes;
  if (!fwref::host::read_file(in, "input", &bytes, &error)) return fail(error);
  const std::size_t per_window = std::size_t(m->window) * m->channels;
  const std::size_t window_bytes = per_window * sizeof(float);
  if (bytes.empty() || bytes.size() % window_bytes != 0) {
    char buf[512];
    std::snprintf(buf, sizeof buf,
                  "input %s holds %zu bytes, not a whole positive number of (%d, %d) float32 windows of %zu bytes "
                  "(the weights' window and channel count)",
                  in.c_str(), bytes.size(), m->window, m->channels, window_bytes);
    return fail(buf);
  }
  const std::size_t n = bytes.size() / window_bytes;
  std::vector<float> x(n * per_window);
  std::memcpy(x.data(), bytes.data(), bytes.size());
  for (std::size_t k = 0; k < n; ++k) {
    for (std::size_t i = 0; i < per_window; ++i) {
      if (!std::isfinite(x[k * per_window + i])) {
        char buf[512];
        std::snprintf(buf, sizeof buf, "input %s: window %zu holds NaN or Inf (first at sample %zu, channel %zu)",
                      in.c_str(), k, i / m->channels, i % m->channels);
        return fail(buf);
      }
    }
  }

  std::vector<float> logits(n * m->classes);
  std::vector<float> motor(mm ? n * fwref::kMotors : 0);
  std::vector<double> seconds(timings.empty() ? 0 : n * repeat);
  for (std::size_t k = 0; k < n; ++k) {
    for (long r = 0; r < repeat; ++r) {
      const auto t0 = std::chrono::steady_clock::now();
      status = mm ? mm->run(&x[k * per_window], &logits[k * m->classes], &motor[k * fwref::kMotors])
                  : m->run(&x[k * per_window], &logits[k * m->classes]);
      const auto t1 = std::chrono::steady_clock::now();
      if (!seconds.empty()) seconds[k * repeat + r] = std::chrono::duration<double>(t1 - t0).count();
      if (status != fwref::Status::kOk) {
        return fail("window " + std::to_string(k) + " of " + in + ": " + fwref::status_name(status));
      }
    }
  }
  if (!fwref::host::write_atomic(out, logits.data(), logits.size() * sizeof(float), &error)) return fail(error);
  if (!seconds.empty() &&
      !fwref::host::write_atomic(timings, seconds.data(), seconds.size() * sizeof(double), &error)) {
    std::remove(out.c_str());
    return fail(error);
  }
  if (mm && !fwref::host::write_atomic(motor_out, motor.data(), motor.size() * sizeof(float), &error)) {
    std::remove(out.c_str());
    if (!timings.empty()) std::remove(timings.c_str());
    return fail(error);
  }
  return 0;
}
