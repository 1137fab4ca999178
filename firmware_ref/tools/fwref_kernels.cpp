// tools/fwref_kernels.cpp -- scope: the int8 kernels of fwref/kernels_i8.hpp on this machine.
//
//   fwref_kernels --info                    which kernel runs, which ones the CPU runs, the fp32 build's ISA
//   fwref_kernels --check [--kernel NAME]   every kernel the CPU runs (or NAME) against the portable
//                                           loop: the same int32 accumulators on random and extreme data
//   fwref_kernels --bench                   x86-64: ns per product on each kernel the CPU runs, for the
//                                           paper models' shapes (tools/kernel_bench.hpp; exit 3 elsewhere)
//
// --info lines (key: value): cpu_flags, fp32_build, int8_kernel (the dispatched one), int8_kernels
// (name=runs|no for each kernel this build has), gru_int8_products and cnode_int8_products (the host
// models' packed copies: w8 on vpdpbusd, w16 on vpmaddwd, portable the reference path). Besides each kernel, --check runs its packed
// int16 path (w16:NAME) and, for avx512vnni and portable, the packed int8 one (w8:NAME). --check prints one line per kernel,
//   CHECK <name> cases=<n> mismatches=<m> OK|NOT_OK
// and exits 0 when all match, 1 on a mismatch, 3 when NAME is unknown or the CPU cannot run it.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "fwref/kernels_i8.hpp"
#include "fwref/kernels_w8_vnni.hpp"
#include "kernel_bench.hpp"
#include "kernel_info.hpp"

namespace {

#if defined(__x86_64__) && !defined(FWREF_PORTABLE_KERNELS)
constexpr bool kDispatch = true;
#else
constexpr bool kDispatch = false;
#endif

using Fn = void (*)(const std::int8_t*, int, int, const std::int8_t*, std::int32_t*);

// Random shapes (every column count 1..100 and a few long ones, row counts around the 4-row blocks
// and the w8 kernel's 16-row blocks, panels of 1..4 blocks and tails), uniform values, and the
// extremes: x = -128 everywhere against w = +-127 (the largest pair sums of the sign trick),
// alternating signs, zeros.
template <class F>
long check_kernel(F fn, unsigned seed, long* cases) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> ux(-128, 127), uw(-127, 127);
  long bad = 0;
  *cases = 0;
  std::vector<int> col_counts;
  for (int c = 1; c <= 100; ++c) col_counts.push_back(c);
  for (int c : {127, 128, 129, 200, 255, 256}) {
    if (c <= fwref::kMaxGemvCols) col_counts.push_back(c);
  }
  const int row_counts[] = {1, 2, 3, 4, 5, 7, 8, 9, 13, 16, 24, 32, 40, 56, 64, 240};
  for (int cols : col_counts) {
    for (int rows : row_counts) {
      for (int pattern = 0; pattern < 5; ++pattern) {
        // exact-size allocations, so an out-of-bounds read shows under the sanitizer build
        std::vector<std::int8_t> w(std::size_t(rows) * cols), x(cols);
        for (int i = 0; i < cols; ++i) {
          x[i] = std::int8_t(pattern == 0 ? ux(rng) : pattern == 1 ? -128 : pattern == 2 ? (i % 2 ? 127 : -128)
                                                    : pattern == 3 ? 127 : (i % 3 ? 0 : -128));
        }
        for (std::size_t i = 0; i < w.size(); ++i) {
          w[i] = std::int8_t(pattern == 0 ? uw(rng) : pattern == 1 ? (i % 5 == 4 ? 127 : -127)
                                                    : pattern == 2 ? (i % 2 ? 127 : -127) : pattern == 3 ? 127 : uw(rng));
        }
        std::vector<std::int32_t> want(rows), got(rows, 0x5a5a5a5a);
        fwref::gemv_i8_portable(w.data(), rows, cols, x.data(), want.data());
        fn(w.data(), rows, cols, x.data(), got.data());
        ++*cases;
        if (want != got) {
          if (bad < 5) std::fprintf(stderr, "mismatch: rows=%d cols=%d pattern=%d\n", rows, cols, pattern);
          ++bad;
        }
      }
    }
  }
  return bad;
}

#if defined(FWREF_HAS_W16_KERNEL) && defined(__x86_64__) && !defined(FWREF_PORTABLE_KERNELS)
// The packed int16 path as an int8 kernel: expand the weights (fwref/kernels_i8.hpp's layout) and
// widen x into exact-size blocks (rows * w16_stride(cols), w16_stride(cols)), then the int16 kernel.
struct W16AsI8 {
  fwref::GemvW16Fn w16;
  void operator()(const std::int8_t* w, int rows, int cols, const std::int8_t* x, std::int32_t* acc) const {
    const int stride = fwref::w16_stride(cols);
    std::vector<std::int16_t> wp(std::size_t(rows) * stride), x16(stride, 0);
    fwref::expand_i8_to_i16(w, rows, cols, wp.data());
    for (int i = 0; i < cols; ++i) x16[i] = x[i];
    w16(wp.data(), rows, cols, x16.data(), acc);
  }
};
#endif

