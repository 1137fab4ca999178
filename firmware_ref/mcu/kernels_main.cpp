// mcu/kernels_main.cpp -- scope: the QEMU check of the Cortex-M matrix-vector kernels on shapes the
// models do not have: every row count 1..13 (the tails of the 4-row passes: rows % 4 = 1, 2, 3) and
// column counts around the 4- and 8-column steps, each against its portable reference:
//   gemv_i8 (int8 weights, SXTB16 + SMLAD)         == gemv_i8_portable, exactly;
//   gemv_i8_x2 (two vectors per pass)              == gemv_i8_portable of each, exactly;
//   expand_i8_to_i16 + gemv_w16_x16 / gemv_i8w16   == gemv_i8_portable, exactly (int16 copies);
//   gemv_f32 (VLDM + VMLA.F32)                     == gemv_f32_portable, bit for bit;
//   all_finite_f32 (VMLA of x * 0)                 == std::isfinite on every value.
// Prints "KERNELS PASS cases=<n>" (or the first failing case) over semihosting; exit 0 or 1.
#include <cstdint>
#include <cstring>

#include "board.hpp"
#include "fwref/kernels_f32.hpp"
#include "fwref/kernels_i8.hpp"
#include "fwref/kernels_i8_x2.hpp"

namespace {

constexpr int kRows = 13;
constexpr int kCols = fwref::kMaxGemvCols < 41 ? fwref::kMaxGemvCols : 41;

std::uint32_t g_seed = 12345u;
std::uint32_t next() {
  g_seed = g_seed * 1664525u + 1013904223u;
  return g_seed >> 8;
}

std::int8_t w8[kRows * kCols];
std::int8_t x8[kCols], x8b[kCols];
std::int32_t got[kRows], want[kRows], got_b[kRows], want_b[kRows];
#if defined(FWREF_HAS_W16_KERNEL)
alignas(8) std::int16_t w16[kRows * fwref::w16_stride(kCols)];
alignas(8) std::int16_t x16[fwref::w16_stride(kCols)];
#endif
float wf[kRows * kCols];
float xf[kCols];
float yf[kRows], yref[kRows];

void put_case(const char* what, int rows, int cols) {
  char b[64];
  int n = 0;
  for (const char* t = what; *t != '\0'; ++t) b[n++] = *t;
  for (int v : {rows, cols}) {
    b[n++] = ' ';
    if (v >= 10) b[n++] = char('0' + v / 10);
    b[n++] = char('0' + v % 10);
  }
  b[n++] = '\n';
  b[n] = '\0';
  board::puts(b);
}

// One shape: fresh data, every kernel against its reference; false (and the case printed) on a mismatch.
bool check_shape(int rows, int cols) {
  for (int i = 0; i < rows * cols; ++i) {
    w8[i] = static_cast<std::int8_t>(int(next() % 255u) - 127);  // weights in [-127, 127] (docs/formats.md)
    wf[i] = float(int(next() % 20001u) - 10000) * 1.37e-4f;
  }
  for (int i = 0; i < cols; ++i) {
    x8[i] = static_cast<std::int8_t>(int(next() % 256u) - 128);
    xf[i] = float(int(next() % 20001u) - 10000) * 3.1e-4f;
  }
  fwref::gemv_i8_portable(w8, rows, cols, x8, want);
  fwref::gemv_i8(w8, rows, cols, x8, got);
  if (std::memcmp(got, want, sizeof(std::int32_t) * rows) != 0) return put_case("FAIL gemv_i8", rows, cols), false;
  for (int i = 0; i < cols; ++i) x8b[i] = static_cast<std::int8_t>(int(next() % 256u) - 128);
  fwref::gemv_i8_portable(w8, rows, cols, x8b, want_b);
  fwref::gemv_i8_x2(w8, rows, cols, x8, x8b, got, got_b);
  if (std::memcmp(got, want, sizeof(std::int32_t) * rows) != 0 || std::memcmp(got_b, want_b, sizeof(std::int32_t) * rows) != 0) {
    return put_case("FAIL gemv_i8_x2", rows, cols), false;
  }
#if defined(FWREF_HAS_W16_KERNEL)
  fwref::expand_i8_to_i16(w8, rows, cols, w16);
  const int stride = fwref::w16_stride(cols);
  for (int i = 0; i < stride; ++i) x16[i] = i < cols ? x8[i] : 0;
  fwref::gemv_w16_x16(w16, rows, cols, x16, got);
  if (std::memcmp(got, want, sizeof(std::int32_t) * rows) != 0) return put_case("FAIL gemv_w16_x16", rows, cols), false;
  fwref::gemv_i8w16(w16, rows, cols, x8, got);
  if (std::memcmp(got, want, sizeof(std::int32_t) * rows) != 0) return put_case("FAIL gemv_i8w16", rows, cols), false;
#endif
  fwref::gemv_f32_portable(wf, rows, cols, xf, yref);
  fwref::gemv_f32(wf, rows, cols, xf, yf);
  if (std::memcmp(yf, yref, sizeof(float) * rows) != 0) return put_case("FAIL gemv_f32", rows, cols), false;
  return true;
}

// all_finite_f32 against std::isfinite: every length 0..kCols, a NaN, +inf or -inf at every position
// (and the largest finite values, which must pass); false and the case printed on a mismatch.
bool check_finite() {
  static const float bad[3] = {__builtin_nanf(""), __builtin_inff(), -__builtin_inff()};
  for (int n = 0; n <= kCols; ++n) {
    for (int i = 0; i < n; ++i) xf[i] = (i & 1) ? 3.4028235e38f : -1.0e-45f;  // finite extremes
    if (!fwref::all_finite_f32(xf, n)) return put_case("FAIL all_finite_f32 finite", n, 0), false;
    for (int pos = 0; pos < n; ++pos) {
      for (float b : bad) {
        const float keep = xf[pos];
        xf[pos] = b;
        const bool got_ok = fwref::all_finite_f32(xf, n);
        xf[pos] = keep;
        if (got_ok) return put_case("FAIL all_finite_f32 at", n, pos), false;
      }
    }
  }
  return true;
}

}  // namespace

int main() {
  if (!check_finite()) return 1;
  static const int cols_list[] = {1, 2, 3, 4, 5, 7, 8, 9, 11, 12, 15, 16, 17, 23, 25, 31, 40, 41};
  int cases = 0;
  for (int rows = 1; rows <= kRows; ++rows) {
    for (int cols : cols_list) {
      if (cols > kCols) continue;
      if (!check_shape(rows, cols)) return 1;
      ++cases;
    }
  }
  char b[48] = "KERNELS PASS cases=";
  int n = 19;
  if (cases >= 100) b[n++] = char('0' + cases / 100);
  if (cases >= 10) b[n++] = char('0' + cases / 10 % 10);
  b[n++] = char('0' + cases % 10);
  b[n++] = '\n';
  b[n] = '\0';
  board::puts(b);
  // the kernels this image checked (fwref/kernels_i8.hpp, fwref/kernels_f32.hpp)
  board::puts(fwref::gemv_i8_kernel_name());
  board::puts(" ");
  board::puts(fwref::gemv_f32_kernel_name());
  board::puts("\n");
  return 0;
}
