// tools/fwref_tanhq.cpp -- scope: generates and proves fwref/tanhq_table.hpp, the table behind
// fwref/tanhq.hpp's tanh_quantize_bound(a) == quantize(tanh_approx(a), f32(1/127)) (the CNODE's
// hidden layer; docs/firmware.md):
//
//   fwref_tanhq > firmware_ref/include/fwref/tanhq_table.hpp     generate (walks every float in [0, 9])
//   fwref_tanhq --check                                          prove the compiled-in table: exit 0 iff
//                                                                tanh_quantize_bound equals the direct
//                                                                computation on every float in [-9, 9]
//                                                                (and +-inf, NaN, beyond the clamp)
//
// q(a) is not monotone in float32 (the rational approximation wiggles by an ulp: on this function 34
// floats near a rounding boundary step back by one code), so the table holds two boundaries per code
// k: F[k], the first float a >= 0 with q(a) >= k, and L[k], the first float from which q >= k for
// good. Sorted, they make kTanhqBoundary; c = #{boundaries <= bits(a)} is even (2k: q = k exactly)
// outside the narrow [F[k], L[k]) zones and odd inside one, where the direct computation runs.
// q(-a) = -q(a) exactly (tanh_approx is odd: symmetric clamp, odd numerator, even denominator; x / s
// and round-half-even are symmetric), so only a >= 0 is tabulated.
#include <algorithm>
#include <atomic>
#include <cinttypes>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <thread>
#include <vector>

#include "fwref/numerics.hpp"

#if __has_include("fwref/tanhq_table.hpp")
#include "fwref/tanhq.hpp"
#define FWREF_HAVE_TANHQ 1
#endif

