/* Instructions per tick of the whole board with the loop on it, on the MPS2 AN500
 * (Cortex-M7) under QEMU with -icount shift=0: board.c's session (framing, REFS in, the
 * kind's kernels, LOG rows out every p-th tick) fed a recorded host session from memory.
 * Not a board's program.  The sessions come from bench_session.c (hil/firmware.py:
 * HELLO, CONFIG, the kind's LOOP records with log period p, START, then REFS frames of 32
 * ticks for BENCH_TICKS ticks).  The drive half of the HAL is a stand-in that costs
 * next to nothing (a position read from a table, the current clipped), so the count is
 * the board's own: what a real board adds is its encoder and amplifier access.  Writes,
 * on UART0,
 *
 *   <label> board <n>        (instructions per tick, from START to the last tick)
 *
 * then "done", once the host has sent a byte.
 */
#include <stdint.h>
#include <string.h>

#include "board.h"
#include "hal.h"
#include "mps2.h"

extern const int BENCH_SESSIONS;
extern const uint32_t BENCH_TICKS;
extern const char *const BENCH_LABEL[];
extern const uint8_t *const BENCH_BYTES[];
extern const uint32_t BENCH_LEN[], BENCH_SETUP[]; /* bytes; bytes before the first REFS */
extern const double BENCH_RATE_HZ, BENCH_U_MAX;

static const uint8_t *src;
static uint32_t pos, until;
static uint32_t reads;

void hal_read_position(double *x, double *v)
{
    reads++;
    *x = 1e-9 * (double)(reads & 15u); /* a few quantisation steps of motion */
    *v = 0.0;
}

double hal_write_current(double amps) { return amps > BENCH_U_MAX ? BENCH_U_MAX : amps < -BENCH_U_MAX ? -BENCH_U_MAX : amps; }

uint32_t hal_now_us(void) { return 0; } /* lockstep: no timeout runs out */

size_t hal_stream(const uint8_t *tx, size_t tx_len, size_t *tx_taken, uint8_t *rx, size_t rx_cap)
{
    (void)tx;
    *tx_taken = tx_len; /* sent: a DMA would take it */
    size_t n = until - pos < rx_cap ? until - pos : rx_cap;
    memcpy(rx, src + pos, n);
    pos += (uint32_t)n;
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
    while (!(UART_STATE & 2u))
        ;
    (void)UART_DATA;
    for (int s = 0; s < BENCH_SESSIONS; s++) {
        board_info info = {"bench", BENCH_RATE_HZ, BENCH_U_MAX, 0.0, 1, 1, 0};
        board_init(&bd, &info);
        src = BENCH_BYTES[s];
        pos = 0;
        until = BENCH_SETUP[s];
        while (pos < until)
            board_poll(&bd);
        board_poll(&bd);
        if (bd.state != BOARD_ACTIVE) {
            mps2_put(BENCH_LABEL[s]);
            mps2_put(" not active\n");
            continue;
        }
        until = BENCH_LEN[s];
        uint32_t t0 = TIMER_VALUE;
        while (bd.k < BENCH_TICKS && bd.state == BOARD_ACTIVE)
            board_poll(&bd);
        uint32_t t = (t0 - TIMER_VALUE) * INSN_PER_COUNT / BENCH_TICKS;
        mps2_put(BENCH_LABEL[s]);
        mps2_put(bd.k == BENCH_TICKS ? " board " : " fault ");
        mps2_put_u32(t);
        mps2_put("\n");
    }
    mps2_put("done\n");
    for (;;)
        ;
}

void mps2_fault(void) {}
