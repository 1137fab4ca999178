// bench/cpp/l2bw.cpp -- scope: the read bandwidth of one core from a buffer of a given size, for
// bench/limits.py (the "stream the weights at L2 bandwidth" half of each model's floor).
//
//   l2bw <kib> <trials> [min_seconds]    -> one line per trial: "<bytes read> <seconds>"
//
// Reads a float32 buffer of <kib> KiB over and over and sums it into 8 independent 64-byte vector
// accumulators (GCC vector extensions, so the code is the same whatever the auto-vectoriser
// decides): 8 independent add chains hide the add latency, so the loads, not the adds, are the
// bottleneck. A trial repeats passes until min_seconds. Built by bench/limits.py with
// g++ -O2 -march=native (the vector type is lowered to AVX-512, AVX2 or SSE pairs as available).
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <vector>

namespace {

typedef float V16 __attribute__((vector_size(64)));
constexpr int kLanes = 8 * 16;  // floats consumed per loop iteration

float pass(const float* a, long n) {
  const V16* v = reinterpret_cast<const V16*>(a);  // a is 64-byte aligned, n a multiple of kLanes
  V16 s0 = {}, s1 = {}, s2 = {}, s3 = {}, s4 = {}, s5 = {}, s6 = {}, s7 = {};
  for (long i = 0; i < n / 16; i += 8) {
    s0 += v[i]; s1 += v[i + 1]; s2 += v[i + 2]; s3 += v[i + 3];
    s4 += v[i + 4]; s5 += v[i + 5]; s6 += v[i + 6]; s7 += v[i + 7];
  }
  const V16 s = ((s0 + s1) + (s2 + s3)) + ((s4 + s5) + (s6 + s7));
  float out = 0.0f;
  for (int j = 0; j < 16; ++j) out += s[j];
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: l2bw <kib> <trials> [min_seconds]\n");
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
  float* a = static_cast<float*>(std::aligned_alloc(64, ((n * sizeof(float) + 63) / 64) * 64));
  if (a == nullptr) return 2;
  for (long i = 0; i < n; ++i) a[i] = 1.0f + float(i % 7) * 1e-3f;
  volatile float sink = 0.0f;
  for (int w = 0; w < 3; ++w) sink = sink + pass(a, n);  // warm: page faults, the buffer in cache
  for (int t = 0; t < trials; ++t) {
    long passes = 0;
    const auto t0 = std::chrono::steady_clock::now();
    double s = 0.0;
    do {
      for (int k = 0; k < 16; ++k) sink = sink + pass(a, n);
      passes += 16;
      s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    } while (s < min_s);
    std::printf("%ld %.9f\n", long(passes * n * sizeof(float)), s);
  }
  std::free(a);
  return 0;
}
