// tools/fwref_vmath.cpp -- scope: checks the host's fp32 vector math (fwref/vmath_f32.hpp) against
// the scalar code it replaces, bit for bit, and prints what it compared.
//
//   fwref_vmath [--stride N]
//
// 1. tanh_n / logistic_n against tanh_approx / logistic_approx on: the clamp edges (+-9, +-18 and
//    their neighbouring floats), +-0, +-inf, quiet and signalling NaNs of both signs, denormals, and
//    every N-th float32 bit pattern (default 4099: about a million floats of every exponent). A
//    float's 8-lane vector and its scalar tail are both exercised (arrays of 8k + 5 values).
// 2. gemv_f32_eigen against Eigen's lazyProduct (fwref/linalg.hpp's matvec) on random matrices of
//    every column count from 1 to 140 and row counts 1..9 (the 4-row blocks and their remainders).
// 3. all_finite_n against all_finite_f32 (one inf / NaN at every position of short windows).
// 4. the int8 vector math (fwref/vmath_i8.hpp) against numerics.hpp's scalar expressions: quantize
//    (round-half-even ties, saturation bounds, NaN, the bit-pattern walk), rescale + tanh + quantize,
//    rescale + bias, the control path's per-channel work, the nonzero search (tools/fwref_vmath_i8.hpp).
// Prints one line per check ("tanh: 0 of N differ") and the kernel names; exit 0 when nothing differs,
// 1 otherwise.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "fwref/vmath_f32.hpp"
#include "fwref_vmath_i8.hpp"

namespace {

std::uint32_t bits(float f) {
  std::uint32_t u;
  std::memcpy(&u, &f, 4);
  return u;
}

float from_bits(std::uint32_t u) {
  float f;
  std::memcpy(&f, &u, 4);
  return f;
}

std::vector<float> special_inputs() {
  std::vector<float> v;
  const float edges[] = {9.0f, 18.0f, 0.0f, 1.0f, 1e-20f};
  for (float e : edges) {
    for (float s : {1.0f, -1.0f}) {
      const float x = s * e;
      v.push_back(x);
      v.push_back(std::nextafter(x, std::numeric_limits<float>::infinity()));
      v.push_back(std::nextafter(x, -std::numeric_limits<float>::infinity()));
    }
  }
  for (std::uint32_t u : {0x00000000u, 0x80000000u, 0x7f800000u, 0xff800000u, 0x7fc00000u, 0xffc00000u,
                          0x7fa00001u, 0xffa00001u, 0x7fffffffu, 0x00000001u, 0x80000001u, 0x007fffffu,
                          0x807fffffu, 0x00400000u, 0x7f7fffffu, 0xff7fffffu}) {
    v.push_back(from_bits(u));
  }
  return v;
}

// Number of elements whose bits differ between the vector and the scalar function.
template <class Vec, class Scalar>
long compare(const std::vector<float>& in, Vec vec, Scalar scalar) {
  std::vector<float> y(in);
  vec(y.data(), static_cast<int>(y.size()));
  long bad = 0;
  for (std::size_t i = 0; i < in.size(); ++i) {
    const float want = scalar(in[i]);
    if (bits(want) != bits(y[i])) {
      if (bad < 5) std::printf("  x=%a (0x%08x): vector 0x%08x, scalar 0x%08x\n", in[i], bits(in[i]), bits(y[i]), bits(want));
      ++bad;
    }
  }
  return bad;
}

long check_gemv(long* compared) {
  std::mt19937 rng(1234);
  std::normal_distribution<float> nd(0.0f, 1.0f);
  long bad = 0;
  for (int cols = 1; cols <= 140; ++cols) {
    for (int rows = 1; rows <= 9; ++rows) {
      std::vector<float> w(rows * cols + 1), x(cols + 1), y(rows);
      for (float& f : w) f = nd(rng);
      for (float& f : x) f = nd(rng);
      // offset by one float: unaligned rows and x, as weights.bin's views may be
      const fwref::MatF m{w.data() + 1, rows, cols};
      Eigen::Matrix<float, Eigen::Dynamic, 1> ref(rows);
      fwref::matvec(m, fwref::ConstMapVec(x.data() + 1, cols), ref);
      fwref::gemv_f32_eigen(m.data, rows, cols, x.data() + 1, y.data());
      for (int o = 0; o < rows; ++o) {
        if (bits(ref[o]) != bits(y[o])) {
          if (bad < 5) std::printf("  gemv rows=%d cols=%d row %d: %a vs Eigen %a\n", rows, cols, o, y[o], ref[o]);
          ++bad;
        }
      }
      *compared += rows;
    }
  }
  return bad;
}

// all_finite_n against all_finite_f32 on windows of every length 0..40 with one inf, -inf or NaN at
// every position (and none): the number of answers that differ.
long check_all_finite(long* compared) {
  const float bad_values[] = {std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(),
                              std::numeric_limits<float>::quiet_NaN(), from_bits(0xffa00001u)};
  long bad = 0;
  for (int n = 0; n <= 40; ++n) {
    std::vector<float> x(n + 1);
    for (int i = 0; i < n; ++i) x[i] = i % 3 == 0 ? std::numeric_limits<float>::max() : from_bits(0x00000001u + i);
    for (int pos = -1; pos < n; ++pos) {
      for (float v : bad_values) {
        std::vector<float> y(x);
        if (pos >= 0) y[pos] = v;
        bad += fwref::all_finite_n(y.data(), n) != fwref::all_finite_f32(y.data(), n);
        ++*compared;
        if (pos < 0) break;
      }
    }
  }
  return bad;
}

}  // namespace

