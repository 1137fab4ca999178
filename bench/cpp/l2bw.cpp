// bench/cpp/l2bw.cpp -- scope: one core's read bandwidth from a buffer of a given size (L1, L2) and
// its float32 FMA peak, for bench/limits.py (the two halves of each model's floor).
//
//   l2bw <kib> <trials> [min_seconds]    -> one line per trial: "<bytes read> <seconds>"
//   l2bw --fma <trials> [min_seconds]    -> one line per trial: "<flops> <seconds>"
//
// VEC_BYTES (16, 32 or 64: SSE, AVX2, AVX-512) is the width of the vector type, chosen by
// bench/limits.py for the host's ISA and given with -DVEC_BYTES=...: a 64-byte vector on an
// AVX2-only CPU is lowered to register pairs that spill to the stack (measured: 15.6 GB/s whatever
// the buffer size, against 62 GB/s for a plain 8-register AVX2 loop). bench/limits.py checks the
// compiled inner loops with objdump: vector registers of the intended width, no stack access.
//
// Read: 8 independent accumulators (8 registers; AVX2 has 16, AVX-512 32) hide the add latency,
// so the loads, not the adds, are the bottleneck. FMA: 10 independent chains of v = v * a + b
// (FMA latency 4-5 cycles, 2 ports: 8-10 chains in flight saturate them). A trial repeats passes
// until min_seconds; bench/limits.py keeps the best trial.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>

#ifndef VEC_BYTES
#define VEC_BYTES 32
#endif

typedef float V __attribute__((vector_size(VEC_BYTES)));
constexpr int kVecFloats = VEC_BYTES / 4;
constexpr int kLanes = 8 * kVecFloats;  // floats consumed per loop iteration

extern "C" __attribute__((noinline)) float l2bw_read_pass(const float* a, long n) {
  const V* v = reinterpret_cast<const V*>(a);  // a is 64-byte aligned, n a multiple of kLanes
  V s0 = {}, s1 = {}, s2 = {}, s3 = {}, s4 = {}, s5 = {}, s6 = {}, s7 = {};
  for (long i = 0; i < n / kVecFloats; i += 8) {
    s0 += v[i]; s1 += v[i + 1]; s2 += v[i + 2]; s3 += v[i + 3];
    s4 += v[i + 4]; s5 += v[i + 5]; s6 += v[i + 6]; s7 += v[i + 7];
  }
  const V s = ((s0 + s1) + (s2 + s3)) + ((s4 + s5) + (s6 + s7));
  float out = 0.0f;
  for (int j = 0; j < kVecFloats; ++j) out += s[j];
  return out;
}

constexpr int kChains = 10;
constexpr long kFmaIters = 1 << 16;

// kChains * kFmaIters vector FMAs: 2 * kVecFloats flops each.
extern "C" __attribute__((noinline)) float l2bw_fma_kernel(float seed) {
  // Whole-vector broadcasts, not lane-by-lane stores: with -march=native on AVX-512 Intel parts GCC
  // tunes for 256-bit vectors (-mprefer-vector-width=256), so a lane loop filled the 64-byte b with
  // two 32-byte stores and the hot loop then read b from the stack in every FMA.
  const V a = V{} + 0.999f;
  const V b = V{} + 1e-3f * seed;
  V c[kChains];
  for (int k = 0; k < kChains; ++k) c[k] = a * float(k + 1);
  for (long i = 0; i < kFmaIters; ++i) {
#pragma GCC unroll 16
    for (int k = 0; k < kChains; ++k) c[k] = c[k] * a + b;  // one FMA with -mfma/-march=native
  }
  V s = c[0];
  for (int k = 1; k < kChains; ++k) s += c[k];
  float out = 0.0f;
  for (int j = 0; j < kVecFloats; ++j) out += s[j];
  return out;
}

namespace {

int run_fma(int trials, double min_s) {
  volatile float sink = 0.0f;
  sink = sink + l2bw_fma_kernel(1.0f);
  const double flops_per_call = 2.0 * kVecFloats * kChains * double(kFmaIters);
  for (int t = 0; t < trials; ++t) {
    long calls = 0;
    const auto t0 = std::chrono::steady_clock::now();
    double s = 0.0;
    do {
      for (int k = 0; k < 8; ++k) sink = sink + l2bw_fma_kernel(1.0f + float(k));
      calls += 8;
      s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    } while (s < min_s);
    std::printf("%.0f %.9f\n", flops_per_call * double(calls), s);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc >= 2 && std::strcmp(argv[1], "--fma") == 0) {
    const int trials = argc > 2 ? std::atoi(argv[2]) : 5;
    const double min_s = argc > 3 ? std::atof(argv[3]) : 0.05;
    if (trials < 1 || !(min_s > 0)) {
      std::fprintf(stderr, "l2bw: trials must be positive\n");
      return 1;
    }
    return run_fma(trials, min_s);
  }
  if (argc < 3) {
    std::fprintf(stderr, "usage: l2bw <kib> <trials> [min_seconds] | l2bw --fma <trials> [min_seconds]\n");
    return 1;
  }
  const long kib = std::atol(argv[1]);
  const int trials = std::atoi(argv[2]);
  const double min_s = argc > 3 ? std::atof(argv[3]) : 0.05;
  if (kib < 1 || trials < 1 || !(min_s > 0)) {
    std::fprintf(stderr, "l2bw: kib and trials must be positive\n");
    return 1;
  }
  long n = kib * 1024 / sizeof(float);
  n -= n % kLanes;
  if (n < kLanes) n = kLanes;
  float* a = static_cast<float*>(std::aligned_alloc(64, ((n * sizeof(float) + 63) / 64) * 64));
  if (a == nullptr) return 2;
  for (long i = 0; i < n; ++i) a[i] = 1.0f + float(i % 7) * 1e-3f;
  volatile float sink = 0.0f;
  for (int w = 0; w < 3; ++w) sink = sink + l2bw_read_pass(a, n);  // warm: page faults, the buffer in cache
  for (int t = 0; t < trials; ++t) {
    long passes = 0;
    const auto t0 = std::chrono::steady_clock::now();
    double s = 0.0;
    do {
      for (int k = 0; k < 16; ++k) sink = sink + l2bw_read_pass(a, n);
      passes += 16;
      s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    } while (s < min_s);
    std::printf("%ld %.9f\n", long(passes * n * sizeof(float)), s);
  }
  std::free(a);
  return 0;
}
