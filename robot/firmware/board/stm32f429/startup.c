/* Cortex-M4 start-up: vector table, .data copy, .bss clear, FPU on, then main(). */
#include <stdint.h>

#include "regs.h"

extern uint32_t _estack, _sidata, _sdata, _edata, _sbss, _ebss;
int main(void);
void SysTick_Handler(void);

void Reset_Handler(void) {
    const uint32_t *src = &_sidata;
    for (uint32_t *dst = &_sdata; dst < &_edata;) *dst++ = *src++;
    for (uint32_t *dst = &_sbss; dst < &_ebss;) *dst++ = 0;
    SCB_CPACR |= 0xFu << 20; /* CP10, CP11 full access: the core uses single-precision floats */
    __asm__ volatile("dsb\n isb");
    main();
    for (;;) {
    }
}

/* Any fault: stop the motors by stopping everything (the drivers' PWM goes low on reset) */
void Default_Handler(void) { SCB_AIRCR = 0x05FA0004u; for (;;) {} }

__attribute__((section(".isr_vector"), used)) void (*const g_vectors[16])(void) = {
    (void (*)(void))(uintptr_t)&_estack,
    Reset_Handler,
    Default_Handler, /* NMI */
    Default_Handler, /* HardFault */
    Default_Handler, /* MemManage */
    Default_Handler, /* BusFault */
    Default_Handler, /* UsageFault */
    0, 0, 0, 0,
    Default_Handler, /* SVCall */
    Default_Handler, /* DebugMonitor */
    0,
    Default_Handler, /* PendSV */
    SysTick_Handler,
};
