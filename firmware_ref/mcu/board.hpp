// mcu/board.hpp -- scope: what the QEMU parity harness needs from the (emulated) board: semihosting
// console output, SysTick as an instruction counter, and stack painting. Not part of the library;
// the minimal size images do not include it.
#pragma once

#include <cstdint>

namespace board {

// SYS_WRITE0: a NUL-terminated string to the host's console.
void puts(const char* s);

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
