/* The firmware on an ARM MPS2 board with the AN500 image (Cortex-M7, double-precision
 * FPU), as QEMU emulates it (`qemu-system-arm -M mps2-an500`): the stream and clock half
 * of hal.h on the board's UART0 and TIMER0, the drive simulated (hal_sim.c), lockstep.
 *
 * Startup and registers: mps2_start.c, mps2.h; the program needs nothing but newlib's
 * string and math functions.
 */
#include <stdint.h>

#include "board.h"
#include "drive.h"
#include "hal.h"
#include "mps2.h"

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

void mps2_fault(void) { hal_write_current(0.0); } /* a fault handler's safe state */
