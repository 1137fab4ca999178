// tools/fwref_alarm.cpp -- scope: the alarm policy of fwref/alarm.hpp over recorded window
// sequences, for tests/test_stream.py to hold it against core/alarm.py:
//
//   fwref_alarm --in SEQ.f64 --out STEPS.i32 --windows W --classes K --healthy H --threshold T --k K --n N
//               --clear-m M [--latch] [--motor] [--rotor-mask BITS]
//
// SEQ.f64: flights x W windows x (valid 0/1, proba (K), motor_proba (4) with --motor) float64, whole rows, a
// regular file of at most limits::kToolInputBytes; STEPS.i32 written through a temp file, never over SEQ.f64.
// STEPS.i32: per window vote, active, raised, cleared, cls, motor (int32). Each flight starts reset.
// --rotor-mask: AlarmParams::rotor_mask (bit c: class c is rotor-side, core.alarm rule 5; decimal or
// 0x hex; default every bit, rule 4 alone): motor is the reported motor, -1 for other classes.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "fwref/alarm.hpp"
#include "host_common.hpp"
#include "host_files.hpp"

int main(int argc, char** argv) try {
  std::string in, out;
  fwref::AlarmParams p{0.5, 2, 3, 3, false, 0, 0};
  long windows = 0;
  bool motor = false;
  for (int a = 1; a < argc; ++a) {
    const std::string k = argv[a];
    if (k == "--latch") { p.latch = true; continue; }
    if (k == "--motor") { motor = true; continue; }
    if (a + 1 >= argc) return std::fprintf(stderr, "fwref_alarm: %s needs a value\n", k.c_str()), 1;
    const char* v = argv[++a];
    if (k == "--in") in = v;
    else if (k == "--out") out = v;
    else if (k == "--windows") windows = std::atol(v);
    else if (k == "--classes") p.classes = std::atoi(v);
    else if (k == "--healthy") p.healthy = std::atoi(v);
    else if (k == "--threshold") p.threshold = std::strtod(v, nullptr);
    else if (k == "--k") p.k = std::atoi(v);
    else if (k == "--n") p.n = std::atoi(v);
    else if (k == "--clear-m") p.clear_m = std::atoi(v);
    else if (k == "--rotor-mask") {
      char* end = nullptr;
      const unsigned long long mask = std::strtoull(v, &end, 0);
      if (end == v || *end != '\0' || mask > 0xFFFFFFFFull) {
        return std::fprintf(stderr, "fwref_alarm: --rotor-mask must be a 32-bit unsigned integer\n"), 1;
      }
      p.rotor_mask = static_cast<std::uint32_t>(mask);
    }
    else return std::fprintf(stderr, "fwref_alarm: unknown argument %s\n", k.c_str()), 1;
  }
  static fwref::AlarmPolicy<64, 16> alarm;
  if (in.empty() || out.empty() || windows <= 0 || !alarm.configure(p)) {
    return std::fprintf(stderr, "fwref_alarm: bad arguments or policy\n"), 2;
  }
  std::string error;
  if (!fwref::host::output_allowed(out, {in}, {"--in file"}, &error)) {
    return std::fprintf(stderr, "fwref_alarm: error: %s\n", error.c_str()), 2;
  }
  std::vector<unsigned char> bytes;
  if (!fwref::host::read_file(in, "input", fwref::limits::kToolInputBytes, &bytes, &error)) {
    return std::fprintf(stderr, "fwref_alarm: error: %s\n", error.c_str()), 2;
  }
  const std::size_t per = 1 + std::size_t(p.classes) + (motor ? 4 : 0);
  if (bytes.size() % (per * sizeof(double)) != 0) {
    return std::fprintf(stderr, "fwref_alarm: error: input %s is not whole rows of %zu float64\n", in.c_str(), per), 2;
  }
  const std::size_t rows = bytes.size() / (per * sizeof(double));
  std::vector<double> row(per);
  std::vector<std::int32_t> steps;
  steps.reserve(rows * 6);
  for (std::size_t w = 0; w < rows; ++w) {
    std::memcpy(row.data(), bytes.data() + w * per * sizeof(double), per * sizeof(double));
    if (w % std::size_t(windows) == 0) alarm.reset();
    const fwref::AlarmStep s = alarm.step(&row[1], motor ? &row[1 + p.classes] : nullptr, row[0] != 0.0);
    for (int v : {int(s.vote), int(s.active), int(s.raised), int(s.cleared), s.cls, s.motor}) steps.push_back(v);
  }
  if (!fwref::host::write_atomic(out, steps.data(), steps.size() * sizeof(std::int32_t), &error)) {
    return std::fprintf(stderr, "fwref_alarm: error: %s\n", error.c_str()), 2;
  }
  return 0;
} catch (const std::exception& e) {
  return fwref::host::fail_exception("fwref_alarm", e);
}
