/* The stream and clock half of hal.h for unit tests (tests/test_firmware.py drives it
 * through ctypes): bytes in and out through buffers, a clock the test sets.  The drive
 * half is hal_sim.c.  Not part of a board's build. */
#include <string.h>

#include "board.h"
#include "drive.h"
#include "hal.h"
#include "noise.h"

static uint8_t in[1 << 16], out[1 << 16];
static size_t in_len, in_pos, out_len;
static uint32_t clock_us;
static board bd;

uint32_t hal_now_us(void) { return clock_us; }

size_t hal_stream(const uint8_t *tx, size_t tx_len, size_t *tx_taken, uint8_t *rx, size_t rx_cap)
{
    size_t room = sizeof out - out_len, m = tx_len < room ? tx_len : room;
    memcpy(out + out_len, tx, m);
    out_len += m;
    *tx_taken = m;
    size_t n = in_len - in_pos < rx_cap ? in_len - in_pos : rx_cap;
    memcpy(rx, in + in_pos, n);
    in_pos += n;
    return n;
}

/* Power up a board (lockstep 1/0) with a session log of none. */
void fwt_init(int lockstep)
{
    board_info info = {"firmware under test", FW_SAMPLE_RATE_HZ, FW_DRIVE.p.u_max, FW_DRIVE.u_hold, FW_HAS_VELOCITY,
                       lockstep, 0};
    in_len = in_pos = out_len = 0;
    board_init(&bd, &info);
    sim_park();
}

/* Bytes from the host at time now_us: polled until consumed and the answers flushed. */
void fwt_feed(const uint8_t *p, size_t n, uint32_t now_us)
{
    clock_us = now_us;
    in_len = in_pos = 0;
    memcpy(in, p, n < sizeof in ? n : sizeof in);
    in_len = n < sizeof in ? n : sizeof in;
    while (in_pos < in_len)
        sim_poll(&bd);
    sim_poll(&bd);
}

/* Time passes: poll at now_us (the watchdog and the ready timeout). */
void fwt_poll(uint32_t now_us)
{
    clock_us = now_us;
    sim_poll(&bd);
}

/* Real time: one tick at now_us, its output flushed. */
void fwt_tick(uint32_t now_us)
{
    clock_us = now_us;
    board_tick(&bd);
    sim_poll(&bd);
}

/* The bytes the board sent since the last call. */
size_t fwt_take(uint8_t *dst, size_t cap)
{
    size_t n = out_len < cap ? out_len : cap;
    memcpy(dst, out, n);
    memmove(out, out + n, out_len - n);
    out_len -= n;
    return n;
}

int fwt_state(void) { return (int)bd.state; }
double fwt_applied(void) { return board_applied_current(&bd); }
uint32_t fwt_stat(int i) { return bd.stats[i]; }
uint32_t fwt_refused(void) { return bd.refused_hellos; }

/* The simulated drive alone, from power-up: for k < n, out[2k], out[2k+1] = the sample
 * (x m, v m/s) of tick k, then a step under u[k] (A) with force d[k] (A). */
void fwt_plant_run(int n, const double *u, const double *d, double *out)
{
    static plant pl;
    pl = FW_DRIVE;
    for (int k = 0; k < n; k++) {
        plant_measure(&pl, 0.0, 0.0, out + 2 * k, out + 2 * k + 1);
        plant_step(&pl, u[k], d[k]);
    }
}

/* The sensor noise generator alone: n pairs of standard-normal draws from `seed`. */
void fwt_noise(uint64_t seed, int n, double *out)
{
    static noise_gen g;
    noise_seed(&g, seed);
    for (int k = 0; k < n; k++)
        noise_pair(&g, out + 2 * k, out + 2 * k + 1);
}

/* The simulated drive's disturbance force (A) over periods 0 .. n-1. */
void fwt_disturbance(int n, double *out)
{
    for (int k = 0; k < n; k++)
        out[k] = sim_disturbance((uint32_t)k);
}
