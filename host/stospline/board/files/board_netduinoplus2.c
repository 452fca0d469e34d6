/* Board support for the Netduino Plus 2 (STM32F405RG, Cortex-M4F, 168 MHz), as QEMU 7.2's
 * `netduinoplus2` machine emulates it: vector table, clock, USART1 (PA9 TX,
 * PA10 RX, 115200 8N1), the first `-serial` of QEMU.
 *
 * Board-specific (change these for another STM32F4 board): BOARD_HSE_HZ and the PLL factors
 * in clock_init(), the USART and its pins in uart_init(), the baud rate (BRR). With
 * BOARD_EMULATED (the qemu preset) the clock set-up is skipped: QEMU models no RCC and runs
 * the core at 168 MHz from reset. */
#include <stddef.h>
#include <stdint.h>

#include "board.h"

#define REG(addr) (*(volatile uint32_t *)(addr))

/* RCC, FLASH, GPIOA, USART1 (RM0090). */
#define RCC_CR REG(0x40023800u)
#define RCC_PLLCFGR REG(0x40023804u)
#define RCC_CFGR REG(0x40023808u)
#define RCC_AHB1ENR REG(0x40023830u)
#define RCC_APB2ENR REG(0x40023844u)
#define FLASH_ACR REG(0x40023C00u)
#define GPIOA_MODER REG(0x40020000u)
#define GPIOA_AFRH REG(0x40020024u)
#define USART1_SR REG(0x40011000u)
#define USART1_DR REG(0x40011004u)
#define USART1_BRR REG(0x40011008u)
#define USART1_CR1 REG(0x4001100Cu)
#define USART_SR_RXNE 0x20u
#define USART_SR_TXE 0x80u
#define USART_CR1_UE 0x2000u
#define USART_CR1_TE 0x8u
#define USART_CR1_RE 0x4u
#define USART_CR1_RXNEIE 0x20u
#define NVIC_ISER1 REG(0xE000E104u)
#define USART1_IRQ 37u /* board-specific: the USART's interrupt number */
/* The core's SysTick: the tick timer. */
#define SYST_CSR REG(0xE000E010u)
#define SYST_RVR REG(0xE000E014u)
#define SYST_CVR REG(0xE000E018u)
#define SYST_CSR_ENABLE 0x1u
#define SYST_CSR_TICKINT 0x2u
#define SYST_CSR_CLKSOURCE 0x4u /* the processor clock */

#define BOARD_CLOCK_HZ 168000000u /* board-specific: SYSCLK after clock_init() */
#define BOARD_HSE_HZ 25000000u    /* board-specific: the Netduino Plus 2's crystal */
#define BOARD_APB2_HZ (BOARD_CLOCK_HZ / 2u)
#define BOARD_BAUD 115200u        /* board-specific */
#define WAIT_LIMIT 1000000u       /* bounded waits for the oscillators */

static uint32_t clock_hz = 16000000u; /* HSI at reset */

/* HSE 25 MHz -> PLL (M 25, N 336, P 2) = 168 MHz, AHB /1, APB1 /4, APB2 /2, 5 wait states.
 * Returns 0, or 1 when an oscillator did not become ready (the core stays on HSI). */
static int clock_init(void)
{
#if defined(BOARD_EMULATED)
    clock_hz = BOARD_CLOCK_HZ;
    return 0;
#else
    uint32_t i;
    RCC_CR |= 1u << 16; /* HSEON */
    for (i = 0u; i < WAIT_LIMIT && (RCC_CR & (1u << 17)) == 0u; ++i) {
    }
    if ((RCC_CR & (1u << 17)) == 0u) {
        return 1;
    }
    RCC_PLLCFGR = (BOARD_HSE_HZ / 1000000u) | (336u << 6) | (0u << 16) | (1u << 22) | (7u << 24);
    RCC_CR |= 1u << 24; /* PLLON */
    for (i = 0u; i < WAIT_LIMIT && (RCC_CR & (1u << 25)) == 0u; ++i) {
    }
    if ((RCC_CR & (1u << 25)) == 0u) {
        return 1;
    }
    FLASH_ACR = 5u | (1u << 8) | (1u << 9) | (1u << 10); /* 5 WS, prefetch, I/D cache */
    RCC_CFGR = (5u << 10) | (4u << 13) | 2u;             /* APB1 /4, APB2 /2, SW = PLL */
    for (i = 0u; i < WAIT_LIMIT && ((RCC_CFGR >> 2) & 3u) != 2u; ++i) {
    }
    if (((RCC_CFGR >> 2) & 3u) != 2u) {
        return 1;
    }
    clock_hz = BOARD_CLOCK_HZ;
    return 0;
#endif
}

static void uart_init(void)
{
    RCC_AHB1ENR |= 1u;      /* GPIOA */
    RCC_APB2ENR |= 1u << 4; /* USART1 */
    GPIOA_MODER = (GPIOA_MODER & ~((3u << 18) | (3u << 20))) | (2u << 18) | (2u << 20);
    GPIOA_AFRH = (GPIOA_AFRH & ~((0xFu << 4) | (0xFu << 8))) | (7u << 4) | (7u << 8);
    USART1_BRR = (clock_hz == BOARD_CLOCK_HZ ? BOARD_APB2_HZ : clock_hz) / BOARD_BAUD;
    USART1_CR1 = USART_CR1_UE | USART_CR1_TE | USART_CR1_RE | USART_CR1_RXNEIE;
    NVIC_ISER1 = 1u << (USART1_IRQ - 32u);
}

/* A received byte into the ring (board_rx_put). */
void USART1_IRQHandler(void);
void USART1_IRQHandler(void)
{
    if ((USART1_SR & USART_SR_RXNE) != 0u) {
        board_rx_put((uint8_t)(USART1_DR & 0xFFu));
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
    return clock_hz;
}

void board_uart_write(const uint8_t *data, size_t n)
{
    size_t i;
    for (i = 0u; i < n; ++i) {
        while ((USART1_SR & USART_SR_TXE) == 0u) {
        }
        USART1_DR = data[i];
    }
}

void board_timer_start(uint32_t reload)
{
    SYST_RVR = reload;
    SYST_CVR = 0u;
    SYST_CSR = SYST_CSR_ENABLE | SYST_CSR_TICKINT | SYST_CSR_CLKSOURCE;
}

uint32_t board_timer_elapsed(void)
{
    return SYST_RVR - SYST_CVR; /* the SysTick counts down from the reload */
}

void SysTick_Handler(void);
void SysTick_Handler(void)
{
    board_timer_handler();
}

/* The vector table: Reset_Handler and Fault_Handler are board_common.c's. */
typedef void (*vector_t)(void);
typedef struct {
    uint32_t *initial_sp;
    vector_t core[15];
    vector_t irq[USART1_IRQ + 1u];
} vector_table_t;

/* The core's exceptions, then the peripheral interrupts up to USART1's (the others are
 * never enabled; board-specific: the vector of the USART used). */
__attribute__((section(".isr_vector"), used)) const vector_table_t board_vectors = {
    __StackTop,
    {Reset_Handler, Fault_Handler, Fault_Handler, Fault_Handler, Fault_Handler, Fault_Handler,
     0, 0, 0, 0, Fault_Handler, Fault_Handler, 0, Fault_Handler, SysTick_Handler},
    {[USART1_IRQ] = USART1_IRQHandler}};
