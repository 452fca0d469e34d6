/* Minimal Cortex-M4F start-up for QEMU's mps2-an386: vector table and reset handler.
 *
 * Reset: copy .data from flash to RAM, zero .bss, enable the FPU (CP10/CP11 full access in
 * CPACR, 0xE000ED88 bits 20-23) and `dsb; isb` before any floating-point instruction, open the
 * semihosting console (librdimon), run constructors, then exit(main()): newlib's exit flushes
 * stdio and ends QEMU with main's status through semihosting.
 *
 * newlib's own rdimon crt0 (_start) is deliberately not used: it moves the stack to whatever
 * the SYS_HEAPINFO semihosting call reports, which on QEMU's mps2-an386 is the top of the
 * 16 MiB PSRAM at 0x21000000, outside the 4 MiB RAM this image is linked for. Here the stack
 * stays at __StackTop (top of RAM, mps2-an386.ld) and the heap grows from `end`.
 * Exceptions other than reset spin in place (QEMU's -d int shows them). This file is compiled
 * without floating-point code: the FPU is off until the CPACR write. */
#include <stdint.h>
#include <stdlib.h>

#define STSP_SCB_CPACR (*(volatile uint32_t *)0xE000ED88u)
#define STSP_CPACR_CP10_CP11_FULL (0xFu << 20)

extern uint32_t __data_start__[];
extern uint32_t __data_end__[];
extern uint32_t __data_load__[];
extern uint32_t __bss_start__[];
extern uint32_t __bss_end__[];
extern uint32_t __StackTop[];

int main(void);
void initialise_monitor_handles(void); /* librdimon: semihosting stdin/stdout/stderr */
void __libc_init_array(void);          /* newlib: .preinit_array, _init, .init_array */
void Reset_Handler(void);
void Default_Handler(void);

void Default_Handler(void)
{
    for (;;) {
    }
}

/* Words between two linker-script symbols (compared as addresses: distinct objects in C). */
static uint32_t words_between(const uint32_t *begin, const uint32_t *end)
{
    return (uint32_t)(((uintptr_t)end - (uintptr_t)begin) / sizeof(uint32_t));
}

void Reset_Handler(void)
{
    /* volatile: keep these plain word loops, not calls into the C library */
    volatile uint32_t *data = __data_start__;
    volatile uint32_t *bss = __bss_start__;
    const volatile uint32_t *load = __data_load__;
    uint32_t i, n;
    n = words_between(__data_start__, __data_end__);
    for (i = 0u; i < n; ++i) {
        data[i] = load[i];
    }
    n = words_between(__bss_start__, __bss_end__);
    for (i = 0u; i < n; ++i) {
        bss[i] = 0u;
    }
#if defined(__ARM_FP)
#if defined(__ARM_FP)
    /* Only with an FPU (cortex-m4 build); the cortex-m0plus build has none to enable. */
    STSP_SCB_CPACR |= STSP_CPACR_CP10_CP11_FULL;
    __asm__ volatile("dsb\n\tisb" ::: "memory");
#endif
#endif
    initialise_monitor_handles();
    __libc_init_array();
    exit(main());
}

typedef void (*stsp_vector_t)(void);

/* Initial SP, then the 15 system exception vectors (reset first); no external interrupts. */
typedef struct {
    uint32_t *initial_sp;
    stsp_vector_t vectors[15];
} stsp_vector_table_t;

__attribute__((section(".isr_vector"), used)) const stsp_vector_table_t stsp_vector_table = {
    __StackTop,
    {
        Reset_Handler,   /* Reset */
        Default_Handler, /* NMI */
        Default_Handler, /* HardFault */
        Default_Handler, /* MemManage */
        Default_Handler, /* BusFault */
        Default_Handler, /* UsageFault */
        0, 0, 0, 0,      /* reserved */
        Default_Handler, /* SVCall */
        Default_Handler, /* DebugMonitor */
        0,               /* reserved */
        Default_Handler, /* PendSV */
        Default_Handler, /* SysTick */
    }};
