// mcu/board.cpp -- scope: semihosting output, SysTick instruction counting and stack painting for
// the QEMU parity harness (mcu/board.hpp).
#include "board.hpp"

extern "C" std::uint32_t __stack_limit[];

namespace {

volatile std::uint32_t* const kSystCsr = reinterpret_cast<volatile std::uint32_t*>(0xE000E010);
volatile std::uint32_t* const kSystRvr = reinterpret_cast<volatile std::uint32_t*>(0xE000E014);
volatile std::uint32_t* const kSystCvr = reinterpret_cast<volatile std::uint32_t*>(0xE000E018);
constexpr std::uint32_t kReload = 0x00FFFFFF;
constexpr std::uint32_t kPaint = 0xC0DEC0DEu;
volatile std::uint32_t g_wraps = 0;

// Exactly two instructions per iteration (subs, bne): the calibration's known instruction count.
__attribute__((noinline)) void spin(std::uint32_t n) {
  __asm volatile("1: subs %0, %0, #1\n\tbne 1b" : "+r"(n) : : "cc");
}

}  // namespace

extern "C" void SysTick_Handler(void) { g_wraps = g_wraps + 1; }

namespace board {

void puts(const char* s) {
  register std::uint32_t r0 __asm("r0") = 0x04;  // SYS_WRITE0
  register const char* r1 __asm("r1") = s;
  __asm volatile("bkpt 0xAB" : "+r"(r0) : "r"(r1) : "memory");
}

void ticks_start() {
  *kSystCsr = 0;
  *kSystRvr = kReload;
  *kSystCvr = 0;
  *kSystCsr = 7;  // enable, interrupt on wrap, core clock
  // The counter reads 0 until its first tick reloads it (with no wrap counted): a ticks() in
  // between would read kReload ticks and the next one 0, so wait for the reload (at most one tick).
  while (*kSystCvr == 0) {
  }
}

std::uint64_t ticks() {
  std::uint32_t w1, v, w2;
  do {
    w1 = g_wraps;
    v = *kSystCvr;
    w2 = g_wraps;
  } while (w1 != w2);
  return std::uint64_t(w1) * (kReload + 1ULL) + (kReload - v);
}

double calibrate(std::uint32_t n, std::uint64_t* loop_ticks) {
  const std::uint64_t t0 = ticks();
  spin(n);
  const std::uint64_t t1 = ticks();
  *loop_ticks = t1 - t0;
  return *loop_ticks ? 2.0 * n / double(*loop_ticks) : 0.0;
}

void paint_stack(const void* top) {
  std::uint32_t* end = reinterpret_cast<std::uint32_t*>(const_cast<void*>(top)) - 64;  // keep clear of our frame
  for (std::uint32_t* p = __stack_limit; p < end; ++p) *p = kPaint;
}

std::uint32_t stack_used(const void* top) {
  const std::uint32_t* t = static_cast<const std::uint32_t*>(top);
  const std::uint32_t* p = __stack_limit;
  while (p < t && *p == kPaint) ++p;
  return static_cast<std::uint32_t>(t - p) * 4u;
}

}  // namespace board