int main(int argc, char** argv) {
  std::uint32_t stride = 4099;
  if (argc == 3 && std::string(argv[1]) == "--stride") {
    stride = static_cast<std::uint32_t>(std::strtoul(argv[2], nullptr, 10));
  } else if (argc != 1) {
    std::fprintf(stderr, "fwref_vmath: usage: fwref_vmath [--stride N]\n");
    return 1;
  }
  if (stride == 0) stride = 1;
  std::vector<float> in = special_inputs();
  for (std::uint64_t u = 0; u <= 0xffffffffull; u += stride) in.push_back(from_bits(static_cast<std::uint32_t>(u)));
  for (int i = 0; in.size() % 8 != 5; ++i) in.push_back(static_cast<float>(i) * 0.37f);  // a scalar tail
  std::printf("vmath kernel: %s\n", fwref::vmath_f32_kernel_name());
#if defined(FWREF_GEMV_EIGEN_ORDER)
  std::printf("gemv kernel: eigen-order-avx2-4row\n");
#else
  std::printf("gemv kernel: eigen\n");
#endif
  const long bt = compare(in, fwref::tanh_n, fwref::tanh_approx);
  std::printf("tanh: %ld of %zu differ\n", bt, in.size());
  const long bl = compare(in, fwref::logistic_n, fwref::logistic_approx);
  std::printf("logistic: %ld of %zu differ\n", bl, in.size());
  long compared = 0;
  const long bg = check_gemv(&compared);
  std::printf("gemv: %ld of %ld differ\n", bg, compared);
  long compared_f = 0;
  const long bf = check_all_finite(&compared_f);
  std::printf("all_finite: %ld of %ld differ\n", bf, compared_f);
  std::printf("vmath_i8 kernel: %s\n", fwref::vmath_i8_kernel_name());
  long bad_i8 = 0;
  const auto report = [&](const char* name, long (*check)(long*)) {
    long n = 0;
    const long b = check(&n);
    std::printf("%s: %ld of %ld differ\n", name, b, n);
    bad_i8 += b;
  };
  long compared_q = 0;
  const long bq = vmath_i8_check::check_quantize(in, &compared_q);
  std::printf("quantize: %ld of %ld differ\n", bq, compared_q);
  bad_i8 += bq;
  report("rescale_tanh_quantize+rescale_bias", vmath_i8_check::check_rescale);
  report("hidden_rows", vmath_i8_check::check_hidden_rows);
  report("control_row", vmath_i8_check::check_control_row);
  report("nonzero", vmath_i8_check::check_nonzero);
  return bt == 0 && bl == 0 && bg == 0 && bf == 0 && bad_i8 == 0 ? 0 : 1;
}
