// mcu/board.hpp -- scope: what the QEMU harnesses need from the (emulated) board: semihosting
// console output and its lines, SysTick as an instruction counter, and stack painting. Not part of
// the library; the minimal size images do not include it.
#pragma once

#include <cmath>
#include <cstdint>

namespace board {

// SYS_WRITE0: a NUL-terminated string to the host's console.
void puts(const char* s);

// One console line of at most N - 2 characters (cut there), written by out() with its newline: text,
// integers, %.3e (e) and %.3f for small non-negative values (f3). No printf: newlib's float formatting
// allocates, and the images link no heap.
template <int N>
struct Line {
  char buf[N];
  int n = 0;
  Line& s(const char* t) {
    while (*t && n < N - 2) buf[n++] = *t++;
    return *this;
  }
  Line& u(std::uint64_t v) {
    char tmp[24];
    int k = 0;
    do tmp[k++] = char('0' + v % 10); while ((v /= 10) && k < 23);
    while (k && n < N - 2) buf[n++] = tmp[--k];
    return *this;
  }
  Line& i(long v) { return v < 0 ? s("-").u(std::uint64_t(-v)) : u(std::uint64_t(v)); }
  Line& e(double v) {  // %.3e
    if (std::isnan(v)) return s("nan");
    if (v < 0) s("-"), v = -v;
    if (std::isinf(v)) return s("inf");
    int ex = 0;
    if (v != 0.0) {
      while (v >= 10.0) v /= 10.0, ++ex;
      while (v < 1.0) v *= 10.0, --ex;
    }
    std::uint64_t m = std::uint64_t(v * 1000.0 + 0.5);
    if (m >= 10000) m /= 10, ++ex;
    u(m / 1000).s(".");
    const std::uint64_t f = m % 1000;
    if (f < 100) s("0");
    if (f < 10) s("0");
    u(f).s(ex < 0 ? "e-" : "e+");
    if ((ex < 0 ? -ex : ex) < 10) s("0");
    return u(std::uint64_t(ex < 0 ? -ex : ex));
  }
  Line& f3(double v) {  // %.3f for small non-negative values
    const std::uint64_t m = std::uint64_t(v * 1000.0 + 0.5);
    u(m / 1000).s(".");
    const std::uint64_t f = m % 1000;
    if (f < 100) s("0");
    if (f < 10) s("0");
    return u(f);
  }
  void out() {
    buf[n++] = '\n';
    buf[n] = '\0';
    board::puts(buf);
  }
};

// Start SysTick from the core clock with the largest reload and count its wraps in the interrupt;
// returns once the counter has loaded its reload value, so a ticks() right after it is valid.
// Under QEMU with -icount shift=0 the virtual clock advances 1 ns per instruction, and SysTick
// runs at the board's 25 MHz, so one tick is 40 instructions; calibrate() measures that ratio.
void ticks_start();
std::uint64_t ticks();
double calibrate(std::uint32_t loop_iterations, std::uint64_t* loop_ticks);

// Fill the free stack below the caller with a pattern; after a call, stack_used() is the number
// of bytes below ``top`` that were written (the callee's peak stack).
void paint_stack(const void* top);
std::uint32_t stack_used(const void* top);

inline const void* stack_pointer() {
  const void* sp;
  __asm volatile("mov %0, sp" : "=r"(sp));
  return sp;
}

}  // namespace board
