// tools/fwref_alarm.cpp -- scope: the alarm policy of fwref/alarm.hpp over recorded window
// sequences, for tests/test_stream.py to hold it against core/alarm.py:
//
//   fwref_alarm --in SEQ.f64 --out STEPS.i32 --windows W --classes K --healthy H --threshold T --k K --n N
//               --clear-m M [--latch] [--motor] [--rotor-mask BITS]
//
// SEQ.f64: flights x W windows x (valid 0/1, proba (K), motor_proba (4) with --motor) float64.
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

int main(int argc, char** argv) {
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
  std::FILE* f = std::fopen(in.c_str(), "rb");
  if (!f) return std::fprintf(stderr, "fwref_alarm: cannot open %s\n", in.c_str()), 2;
  const std::size_t per = 1 + std::size_t(p.classes) + (motor ? 4 : 0);
  std::vector<double> row(per);
  std::vector<std::int32_t> steps;
  for (long w = 0;; ++w) {
    if (std::fread(row.data(), sizeof(double), per, f) != per) break;
    if (w % windows == 0) alarm.reset();
    const fwref::AlarmStep s = alarm.step(&row[1], motor ? &row[1 + p.classes] : nullptr, row[0] != 0.0);
    for (int v : {int(s.vote), int(s.active), int(s.raised), int(s.cleared), s.cls, s.motor}) steps.push_back(v);
  }
  std::fclose(f);
  std::FILE* o = std::fopen(out.c_str(), "wb");
  if (!o) return std::fprintf(stderr, "fwref_alarm: cannot write %s\n", out.c_str()), 2;
  std::fwrite(steps.data(), sizeof(std::int32_t), steps.size(), o);
  std::fclose(o);
  return 0;
}
