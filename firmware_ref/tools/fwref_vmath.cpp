// tools/fwref_vmath.cpp -- scope: checks the host's fp32 vector math (fwref/vmath_f32.hpp) against the scalar code
// it replaces (bit for bit) and the gemv against its stated order and error bound, and prints what it compared.
//
//   fwref_vmath [--stride N]
//
// 1. tanh_n / logistic_n against tanh_approx / logistic_approx on: the clamp edges (+-9, +-18 and their neighbouring
//    floats), +-0, +-inf, quiet and signalling NaNs of both signs, denormals, and every N-th float32 bit pattern
//    (default 4099: about a million floats of every exponent); 8-lane vectors and scalar tails (8k + 5 values).
// 2. matvec_f32 / matvec_bias_f32 on random matrices of every column count from 1 to 140 and row counts 1..17,
//    for each kernel the CPU runs (gemv_f32_fma on an AVX2 host, gemv_f32_avx512 too on an AVX-512F one,
//    each selected in turn): bit for bit against a scalar statement of that kernel's summation order, and
//    against a double-precision sum within the order's rounding-error bound.
// 3. all_finite_n against all_finite_f32 (one inf / NaN at every position of short windows).
// 4. the int8 vector math (fwref/vmath_i8.hpp) against numerics.hpp's scalar expressions: quantize (round-half-even
//    ties, saturation bounds, NaN, the bit-pattern walk), rescale + tanh + quantize, rescale + bias, the control
//    path's per-channel work, the nonzero search (tools/fwref_vmath_i8.hpp).
// 5. the GRU's int8 step math (fwref/vmath_gru_i8.hpp) against the portable path's scalar expressions: the input
//    codes, the gates from the accumulators with the state update and its codes (tools/fwref_vmath_gru.hpp).
// 6. where the int8 kernel is avx512vnni: the CNODE int8 field in one call (fwref/field_w8_vnni.hpp) against the
//    separate steps, every H, L in 1..64 (fwref_vmath_w8.hpp); (AVX-512F) control_row_avx512, as control_row_avx2
//    where the CPU runs AVX2, against the AVX2 helpers (tools/fwref_vmath_check.hpp's check_control_row).
// 7. where the CPU runs the avx2field int8 kernel (AVX2 + FMA): the CNODE int8 field in one call on AVX2
//    (fwref/field_w16_avx2.hpp) against the separate steps, every H, L multiple of 8 up to 64, the other shapes
//    refused (tools/fwref_vmath_w16.hpp); its lin1_u rows in one call (tools/fwref_vmath_lin16.hpp).
// 8. where the CPU runs AVX2 + FMA: the fp32 CNODE field in one call on AVX2 (fwref/field_f32_avx2.hpp) against a
//    scalar statement of its order, bit for bit, and within its bound, every H, L in 1..64 (tools/fwref_vmath_f32t.hpp);
//    the control rows of its control path and its zero-padded products (tools/fwref_vmath_ctlf32.hpp).
// Prints one line per check ("tanh: 0 of N differ", tools/fwref_vmath_check.hpp's Tally) and the kernel names; exit 0
// when nothing differs, 1 otherwise.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "fwref/controls_avx2.hpp"
#include "fwref/controls_avx512.hpp"
#include "fwref/vmath_f32.hpp"
#include "fwref_vmath_check.hpp"
#include "fwref_vmath_gru.hpp"
#include "fwref_vmath_i8.hpp"
#include "fwref_vmath_ctlf32.hpp"
#include "fwref_vmath_f32t.hpp"
#include "fwref_vmath_lin16.hpp"
#include "fwref_vmath_w16.hpp"
#include "fwref_vmath_w8.hpp"

