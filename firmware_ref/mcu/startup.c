/* startup.c -- scope: reset and exceptions of the bare-metal Cortex-M images: the vector table,
 * the FPU enable, .data copy and .bss zeroing, C++ constructors, main, and the exit of QEMU through
 * semihosting with main's return value. Shared by the parity harness and the minimal images. */
#include <stdint.h>

extern uint32_t __data_load[], __data_start[], __data_end[], __bss_start[], __bss_end[], __stack_top[];
extern void (*__init_array_start[])(void), (*__init_array_end[])(void);
int main(void);
void semihost_exit(int code) __attribute__((noreturn));

void Reset_Handler(void) {
  /* CPACR: full access to CP10/CP11 (the FPU) before any floating-point instruction. */
  *(volatile uint32_t*)0xE000ED88 |= 0xFu << 20;
  __asm volatile("dsb\n\tisb" ::: "memory");
  for (uint32_t *s = __data_load, *d = __data_start; d < __data_end;) *d++ = *s++;
  for (uint32_t* d = __bss_start; d < __bss_end;) *d++ = 0;
  for (void (**f)(void) = __init_array_start; f < __init_array_end; ++f) (*f)();
  semihost_exit(main());
}

static void Fault_Handler(void) { semihost_exit(3); } /* a fault is a failed run, never a hang */
void Default_Handler(void) { semihost_exit(4); }
void SysTick_Handler(void) __attribute__((weak, alias("Default_Handler")));

/* SYS_EXIT_EXTENDED (0x20) with ADP_Stopped_ApplicationExit: QEMU exits with ``code``. */
void semihost_exit(int code) {
  uint32_t block[2] = {0x20026u, (uint32_t)code};
  register uint32_t r0 __asm("r0") = 0x20;
  register uint32_t* r1 __asm("r1") = block;
  __asm volatile("bkpt 0xAB" : "+r"(r0) : "r"(r1) : "memory");
  for (;;) {
  }
}

__attribute__((section(".isr_vector"), used)) void (*const g_vectors[16])(void) = {
    (void (*)(void))__stack_top, Reset_Handler, Fault_Handler, Fault_Handler, Fault_Handler, Fault_Handler,
    Fault_Handler, 0, 0, 0, 0, Default_Handler, Default_Handler, 0, Default_Handler, SysTick_Handler};
