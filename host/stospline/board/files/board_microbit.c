/* Board support for the BBC micro:bit (nRF51822, Cortex-M0 at 16 MHz), as QEMU 7.2's
 * `microbit` machine emulates it: vector table, clock, UART0 (P0.24 TX, P0.25 RX:
 * the interface chip's USB serial, 115200 8N1), the first `-serial` of QEMU, and TIMER0 as
 * the tick timer: the nRF51's Cortex-M0 has no SysTick.
 *
 * Board-specific (change these for another nRF51 board): the UART pins and baud rate in
 * uart_init(), the crystal start in clock_init(). With BOARD_EMULATED (the qemu preset) the
 * crystal start is skipped: QEMU models no CLOCK peripheral. */
#include <stddef.h>
#include <stdint.h>

#include "board.h"

#define REG(addr) (*(volatile uint32_t *)(addr))

/* CLOCK, UART0, TIMER0, NVIC (nRF51 Reference Manual). */
#define CLOCK_TASKS_HFCLKSTART REG(0x40000000u)
#define CLOCK_EVENTS_HFCLKSTARTED REG(0x40000100u)
#define UART_TASKS_STARTRX REG(0x40002000u)
#define UART_TASKS_STARTTX REG(0x40002008u)
#define UART_EVENTS_RXDRDY REG(0x40002108u)
#define UART_EVENTS_TXDRDY REG(0x4000211Cu)
#define UART_INTENSET REG(0x40002304u)
#define UART_ENABLE REG(0x40002500u)
#define UART_PSELTXD REG(0x4000250Cu)
#define UART_PSELRXD REG(0x40002514u)
#define UART_RXD REG(0x40002518u)
#define UART_TXD REG(0x4000251Cu)
#define UART_BAUDRATE REG(0x40002524u)
#define UART_INTEN_RXDRDY (1u << 2)
#define UART_ENABLE_ON 4u
#define UART_BAUD_115200 0x01D7E000u /* board-specific */
#define UART_FIFO 6u                 /* the receiver's FIFO: bytes an interrupt drains at most */
#define TIMER_TASKS_START REG(0x40008000u)
#define TIMER_TASKS_CLEAR REG(0x4000800Cu)
#define TIMER_TASKS_CAPTURE1 REG(0x40008044u)
#define TIMER_EVENTS_COMPARE0 REG(0x40008140u)
#define TIMER_SHORTS REG(0x40008200u)
#define TIMER_INTENSET REG(0x40008304u)
#define TIMER_MODE REG(0x40008504u)
#define TIMER_BITMODE REG(0x40008508u)
#define TIMER_PRESCALER REG(0x40008510u)
#define TIMER_CC0 REG(0x40008540u)
#define TIMER_CC1 REG(0x40008544u)
#define NVIC_ISER REG(0xE000E100u)
#define UART0_IRQ 2u
#define TIMER0_IRQ 8u
#define PIN_TXD 24u /* board-specific: the micro:bit's UART pins */
#define PIN_RXD 25u

#define BOARD_CLOCK_HZ 16000000u /* HFCLK: the core, and TIMER0 with prescaler 0 */
#define WAIT_LIMIT 1000000u      /* bounded waits: the crystal, a byte's transmission */

static uint32_t timer_reload;

/* The 16 MHz crystal for the UART's baud rate. Returns 0, or 1 when it did not start (the
 * core then runs on the 16 MHz RC oscillator). */
static int clock_init(void)
{
#if defined(BOARD_EMULATED)
    return 0;
#else
    uint32_t i;
    CLOCK_EVENTS_HFCLKSTARTED = 0u;
    CLOCK_TASKS_HFCLKSTART = 1u;
    for (i = 0u; i < WAIT_LIMIT && CLOCK_EVENTS_HFCLKSTARTED == 0u; ++i) {
    }
    return (CLOCK_EVENTS_HFCLKSTARTED == 0u) ? 1 : 0;
#endif
}

