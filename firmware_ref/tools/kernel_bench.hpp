// tools/kernel_bench.hpp -- scope: fwref_kernels --bench: the time of one int8 product of a given
// shape on each x86-64 kernel this CPU runs (the row-wise int8 kernels, the packed int16 copy on
// vpmaddwd, the packed int8 copy on vpdpbusd), to choose between them per shape. Prints
//   BENCH <rows>x<cols> <kernel> <ns> ns
// per kernel: the median over 31 trials of the mean of 20,000 back-to-back calls on random data
// (wall time: noisy on a shared machine; compare within one run).
#pragma once

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "fwref/kernels_i8.hpp"
#include "fwref/kernels_w8_vnni.hpp"

namespace kernel_bench {

#if defined(__x86_64__) && !defined(FWREF_PORTABLE_KERNELS)

template <class F>
double median_ns(F&& f) {
  std::vector<double> t;
  for (int trial = 0; trial < 31; ++trial) {
    const auto a = std::chrono::steady_clock::now();
    for (int i = 0; i < 20000; ++i) f();
    const auto b = std::chrono::steady_clock::now();
    t.push_back(std::chrono::duration<double, std::nano>(b - a).count() / 20000);
  }
  std::sort(t.begin(), t.end());
  return t[t.size() / 2];
}

inline void bench_shape(int rows, int cols) {
  std::mt19937 rng(unsigned(rows * 1000 + cols));
  std::vector<std::int8_t> w(std::size_t(rows) * cols), x(cols);
  for (auto& v : w) v = std::int8_t(int(rng() % 255) - 127);
  for (auto& v : x) v = std::int8_t(int(rng() % 256) - 128);
  std::vector<std::int16_t> w16(std::size_t(rows) * fwref::w16_stride(cols)), x16(fwref::w16_stride(cols), 0);
  fwref::expand_i8_to_i16(w.data(), rows, cols, w16.data());
  for (int i = 0; i < cols; ++i) x16[i] = x[i];
  std::vector<std::int32_t> words((fwref::w8_bytes(rows, cols) + 3) / 4);  // 4-byte aligned
  std::uint8_t* w8 = reinterpret_cast<std::uint8_t*>(words.data());
  fwref::pack_i8_w8(w.data(), rows, cols, w8);
  std::vector<std::uint8_t> xu(fwref::w8_cols(cols), 128);
  fwref::offset_codes_u8(x.data(), cols, xu.data());
  std::vector<std::int32_t> acc(rows);
  volatile std::int32_t sink = 0;
  const fwref::GemvI8Kernel* ks = nullptr;
  const int n = fwref::gemv_i8_kernels(&ks);
  for (int k = 1; k < n; ++k) {  // not the portable loop
    if (!ks[k].cpu_runs) continue;
    const double t = median_ns([&] { ks[k].fn(w.data(), rows, cols, x.data(), acc.data()), sink = sink + acc[0]; });
    std::printf("BENCH %dx%d %s %.1f ns\n", rows, cols, ks[k].name, t);
    if (k == 1) {  // the int16 copy's kernel (the same for every x86-64 instruction set: vpmaddwd)
      const double t16 = median_ns([&] { ks[k].w16(w16.data(), rows, cols, x16.data(), acc.data()), sink = sink + acc[0]; });
      std::printf("BENCH %dx%d w16:%s %.1f ns\n", rows, cols, ks[k].name, t16);
    }
    if (std::string(ks[k].name) == "avx512vnni") {
      const double t8 = median_ns([&] { fwref::gemv_w8_avx512vnni(w8, rows, cols, xu.data(), acc.data()), sink = sink + acc[0]; });
      std::printf("BENCH %dx%d w8:avx512vnni %.1f ns\n", rows, cols, t8);
    }
  }
}

#endif

}  // namespace kernel_bench
