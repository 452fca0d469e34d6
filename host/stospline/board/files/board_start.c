/* Start-up, the same on every board: the reset handler copies .data from flash, zeroes .bss,
 * enables the FPU where the core has one (__ARM_FP: CP10/CP11 full access before any
 * floating-point instruction), then runs board_main(); the fault handler. The board's file
 * (board_<name>.c) holds the vector table that names them. */
#include <stdint.h>

#include "board.h"

#define SCB_CPACR (*(volatile uint32_t *)0xE000ED88u)

/* The linker script's symbols (<board>.ld). */
extern uint32_t __data_start__[];
extern uint32_t __data_end__[];
extern uint32_t __data_load__[];
extern uint32_t __bss_start__[];
extern uint32_t __bss_end__[];

/* A fault stops the core here; the actuators keep their last command: on a real board set
 * them to the safe command (board-specific) before spinning. */
void Fault_Handler(void)
{
    for (;;) {
    }
}

void Reset_Handler(void)
{
    volatile uint32_t *data = __data_start__;
    volatile uint32_t *bss = __bss_start__;
    const volatile uint32_t *load = __data_load__;
    const uint32_t nd = (uint32_t)(((uintptr_t)__data_end__ - (uintptr_t)__data_start__) / 4u);
    const uint32_t nb = (uint32_t)(((uintptr_t)__bss_end__ - (uintptr_t)__bss_start__) / 4u);
    uint32_t i;
    for (i = 0u; i < nd; ++i) {
        data[i] = load[i];
    }
    for (i = 0u; i < nb; ++i) {
        bss[i] = 0u;
    }
#if defined(__ARM_FP)
    SCB_CPACR |= 0xFu << 20;
    __asm__ volatile("dsb\n\tisb" ::: "memory");
#endif
    (void)board_main();
    for (;;) {
    }
}
