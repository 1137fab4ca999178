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
// --manifest: weights.bin must have the sha256 export/manifest.json records for it (checked on the one read
// of weights.bin that is then parsed). --weights, --in and --manifest must be regular files within
// fwref/read_limits.hpp's maxima (64 MiB, 1 GiB, 16 MiB): a FIFO, a device or a folder is refused at once,
// and every size is checked before anything is allocated. --out and
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

const fwref::host::Cli kCli(
    "fwref_infer",
    "usage: fwref_infer --weights <weights.bin> --model cnode|gru [--int8] --in <windows.f32> --out <logits.f32> "
    "[--repeat R --timings <seconds.f64>] [--manifest <manifest.json>] [--motor-out <motor.f32>]");

}  // namespace

int main(int argc, char** argv) try {
  std::string weights, model, in, out, timings, manifest, motor_out, r;
  bool int8 = false;
  const int parsed = kCli.parse(argc, argv,
                                {{"--weights", &weights}, {"--model", &model}, {"--in", &in}, {"--out", &out},
                                 {"--timings", &timings}, {"--manifest", &manifest}, {"--motor-out", &motor_out},
                                 {"--repeat", &r}},
                                {{"--int8", &int8}});
  if (parsed >= 0) return parsed;
  long repeat = 1;
  if (!r.empty()) {
    char* end = nullptr;
    repeat = std::strtol(r.c_str(), &end, 10);
    if (*end != '\0' || repeat < 1 || repeat > 1000000) return kCli.usage_error("--repeat must be a positive integer");
  }
  if (weights.empty() || model.empty() || in.empty() || out.empty()) {
    return kCli.usage_error("--weights, --model, --in and --out are required");
  }
  if (model != "cnode" && model != "gru") {
    return kCli.usage_error("--model must be cnode or gru, found '" + model + "'");
  }

  std::string error;
  const std::vector<std::string> what = {"--weights file", "--in file", "--manifest file", "--timings file"};
  if (!fwref::host::output_allowed(out, {weights, in, manifest, timings}, what, &error)) return kCli.fail(error);
  if (!timings.empty() && (timings == out ||
                           !fwref::host::output_allowed(timings, {weights, in, manifest, out},
                                                        {"--weights file", "--in file", "--manifest file",
                                                         "--out file"}, &error))) {
    return kCli.fail(timings == out ? "refusing to write --timings " + timings + ": it is also --out" : error);
  }
  if (!motor_out.empty() && (motor_out == out || motor_out == timings ||
                             !fwref::host::output_allowed(motor_out, {weights, in, manifest, out},
                                                          {"--weights file", "--in file", "--manifest file",
                                                           "--out file"}, &error))) {
    return kCli.fail(motor_out == out || motor_out == timings ? "refusing to write --motor-out " + motor_out +
                                                               ": it is also another output"
                                                         : error);
  }
  fwref::WeightsFile wf;
  if (!fwref::host::load_weights(weights, manifest, &wf, &error)) return kCli.fail(error);
  fwref::Status status;
  std::unique_ptr<fwref::host::Model> m = fwref::host::bind_model(wf, model, int8, &status, &error);
  if (!m) return kCli.fail(error);
  std::unique_ptr<fwref::host::MotorModel> mm;
  if (!motor_out.empty() && !(mm = fwref::host::bind_motor_model(wf, model, int8, &status, &error))) {
    return kCli.fail(error);
  }

  std::vector<float> x;
  if (!fwref::host::read_windows(in, m->window, m->channels, &x, &error)) return kCli.fail(error);
  const std::size_t per_window = std::size_t(m->window) * m->channels, n = x.size() / per_window;

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
        return kCli.fail("window " + std::to_string(k) + " of " + in + ": " + fwref::status_name(status));
      }
    }
  }
  if (!fwref::host::write_atomic(out, logits.data(), logits.size() * sizeof(float), &error)) return kCli.fail(error);
  if (!seconds.empty() &&
      !fwref::host::write_atomic(timings, seconds.data(), seconds.size() * sizeof(double), &error)) {
    std::remove(out.c_str());
    return kCli.fail(error);
  }
  if (mm && !fwref::host::write_atomic(motor_out, motor.data(), motor.size() * sizeof(float), &error)) {
    std::remove(out.c_str());
    if (!timings.empty()) std::remove(timings.c_str());
    return kCli.fail(error);
  }
  return 0;
} catch (const std::exception& e) {
  return fwref::host::fail_exception("fwref_infer", e);
}