#if defined(FWREF_HAS_W8_VNNI)
// The packed int8 copy for vpdpbusd (fwref/kernels_w8_vnni.hpp) as an int8 kernel: pack the weights and
// offset x into exact-size blocks (w8_bytes(rows, cols), w8_cols(cols)), then the w8 kernel.
struct W8AsI8 {
  fwref::GemvW8Fn w8;
  void operator()(const std::int8_t* w, int rows, int cols, const std::int8_t* x, std::int32_t* acc) const {
    std::vector<std::int32_t> words((fwref::w8_bytes(rows, cols) + 3) / 4);  // 4-byte aligned
    std::uint8_t* wp = reinterpret_cast<std::uint8_t*>(words.data());
    std::vector<std::uint8_t> xu(fwref::w8_cols(cols), 128);
    fwref::pack_i8_w8(w, rows, cols, wp);
    fwref::offset_codes_u8(x, cols, xu.data());
    w8(wp, rows, cols, xu.data(), acc);
  }
};
#endif

// --bench: the GRU's W_ih (3H, C) and W_hh (3H, H) and the CNODE's lin1_z (H, L) and lin2 (L, H) at the
// paper sizes (C = 23, H = 80; L = 40, H = 64).
int run_bench() {
#if defined(__x86_64__) && !defined(FWREF_PORTABLE_KERNELS)
  std::printf("int8_kernel: %s\n", fwref::gemv_i8_kernel_name());
  const int shapes[][2] = {{240, 23}, {240, 80}, {64, 40}, {40, 64}};
  for (const auto& s : shapes) kernel_bench::bench_shape(s[0], s[1]);
  return 0;
#else
  std::printf("BENCH unavailable (x86-64 kernels only)\n");
  return 3;
#endif
}

}  // namespace

int main(int argc, char** argv) {
  bool info = false, check = false, bench = false;
  std::string only;
  unsigned seed = 12345;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--info") {
      info = true;
    } else if (a == "--check") {
      check = true;
    } else if (a == "--bench") {
      bench = true;
    } else if (a == "--kernel" && i + 1 < argc) {
      only = argv[++i];
    } else if (a == "--seed" && i + 1 < argc) {
      seed = unsigned(std::strtoul(argv[++i], nullptr, 10));
    } else {
      std::fprintf(stderr, "usage: fwref_kernels --info | --check [--kernel NAME] [--seed S] | --bench\n");
      return 1;
    }
  }
  if (bench) return run_bench();
  if (!info && !check) info = true;
  if (info) fwref::host::print_kernel_info(stdout);
  if (!check) return 0;
  int failed = 0, ran = 0;
#if defined(__x86_64__) && !defined(FWREF_PORTABLE_KERNELS)
  const fwref::GemvI8Kernel* ks = nullptr;
  const int n = fwref::gemv_i8_kernels(&ks);
  for (int k = 0; k < n; ++k) {
    if (!only.empty() && only != ks[k].name) continue;
    if (!ks[k].cpu_runs) {
      if (!only.empty()) {
        std::printf("CHECK %s cpu-cannot-run\n", ks[k].name);
        return 3;
      }
      continue;
    }
    long cases = 0;
    const long bad = check_kernel(ks[k].fn, seed, &cases);
    std::printf("CHECK %s cases=%ld mismatches=%ld %s\n", ks[k].name, cases, bad, bad ? "NOT_OK" : "OK");
    failed += bad ? 1 : 0;
    ++ran;
#if defined(FWREF_HAS_W16_KERNEL)
    const long bad16 = check_kernel(W16AsI8{ks[k].w16}, seed + 2, &cases);  // its packed int16 path
    std::printf("CHECK w16:%s cases=%ld mismatches=%ld %s\n", ks[k].name, cases, bad16, bad16 ? "NOT_OK" : "OK");
    failed += bad16 ? 1 : 0;
#endif
#if defined(FWREF_HAS_W8_VNNI)
    // the packed int8 copy's kernel where this instruction set has one (its layout's reference with portable)
    const bool vnni = std::strcmp(ks[k].name, "avx512vnni") == 0, portable = std::strcmp(ks[k].name, "portable") == 0;
    if (vnni || portable) {
      const long bad8 = check_kernel(W8AsI8{vnni ? fwref::gemv_w8_avx512vnni : fwref::gemv_w8_portable}, seed + 3, &cases);
      std::printf("CHECK w8:%s cases=%ld mismatches=%ld %s\n", ks[k].name, cases, bad8, bad8 ? "NOT_OK" : "OK");
      failed += bad8 ? 1 : 0;
    }
#endif
  }
  // and the dispatched entry point itself
  if (only.empty()) {
    long cases = 0;
    const long bad = check_kernel(fwref::gemv_i8, seed + 1, &cases);
    std::printf("CHECK dispatched:%s cases=%ld mismatches=%ld %s\n", fwref::gemv_i8_kernel_name(), cases, bad,
                bad ? "NOT_OK" : "OK");
    failed += bad ? 1 : 0;
    ++ran;
  }
#else
  (void)kDispatch;
  if (only.empty() || only == fwref::gemv_i8_kernel_name()) {
    long cases = 0;
    const long bad = check_kernel(fwref::gemv_i8, seed, &cases);
    std::printf("CHECK %s cases=%ld mismatches=%ld %s\n", fwref::gemv_i8_kernel_name(), cases, bad,
                bad ? "NOT_OK" : "OK");
    failed += bad ? 1 : 0;
    ++ran;
  }
#endif
  if (ran == 0) {
    std::printf("CHECK %s unknown-kernel\n", only.c_str());
    return 3;
  }
  return failed ? 1 : 0;
}
