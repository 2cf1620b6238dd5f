/* Minimal startup for QEMU's mps2-an386 (Cortex-M4F) and mps2-an500 (Cortex-M7) boards, used
 * by KinDynGen's embedded harness (kindyngen/runtime/embedded.py). The image runs from RAM (QEMU
 * loads the ELF's sections where they belong), so reset only zeroes .bss, grants the FPU,
 * opens newlib's semihosting handles (librdimon), calls main and exits through semihosting
 * with main's result. */
#include <stdint.h>
#include <stdlib.h>

extern uint32_t __bss_start__, __bss_end__, __stack_top;
extern int main(void);
extern void initialise_monitor_handles(void);

void Reset_Handler(void);
void Default_Handler(void);

void Reset_Handler(void)
{
    uint32_t *p;
    for (p = &__bss_start__; p < &__bss_end__; ++p) {
        *p = 0u;
    }
    /* CPACR: full access to coprocessors 10 and 11 (the FPU) before any float instruction */
    *(volatile uint32_t *)0xE000ED88u |= 0xFu << 20;
    __asm volatile("dsb\n\tisb" ::: "memory");
    initialise_monitor_handles();
    exit(main());
}

/* newlib's exit runs the fini array, which calls _fini (crti is not linked: -nostartfiles) */
void _init(void);
void _fini(void);
void _init(void)
{
}

void _fini(void)
{
}

void Default_Handler(void)
{
    exit(99);   /* a fault: leave QEMU with a code the harness reports */
}

typedef void (*vector)(void);

/* stack pointer, reset, then NMI, HardFault, MemManage, BusFault, UsageFault: all faults exit */
__attribute__((section(".vectors"), used)) const vector kdg_vectors[16] = {
    (vector)(uintptr_t)&__stack_top, Reset_Handler, Default_Handler, Default_Handler,
    Default_Handler, Default_Handler, Default_Handler, 0, 0, 0, 0, Default_Handler,
    Default_Handler, 0, Default_Handler, Default_Handler,
};