namespace {

std::vector<float> special_inputs() {
  std::vector<float> v;
  const float edges[] = {9.0f, 18.0f, 0.0f, 1.0f, 1e-20f};
  for (float e : edges) {
    for (float s : {1.0f, -1.0f}) vmath_check::push_with_neighbours(v, s * e);
  }
  for (std::uint32_t u : {0x00000000u, 0x80000000u, 0x7f800000u, 0xff800000u, 0x7fc00000u, 0xffc00000u,
                          0x7fa00001u, 0xffa00001u, 0x7fffffffu, 0x00000001u, 0x80000001u, 0x007fffffu,
                          0x807fffffu, 0x00400000u, 0x7f7fffffu, 0xff7fffffu}) {
    v.push_back(fwref::bits_float(u));
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
    if (fwref::float_bits(want) != fwref::float_bits(y[i])) {
      if (bad < 5) std::printf("  x=%a (0x%08x): vector 0x%08x, scalar 0x%08x\n", in[i], fwref::float_bits(in[i]), fwref::float_bits(y[i]), fwref::float_bits(want));
      ++bad;
    }
  }
  return bad;
}

#if defined(FWREF_GEMV_FMA)
// The order the host's gemv kernels promise (fwref/vmath_f32.hpp: 8 lanes, adjacent pairs folded;
// fwref/kernels_f32_avx512.hpp: 16 lanes, halves folded), stated one scalar operation at a time. The
// masked tail's lanes past cols meet fma(0, 0, a) as in the kernels.
float gemv_row_order(const float* w, int cols, const float* x, int lanes) {
  float a[16] = {};
  for (int j = 0; j < lanes && j < cols; ++j) a[j] = cols >= lanes ? w[j] * x[j] : std::fma(w[j], x[j], 0.0f);
  for (int i = lanes; i < cols; ++i) a[i % lanes] = std::fma(w[i], x[i], a[i % lanes]);
  if (cols % lanes != 0) {
    for (int j = cols % lanes; j < lanes; ++j) a[j] = std::fma(0.0f, 0.0f, a[j]);
  }
  if (lanes == 8) return ((a[0] + a[1]) + (a[2] + a[3])) + ((a[4] + a[5]) + (a[6] + a[7]));
  for (int half = 8; half >= 1; half /= 2) {
    for (int k = 0; k < half; ++k) a[k] = a[k] + a[k + half];
  }
  return a[0];
}
#endif

// gemv with and without a bias on random matrices of every column count 1..140 and row counts 1..17
// (the 16- and 8-row passes and the 4 / 2 / 1 remainders), rows and x unaligned as weights.bin's views
// may be, for each kernel this CPU runs (``lanes``: 8 for the AVX2 kernel, 16 for the AVX-512 one, 0
// for Eigen's product).
// order: rows whose bits differ from gemv_row_order (+ b) -- only for the FMA kernels;
// bound: rows farther from the double-precision sum than the error bound gamma(ceil(cols / lanes) + log2
// lanes) * sum |w x| (+ u |y| for the bias add); with Eigen's product the bound is gamma(cols) (any order).
struct GemvCheck {
  long compared = 0, order_compared = 0, order_bad = 0, bound_bad = 0;
  double worst = 0.0;  // largest |error| / bound seen
};

void check_gemv_one(std::mt19937& rng, int rows, int cols, bool bias, int lanes, GemvCheck& c, bool reverse = false) {
  std::normal_distribution<float> nd(0.0f, 1.0f);
  std::vector<float> w(rows * cols + 1), x(cols + 1), b(rows + 1);
  vmath_check::fill(rng, nd, w, x, b);
  const fwref::MatF m{w.data() + 1, rows, cols};
  const float* bp = bias ? b.data() + 1 : nullptr;
  Eigen::Matrix<float, Eigen::Dynamic, 1> y(rows);
#if defined(FWREF_GEMV_FMA)
  if (reverse) {
    fwref::gemv_f32_host(m.data, rows, cols, x.data() + 1, bp, y.data(), true);
  } else
#endif
  if (bias) {
    fwref::matvec_bias_f32(m, fwref::ConstMapVec(x.data() + 1, cols), bp, y);
  } else {
    fwref::matvec_f32(m, fwref::ConstMapVec(x.data() + 1, cols), y);
  }
  const double u = std::ldexp(1.0, -24);
  const double n = lanes > 0 ? (cols + lanes - 1) / lanes + (lanes == 16 ? 4 : 3) : cols;
  const double gamma = n * u / (1.0 - n * u);
  for (int o = 0; o < rows; ++o) {
    const float* r = m.data + o * cols;
    const float* xv = x.data() + 1;
    double exact = 0.0, mag = 0.0;
    for (int i = 0; i < cols; ++i) exact += double(r[i]) * xv[i], mag += std::fabs(double(r[i]) * xv[i]);
    double bound = gamma * mag;
    if (bias) exact += bp[o], bound = bound * (1.0 + u) + u * std::fabs(exact);
    const double err = std::fabs(double(y[o]) - exact);
    if (err > bound) ++c.bound_bad;
    if (bound > 0) c.worst = std::max(c.worst, err / bound);
#if defined(FWREF_GEMV_FMA)
    float want = gemv_row_order(r, cols, xv, lanes);
    if (bias) want = want + bp[o];
    if (fwref::float_bits(want) != fwref::float_bits(y[o])) {
      if (c.order_bad < 5) std::printf("  gemv %d lanes rows=%d cols=%d row %d: %a, the stated order %a\n", lanes, rows, cols, o, y[o], want);
      ++c.order_bad;
    }
    ++c.order_compared;
#endif
    ++c.compared;
  }
}

// Then matrices over 32 KiB (the AVX-512 kernel's prefetching instances), in both pass orders: a GRU
// W_hh (240 x 80), and run-time column counts with rows % 16 = 10 and 1.
constexpr int kLargeShapes[3][2] = {{240, 80}, {250, 97}, {129, 70}};
void check_gemv_kernel(int lanes, GemvCheck& c) {
  std::mt19937 rng(1234);
  for (int cols = 1; cols <= 140; ++cols) {
    for (int rows = 1; rows <= 17; ++rows) check_gemv_one(rng, rows, cols, rows % 2 == 0, lanes, c);
  }
  for (const auto& rc : kLargeShapes) {
    for (bool reverse : {false, true}) check_gemv_one(rng, rc[0], rc[1], true, lanes, c, reverse);
  }
}

// Every kernel this CPU runs, each selected in turn (the run-time choice restored after); prints
// "gemv kernels checked: NAME..." and returns the pooled counts.
GemvCheck check_gemv() {
  GemvCheck c;
  std::printf("gemv kernels checked:");
#if defined(FWREF_GEMV_FMA)
  const bool was512 = fwref::gemv_f32_avx512_active();
  for (const char* k : {"avx2", "avx512"}) {
    if (!fwref::gemv_f32_select(k)) continue;
    std::printf(" %s", fwref::matvec_f32_kernel_name());
    check_gemv_kernel(std::strcmp(k, "avx2") == 0 ? 8 : 16, c);
  }
  fwref::gemv_f32_select(was512 ? "avx512" : "avx2");
#else
  std::printf(" %s", fwref::matvec_f32_kernel_name());
  check_gemv_kernel(0, c);
#endif
  std::printf("\n");
  return c;
}

#if defined(FWREF_HAS_F32_AVX512)
// gemv_f32_t_avx512 (fwref/kernels_f32_avx512.hpp's column-major copy) on random matrices of every
// column count 1..140 and the row counts 1..20, 33, 40, 64, 65, 100: bit for bit against a scalar
// statement of its order and within its bound gamma(ceil(cols / 4) + 2) * sum |w x| (+ the bias add's u |y|).
// Returns false (nothing compared) on a CPU without AVX-512F.
bool check_gemv_t(GemvCheck& c) {
  if (!__builtin_cpu_supports("avx512f")) return false;
  std::mt19937 rng(4321);
  std::normal_distribution<float> nd(0.0f, 1.0f);
  const double u = std::ldexp(1.0, -24);
  std::vector<int> row_counts;
  for (int r = 1; r <= 20; ++r) row_counts.push_back(r);
  for (int r : {33, 40, 64, 65, 100}) row_counts.push_back(r);
  for (int cols = 1; cols <= 140; ++cols) {
    for (int rows : row_counts) {
      std::vector<float> w(rows * cols), x(cols), b(rows), y(rows + 1, 7.0f);
      vmath_check::fill(rng, nd, w, x, b);
      std::vector<float> wt_store;
      float* const wt = vmath_check::floats64(wt_store, std::size_t(cols) * fwref::f32_t_stride(rows));
      fwref::pack_f32_t(w.data(), rows, cols, wt);
      const bool bias = (rows + cols) % 2 == 0;
      fwref::gemv_f32_t_avx512(wt, rows, cols, x.data(), bias ? b.data() : nullptr, y.data());
      const double n = (cols + 3) / 4 + 2, gamma = n * u / (1.0 - n * u);
      for (int o = 0; o < rows; ++o) {
        float sp[4] = {};
        double exact = 0.0, mag = 0.0;
        for (int i = 0; i < cols; ++i) {
          const float wi = w[o * cols + i];
          sp[i % 4] = i < 4 ? wi * x[i] : std::fma(wi, x[i], sp[i % 4]);
          exact += double(wi) * x[i], mag += std::fabs(double(wi) * x[i]);
        }
        float want = (sp[0] + sp[1]) + (sp[2] + sp[3]);
        double bound = gamma * mag;
        if (bias) want = want + b[o], exact += b[o], bound = bound * (1.0 + u) + u * std::fabs(exact);
        if (fwref::float_bits(want) != fwref::float_bits(y[o])) {
          if (c.order_bad < 5) std::printf("  gemv_t rows=%d cols=%d row %d: %a, the stated order %a\n", rows, cols, o, y[o], want);
          ++c.order_bad;
        }
        const double err = std::fabs(double(y[o]) - exact);
        if (err > bound) ++c.bound_bad;
        if (bound > 0) c.worst = std::max(c.worst, err / bound);
        ++c.order_compared, ++c.compared;
      }
      if (y[rows] != 7.0f) ++c.order_bad;  // nothing written past the rows
    }
  }
  return true;
}

// field_f32_t_avx512 against its three steps (gemv_f32_t_avx512, tanh_n, gemv_f32_t_avx512) for every
// H, L in 1..64 (x in [-3, 3] so tanh's clamp is crossed too): elements whose bits differ.
long check_field_t(long* compared) {
  std::mt19937 rng(99);
  std::normal_distribution<float> nd(0.0f, 1.0f);
  long bad = 0;
  for (int H = 1; H <= 64; ++H) {
    for (int L = 1; L <= 64; ++L) {
      const vmath_check::FieldF32Case f(rng, nd, H, L);
      std::vector<float> a(H), want(L), got(L + 1, 7.0f);
      fwref::gemv_f32_t_avx512(f.t1, H, L, f.z.data(), f.v.data(), a.data());
      fwref::tanh_n(a.data(), H);
      fwref::gemv_f32_t_avx512(f.t2, L, H, a.data(), f.b2.data(), want.data());
      if (!fwref::field_f32_t_avx512(f.t1, f.t2, H, L, f.z.data(), f.v.data(), f.b2.data(), got.data())) return -1;
      for (int o = 0; o < L; ++o) bad += vmath_check::differ(want[o], got[o]);
      bad += got[L] != 7.0f;  // nothing written past k
      *compared += L;
    }
  }
  return bad;
}
#endif

// all_finite_n against all_finite_f32 on windows of every length 0..40 with one inf, -inf or NaN at
// every position (and none): the number of answers that differ.
long check_all_finite(long* compared) {
  const float bad_values[] = {std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity(),
                              std::numeric_limits<float>::quiet_NaN(), fwref::bits_float(0xffa00001u)};
  long bad = 0;
  for (int n = 0; n <= 40; ++n) {
    std::vector<float> x(n + 1);
    for (int i = 0; i < n; ++i) x[i] = i % 3 == 0 ? std::numeric_limits<float>::max() : fwref::bits_float(0x00000001u + i);
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
  for (std::uint64_t u = 0; u <= 0xffffffffull; u += stride) in.push_back(fwref::bits_float(static_cast<std::uint32_t>(u)));
  for (int i = 0; in.size() % 8 != 5; ++i) in.push_back(static_cast<float>(i) * 0.37f);  // a scalar tail
  std::printf("vmath kernel: %s\n", fwref::vmath_f32_kernel_name());
  std::printf("gemv kernel: %s\n", fwref::matvec_f32_kernel_name());
  vmath_check::Tally t;
  t.run("tanh", [&](long* n) { return *n = long(in.size()), compare(in, fwref::tanh_n, fwref::tanh_approx); });
  t.run("logistic", [&](long* n) { return *n = long(in.size()), compare(in, fwref::logistic_n, fwref::logistic_approx); });
  const GemvCheck g = check_gemv();
  std::printf("gemv order: %ld of %ld differ\n", g.order_bad, g.order_compared);  // 0 of 0: Eigen's product
  std::printf("gemv bound: %ld of %ld exceed (worst error / bound %.3f)\n", g.bound_bad, g.compared, g.worst);
  t.bad += g.order_bad + g.bound_bad;
#if defined(FWREF_HAS_F32_AVX512)
  GemvCheck gt;
  if (check_gemv_t(gt)) {
    std::printf("gemv_t order: %ld of %ld differ\n", gt.order_bad, gt.order_compared);
    std::printf("gemv_t bound: %ld of %ld exceed (worst error / bound %.3f)\n", gt.bound_bad, gt.compared, gt.worst);
    t.bad += gt.order_bad + gt.bound_bad;
    t.run("field_t", check_field_t);
  }
#endif
#if defined(FWREF_HAS_F32_FIELD_AVX2)
  long compared_f2 = 0, bound_f2 = 0;
  double worst_f2 = 0.0;
  const long bfield2 = vmath_f32t_check::check_field(&compared_f2, &bound_f2, &worst_f2);
  if (bfield2 >= 0) {
    std::printf("field_f32_avx2 order: %ld of %ld differ\n", bfield2, compared_f2);
    std::printf("field_f32_avx2 bound: %ld exceed (worst error / bound %.3f)\n", bound_f2, worst_f2);
    t.bad += bfield2 + bound_f2;
  }
#endif
  t.run("all_finite", check_all_finite);
  std::printf("vmath_i8 kernel: %s\n", fwref::vmath_i8_kernel_name());
  t.run("quantize", [&](long* n) { return vmath_i8_check::check_quantize(in, n); });
  t.run("rescale_tanh_quantize+rescale_bias", vmath_i8_check::check_rescale);
  t.run("hidden_rows", vmath_i8_check::check_hidden_rows);
  t.run("control_row", vmath_i8_check::check_control_row);
  t.run("nonzero", vmath_i8_check::check_nonzero);
#if defined(FWREF_HAS_CONTROLS_AVX2)  // the int8 control rows in registers
  t.run("control_row_avx2", [](long* n) { return vmath_check::check_control_row(fwref::control_row_avx2, n); });
#endif
#if defined(FWREF_HAS_CONTROLS_F32_AVX2)  // the fp32 control path of avx2field
  t.run("control_rows_f32_avx2", vmath_ctlf32_check::check_rows);
  t.run("gemv padded", vmath_ctlf32_check::check_padded);
#endif
  t.run("gru_input_row", vmath_gru_check::check_input_row);
  t.run("gru_gates", vmath_gru_check::check_gates);
  t.run("gru_gate_rows", vmath_gru_check::check_gate_rows);
#if defined(FWREF_HAS_W8_VNNI)
  if (t.run("field_w8", vmath_w8_check::check_field) >= 0) {  // the CPU runs AVX-512F + VNNI: its control rows too
    t.run("control_row_avx512", [](long* n) { return vmath_check::check_control_row(fwref::control_row_avx512, n); });
  }
#endif
#if defined(FWREF_HAS_FIELD_W16_AVX2)
  if (t.run("field_w16", vmath_w16_check::check_field) >= 0) {  // the CPU runs avx2field: its lin1_u rows too
    t.run("linear_w16", vmath_lin16_check::check_linear);
  }
#endif
  return t.bad == 0 ? 0 : 1;
}
