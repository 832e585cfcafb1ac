/* The firmware on an ARM MPS2 board with the AN500 image (Cortex-M7, double-precision
 * FPU), as QEMU emulates it (`qemu-system-arm -M mps2-an500`): the stream and clock half
 * of hal.h on the board's UART0 and TIMER0, the drive simulated (hal_sim.c), lockstep.
 *
 * Startup (vector table, .data/.bss, the FPU) is here too: the program needs nothing
 * but newlib's string and math functions.  Memory map (AN500): code in the 4 MB SSRAM1
 * at 0x00000000, data in SSRAM2/3 at 0x20000000 (mps2.ld).
 */
#include <stdint.h>

#include "board.h"
#include "drive.h"
#include "hal.h"

#define REG(a) (*(volatile uint32_t *)(a))
#define UART0 0x40004000u     /* CMSDK APB UART */
#define UART_DATA REG(UART0 + 0x00)
#define UART_STATE REG(UART0 + 0x04) /* bit 0 TX full, bit 1 RX full */
#define UART_CTRL REG(UART0 + 0x08)  /* bit 0 TX enable, bit 1 RX enable */
#define UART_BAUDDIV REG(UART0 + 0x10)
#define TIMER0 0x40000000u    /* CMSDK APB timer, counts down at PCLK */
#define TIMER_CTRL REG(TIMER0 + 0x00)
#define TIMER_VALUE REG(TIMER0 + 0x04)
#define TIMER_RELOAD REG(TIMER0 + 0x08)
#define PCLK_MHZ 25u
#define CPACR REG(0xE000ED88u)

static uint32_t last_raw;
static uint64_t elapsed; /* PCLK cycles since start */

uint32_t hal_now_us(void)
{
    uint32_t raw = TIMER_VALUE;
    elapsed += (uint32_t)(last_raw - raw); /* a down counter */
    last_raw = raw;
    return (uint32_t)(elapsed / PCLK_MHZ);
}

size_t hal_stream(const uint8_t *tx, size_t tx_len, size_t *tx_taken, uint8_t *rx, size_t rx_cap)
{
    size_t i = 0, n = 0;
    while (i < tx_len && !(UART_STATE & 1u))
        UART_DATA = tx[i++];
    *tx_taken = i;
    while (n < rx_cap && (UART_STATE & 2u))
        rx[n++] = (uint8_t)UART_DATA;
    return n;
}

static board bd;

int main(void)
{
    UART_BAUDDIV = 16;
    UART_CTRL = 3u;
    TIMER_RELOAD = 0xFFFFFFFFu;
    TIMER_VALUE = 0xFFFFFFFFu;
    TIMER_CTRL = 1u;
    last_raw = TIMER_VALUE;
    board_info info = {"servo firmware (mps2-an500)", FW_SAMPLE_RATE_HZ, FW_DRIVE.p.u_max, FW_DRIVE.u_hold,
                       FW_HAS_VELOCITY, 1, 0};
    board_init(&bd, &info);
    sim_park();
    for (;;)
        sim_poll(&bd);
}

/* ------------------------------------------------------------------ startup */

extern uint32_t __data_load, __data_start, __data_end, __bss_start, __bss_end, __stack_top;

void reset_handler(void)
{
    uint32_t *src = &__data_load, *dst = &__data_start;
    while (dst < &__data_end)
        *dst++ = *src++;
    for (dst = &__bss_start; dst < &__bss_end;)
        *dst++ = 0;
    CPACR |= 0xFu << 20; /* CP10, CP11: the FPU, full access */
    __asm__ volatile("dsb\n isb");
    main();
    for (;;)
        ;
}

static void hang(void)
{
    hal_write_current(0.0); /* a fault handler's safe state */
    for (;;)
        ;
}

__attribute__((section(".vectors"), used)) static void (*const vectors[16])(void) = {
    (void (*)(void))&__stack_top, reset_handler, hang, hang, hang, hang, hang, 0, 0, 0, 0, hang, hang, 0, hang, hang,
};
