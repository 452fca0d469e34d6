/* Board support the same on every board: the receive ring between the UART's interrupt and
 * the loop, interrupts off and on, the wait for an interrupt, and the start-up: the reset
 * handler copies .data from flash, zeroes .bss, enables the FPU where the core has one
 * (__ARM_FP: CP10/CP11 full access before any floating-point instruction), then runs
 * board_main(); the fault handler. The board's file (board_<name>.c) holds its peripherals
 * and the vector table that names the handlers. */
#include <stddef.h>
#include <stdint.h>

#include "board.h"

#define SCB_CPACR (*(volatile uint32_t *)0xE000ED88u)
#define RX_RING 512u /* received bytes not yet read by the loop (a power of two, > a frame) */

/* Bytes from the UART interrupt to the loop: one writer (the interrupt), one reader. */
static volatile uint8_t rx_ring[RX_RING];
static volatile uint32_t rx_head, rx_tail;

/* A byte that finds the ring full is dropped (the frame it belongs to then fails its CRC:
 * BOARD_STATUS_BAD_FRAME). */
void board_rx_put(uint8_t byte)
{
    const uint32_t head = rx_head;
    if (head - rx_tail < RX_RING) {
        rx_ring[head & (RX_RING - 1u)] = byte;
        rx_head = head + 1u;
    }
}

int board_uart_read(uint8_t *byte)
{
    const uint32_t tail = rx_tail;
    if (tail == rx_head) {
        return 0;
    }
    *byte = rx_ring[tail & (RX_RING - 1u)];
    rx_tail = tail + 1u;
    return 1;
}

void board_irq_disable(void)
{
    __asm__ volatile("cpsid i" ::: "memory");
}

void board_irq_enable(void)
{
    __asm__ volatile("cpsie i" ::: "memory");
}

/* Sleep until an interrupt: a received byte or the tick timer. */
void board_idle(void)
{
    __asm__ volatile("wfi" ::: "memory");
}

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