namespace {

constexpr int kShift = 15;  // 8 mantissa bits per bucket

int direct(float a) { return fwref::quantize(fwref::tanh_approx(a), 1.0f / 127.0f); }

// The float range split into chunks scanned on every core (the scan and the check each walk about
// 1e9 floats: a minute of one core). Chunks are merged in order, so the output does not depend on
// the number of threads.
template <class Fn>
void parallel_chunks(std::size_t n_chunks, Fn fn) {
  std::atomic<std::size_t> next{0};
  const unsigned n_threads = std::max(1u, std::thread::hardware_concurrency());
  std::vector<std::thread> pool;
  for (unsigned t = 0; t < n_threads; ++t) {
    pool.emplace_back([&] {
      for (std::size_t c = next++; c < n_chunks; c = next++) fn(c);
    });
  }
  for (auto& th : pool) th.join();
}

constexpr std::size_t kChunks = 64;

std::uint32_t chunk_lo(std::uint32_t end, std::size_t c) {  // chunk c covers [lo(c), lo(c + 1))
  return static_cast<std::uint32_t>((static_cast<std::uint64_t>(end) + 1) * c / kChunks);
}

// One chunk [lo, hi) of the generator's walk: per code k, the first float with q >= k, and the last
// float with q < k after that one within the chunk (a step back below k).
struct Scan {
  std::uint32_t first[128] = {}, after[128] = {};
  bool has_first[128] = {}, has_after[128] = {};
  bool negative = false;
  std::uint32_t negative_at = 0;
  int qmax = 0;
};

void scan(std::uint32_t lo, std::uint32_t hi, Scan& s) {
  for (std::uint32_t b = lo; b < hi; ++b) {
    const int q = direct(fwref::bits_float(b));
    if (q < 0) {
      if (!s.negative) s.negative = true, s.negative_at = b;
      continue;
    }
    for (int k = s.qmax + 1; k <= q; ++k) s.first[k] = b, s.has_first[k] = true;
    s.qmax = q > s.qmax ? q : s.qmax;
    for (int k = q + 1; k <= s.qmax; ++k) s.after[k] = b, s.has_after[k] = true;
  }
}

int generate() {
  const std::uint32_t end = fwref::float_bits(9.0f);
  std::vector<Scan> scans(kChunks);
  parallel_chunks(kChunks, [&](std::size_t c) { scan(chunk_lo(end, c), chunk_lo(end, c + 1), scans[c]); });
  // Merge in order: F[k] from the first chunk that reaches k; L[k] - 1 from the last chunk that has
  // a float with q < k after F[k] (in a chunk after F[k]'s, every float before its own first >= k).
  std::vector<std::uint32_t> first(128, 0), last_below(128, 0);
  std::vector<bool> seen(128, false), below(128, false);
  int qmax = 0;
  for (std::size_t c = 0; c < kChunks; ++c) {
    const Scan& s = scans[c];
    const std::uint32_t lo = chunk_lo(end, c), hi = chunk_lo(end, c + 1);
    if (s.negative) return std::fprintf(stderr, "fwref_tanhq: q(%a) < 0\n", fwref::bits_float(s.negative_at)), 1;
    if (lo == hi) continue;
    for (int k = 1; k <= 127; ++k) {
      if (seen[k]) {
        if (s.has_after[k]) {
          last_below[k] = s.after[k], below[k] = true;
        } else if (!s.has_first[k]) {
          last_below[k] = hi - 1, below[k] = true;
        } else if (s.first[k] > lo) {
          last_below[k] = s.first[k] - 1, below[k] = true;
        }
      } else if (s.has_first[k]) {
        first[k] = s.first[k], seen[k] = true;
        if (s.has_after[k]) last_below[k] = s.after[k], below[k] = true;
      }
    }
    qmax = s.qmax > qmax ? s.qmax : qmax;
  }
  if (qmax != 127 || direct(9.0f) != 127) return std::fprintf(stderr, "fwref_tanhq: q(9) != 127\n"), 1;
  std::vector<std::uint32_t> bnd;
  for (int k = 1; k <= 127; ++k) {
    const std::uint32_t l = below[k] ? last_below[k] + 1 : first[k];
    if (!bnd.empty() && first[k] < bnd.back()) {
      return std::fprintf(stderr, "fwref_tanhq: the zones of codes %d and %d overlap\n", k - 1, k), 1;
    }
    bnd.push_back(first[k]);
    bnd.push_back(l);
  }
  const std::uint32_t lo = bnd.front() >> kShift, hi = bnd.back() >> kShift;
  std::vector<int> base;
  int per = 0;
  for (std::uint32_t j = lo; j <= hi; ++j) {
    int c0 = 0, inside = 0;
    for (std::uint32_t v : bnd) {
      if (v <= (j << kShift)) ++c0;
      else if (v < ((j + 1) << kShift)) ++inside;
    }
    base.push_back(c0);
    per = inside > per ? inside : per;
  }
  std::printf("// fwref/tanhq_table.hpp -- GENERATED by firmware_ref/tools/fwref_tanhq.cpp (do not edit); proved\n"
              "// by `fwref_tanhq --check` (tests/test_firmware.py). Used by fwref/tanhq.hpp.\n"
              "#pragma once\n\n#include <cstdint>\n\nnamespace fwref {\nnamespace tanhq {\n\n");
  std::printf("constexpr int kShift = %d;\nconstexpr std::uint32_t kFirstBucket = %" PRIu32 "u;\n"
              "constexpr std::uint32_t kLastBucket = %" PRIu32 "u;\nconstexpr int kPerBucket = %d;  "
              "// most boundaries inside one bucket\nconstexpr int kBoundaries = %zu;\n\n",
              kShift, lo, hi, per, bnd.size());
  std::printf("// sorted boundaries F[1], L[1], ..., F[127], L[127] (float bits), then %d x ~0u of padding\n"
              "constexpr std::uint32_t kBoundary[%zu] = {", per, bnd.size() + per);
  for (std::size_t k = 0; k < bnd.size() + per; ++k) {
    std::printf("%s0x%08" PRIx32 "u,", k % 6 == 0 ? "\n    " : " ", k < bnd.size() ? bnd[k] : 0xffffffffu);
  }
  std::printf("\n};\n\n// kBase[j - kFirstBucket]: boundaries <= the first float of bucket j (bits >> kShift)\n"
              "constexpr std::uint8_t kBase[%zu] = {", base.size());
  for (std::size_t j = 0; j < base.size(); ++j) std::printf("%s%d,", j % 20 == 0 ? "\n    " : " ", base[j]);
  std::printf("\n};\n\n}  // namespace tanhq\n}  // namespace fwref\n");
  return 0;
}

int check() {
#ifdef FWREF_HAVE_TANHQ
  const std::uint32_t end = fwref::float_bits(9.5f);
  struct Count {
    std::uint64_t n = 0, fallback = 0;
    bool bad = false;
    float at = 0.0f;
  };
  std::vector<Count> counts(kChunks);
  parallel_chunks(kChunks, [&](std::size_t c) {
    Count& r = counts[c];
    const std::uint32_t hi = c + 1 == kChunks ? end + 1 : chunk_lo(end, c + 1);
    for (std::uint32_t b = chunk_lo(end, c); b < hi && !r.bad; ++b) {
      for (const float a : {fwref::bits_float(b), -fwref::bits_float(b)}) {
        ++r.n;
        if (fwref::tanh_quantize_bound(a) != direct(a)) r.bad = true, r.at = a;
      }
      r.fallback += fwref::tanhq::needs_direct(b) ? 1 : 0;
    }
  });
  std::uint64_t n = 0, fallback = 0;
  for (const Count& r : counts) {
    if (r.bad) {
      return std::fprintf(stderr, "fwref_tanhq: table %d != direct %d at %a\n", fwref::tanh_quantize_bound(r.at),
                          direct(r.at), r.at), 1;
    }
    n += r.n, fallback += r.fallback;
  }
  const float special[] = {1e30f, -1e30f, fwref::bits_float(0x7f800000u), fwref::bits_float(0xff800000u), fwref::bits_float(0x7fc00000u)};
  for (const float a : special) {
    if (fwref::tanh_quantize_bound(a) != direct(a)) return std::fprintf(stderr, "fwref_tanhq: differs at %a\n", a), 1;
  }
  std::printf("tanhq check: OK, %" PRIu64 " floats, %" PRIu64 " in the direct zones\n", n, 2 * fallback);
  return 0;
#else
  std::fprintf(stderr, "fwref_tanhq: built without fwref/tanhq_table.hpp\n");
  return 1;
#endif
}

}  // namespace

int main(int argc, char** argv) {
  if (argc == 2 && std::strcmp(argv[1], "--check") == 0) return check();
  if (argc == 1) return generate();
  std::fprintf(stderr, "usage: fwref_tanhq [--check]\n");
  return 1;
}
