/* The board support a generated project needs: board_common.c (the same on every board)
 * defines the receive ring, the interrupt switches, board_idle() and the start-up; one file per
 * board (board_<name>.c) the rest, plus its vector table. board_app.c and stsp_frame.c are the
 * same on every board. */
#ifndef BOARD_H
#define BOARD_H

#include <stddef.h>
#include <stdint.h>

/* Clocks, pins and the UART. Returns 0, or 1 when the clock did not start (the board then
 * runs on its reset clock and says so in the HELLO frame). */
int board_init(void);
/* 1 and *byte when a received byte is waiting, else 0 (never blocks). */
int board_uart_read(uint8_t *byte);
/* Send n bytes (waits for the transmitter, at most n bytes long). */
void board_uart_write(const uint8_t *data, size_t n);
/* The core clock in Hz after board_init (the tick timer counts it). */
uint32_t board_clock_hz(void);
/* Interrupts off/on around data shared with the tick timer's handler. */
void board_irq_disable(void);
void board_irq_enable(void);
/* Wait for an interrupt (or return at once). */
void board_idle(void);

/* The tick timer, counting processor cycles: an interrupt that calls board_timer_handler()
 * every reload + 1 cycles (the SysTick on most Cortex-M parts; a peripheral timer where the
 * core has none). */
void board_timer_start(uint32_t reload);
/* Cycles since the timer's last interrupt: 0..reload. */
uint32_t board_timer_elapsed(void);

/* Defined by board_common.c: the UART's receive interrupt puts each byte into the ring that
 * board_uart_read() reads. */
void board_rx_put(uint8_t byte);
/* Defined by board_common.c, named by the board's vector table: the start-up, which calls
 * board_main(), and the handler of every fault. __StackTop: the initial stack pointer
 * (<board>.ld). */
void Reset_Handler(void);
void Fault_Handler(void);
extern uint32_t __StackTop[];

/* Defined by board_app.c: the tick timer's interrupt calls it. */
void board_timer_handler(void);
/* The application, called by the start-up code after .data/.bss are set up. */
int board_main(void);

#endif /* BOARD_H */