static void uart_init(void)
{
    UART_PSELTXD = PIN_TXD;
    UART_PSELRXD = PIN_RXD;
    UART_BAUDRATE = UART_BAUD_115200;
    UART_ENABLE = UART_ENABLE_ON;
    UART_EVENTS_RXDRDY = 0u;
    UART_EVENTS_TXDRDY = 0u;
    UART_INTENSET = UART_INTEN_RXDRDY;
    NVIC_ISER = 1u << UART0_IRQ;
    UART_TASKS_STARTRX = 1u;
    UART_TASKS_STARTTX = 1u;
}

/* Received bytes into the ring (board_rx_put). */
void UART0_IRQHandler(void);
void UART0_IRQHandler(void)
{
    uint32_t i;
    for (i = 0u; i < UART_FIFO && UART_EVENTS_RXDRDY != 0u; ++i) {
        UART_EVENTS_RXDRDY = 0u; /* before RXD: reading it raises the event for the next */
        board_rx_put((uint8_t)(UART_RXD & 0xFFu));
    }
}

void TIMER0_IRQHandler(void);
void TIMER0_IRQHandler(void)
{
    if (TIMER_EVENTS_COMPARE0 != 0u) {
        TIMER_EVENTS_COMPARE0 = 0u;
        board_timer_handler();
    }
}

int board_init(void)
{
    const int failed = clock_init();
    uart_init();
    return failed;
}

uint32_t board_clock_hz(void)
{
    return BOARD_CLOCK_HZ;
}

/* TIMER0 counts the 16 MHz clock, 32 bits, and clears itself on COMPARE0: a period of
 * reload + 1 counts. */
void board_timer_start(uint32_t reload)
{
    timer_reload = reload;
    TIMER_MODE = 0u;      /* timer */
    TIMER_BITMODE = 3u;   /* 32 bits */
    TIMER_PRESCALER = 0u; /* 16 MHz */
    TIMER_CC0 = reload + 1u;
    TIMER_SHORTS = 1u; /* COMPARE0 -> CLEAR */
    TIMER_EVENTS_COMPARE0 = 0u;
    TIMER_INTENSET = 1u << 16; /* COMPARE0 */
    NVIC_ISER = 1u << TIMER0_IRQ;
    TIMER_TASKS_CLEAR = 1u;
    TIMER_TASKS_START = 1u;
}

uint32_t board_timer_elapsed(void)
{
    uint32_t v;
    TIMER_TASKS_CAPTURE1 = 1u;
    v = TIMER_CC1;
    return (v > timer_reload) ? timer_reload : v;
}

/* One byte at a time: TXD, then the TXDRDY event (at most WAIT_LIMIT polls a byte). */
void board_uart_write(const uint8_t *data, size_t n)
{
    size_t i;
    uint32_t k;
    for (i = 0u; i < n; ++i) {
        UART_TXD = data[i];
        for (k = 0u; k < WAIT_LIMIT && UART_EVENTS_TXDRDY == 0u; ++k) {
        }
        UART_EVENTS_TXDRDY = 0u;
    }
}

/* The vector table: Reset_Handler and Fault_Handler are board_common.c's. */
typedef void (*vector_t)(void);
typedef struct {
    uint32_t *initial_sp;
    vector_t core[15];
    vector_t irq[TIMER0_IRQ + 1u];
} vector_table_t;

/* ARMv6-M's exceptions (NMI, HardFault, SVCall, PendSV; no SysTick on the nRF51), then the
 * peripheral interrupts up to TIMER0's (the others are never enabled). */
__attribute__((section(".isr_vector"), used)) const vector_table_t board_vectors = {
    __StackTop,
    {Reset_Handler, Fault_Handler, Fault_Handler, 0, 0, 0, 0, 0, 0, 0, Fault_Handler, 0, 0,
     Fault_Handler, 0},
    {[UART0_IRQ] = UART0_IRQHandler, [TIMER0_IRQ] = TIMER0_IRQHandler}};
