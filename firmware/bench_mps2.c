/* Instructions per tick of the firmware's kernels on the MPS2 AN500 (Cortex-M7), counted
 * on QEMU with -icount shift=0 (one instruction per virtual nanosecond: TIMER0, at 25 MHz
 * of virtual time, counts 40 instructions per step).  Not a board's program: it runs the
 * closed loop of each controller kind against the simulated drive and writes, on UART0,
 *
 *   <kind> controller <n> plant <n> frames <n> refs <n> log <n>
 *
 * instructions per tick (controller, plant, frames: host in the loop at b = 1; refs: a
 * REFS frame of 32 ticks in, per tick) and per LOG frame of one 13-column row (log),
 *
 * then "done", once the host has sent a byte (QEMU drops what a pty nobody reads is sent).  The records come from bench_data.c (hil/firmware.py: each kind's records
 * after its bumpless start, for the drive's config).
 */
#include <stdint.h>
#include <string.h>

#include "cobs.h"
#include "controller.h"
#include "crc32.h"
#include "drive.h"
#include "mps2.h"

#define N 2000

extern const double FW_PI_SS[], FW_PI_SP[], FW_PI_CS[], FW_PI_CP[];
extern const double FW_TRACK_SS[], FW_TRACK_SP[], FW_TRACK_CS[], FW_TRACK_CP[];
extern const double FW_NSS_SS[], FW_NSS_SP[], FW_NSS_CS[], FW_NSS_CP[];

static uint32_t now(void) { return TIMER_VALUE; } /* counts down */

static stage_state ss;
static stage_params sp;
static pi_state pc;
static pi_params pp;
static track_state tc;
static track_params tp;
static plant pl;
static double xs[N], vs[N], us[N];

/* The closed loop once (to get the inputs the controller sees), then the controller
 * alone on them, timed; returns instructions per tick. */
static uint32_t time_kind(int track, const double *s0, const double *p0, const double *c0, const double *q0)
{
    for (int pass = 0; pass < 2; pass++) {
        memcpy(&ss, s0, sizeof ss);
        memcpy(&sp, p0, sizeof sp);
        if (track) {
            memcpy(&tc, c0, sizeof tc);
            memcpy(&tp, q0, sizeof tp);
        } else {
            memcpy(&pc, c0, sizeof pc);
            memcpy(&pp, q0, sizeof pp);
        }
        pl = FW_DRIVE;
        double r = 0.0;
        uint32_t t0 = now();
        for (int k = 0; k < N; k++) {
            if (pass == 0)
                plant_measure(&pl, 0.0, 0.0, &xs[k], &vs[k]);
            r = k > N / 4 ? 1e-6 : 0.0;
            double u = track ? fw_track_tick(&ss, &sp, &tc, &tp, xs[k], vs[k], r, 0.0)
                             : fw_pi_tick(&ss, &sp, &pc, &pp, xs[k], vs[k], r, 0.0);
            if (pass == 0)
                plant_step(&pl, u, 0.0);
            else
                us[k] = u;
        }
        if (pass == 1)
            return (t0 - now()) * INSN_PER_COUNT / N;
    }
    return 0;
}

static uint32_t time_plant(void)
{
    pl = FW_DRIVE;
    double x, v;
    uint32_t t0 = now();
    for (int k = 0; k < N; k++) {
        plant_measure(&pl, 0.0, 0.0, &x, &v);
        plant_step(&pl, us[k], 0.0);
    }
    return (t0 - now()) * INSN_PER_COUNT / N;
}

/* A body of `out_values` float64 after its 12-byte header out (CRC, COBS) and one of
 * `in_values` in (COBS, CRC), N times; instructions per time.  Host in the loop, one
 * tick's frames at b = 1: SAMPLES (3 values) out, COMMANDS (1) in.  The loop on the
 * board: a LOG frame of one 13-column row out (`in_values` 0), or a REFS frame of 32
 * ticks (64 values) in (`out_values` 0). */
#define IN_MAX (12 + 8 * 64 + 4)
static uint32_t time_frames(int out_values, int in_values)
{
    static uint8_t body[12 + 8 * 13 + 4], enc[COBS_MAX(12 + 8 * 13 + 4)], in[IN_MAX], in_enc[COBS_MAX(IN_MAX)],
        dec[IN_MAX];
    size_t out_n = 12 + 8 * (size_t)out_values, in_n = 12 + 8 * (size_t)in_values;
    for (int j = 0; j < in_values; j++)
        memcpy(in + 12 + 8 * j, &us[j], 8);
    uint32_t c0 = crc32_bytes(in, in_n);
    memcpy(in + in_n, &c0, 4);
    size_t in_enc_n = cobs_encode(in, in_n + 4, in_enc);
    uint32_t t0 = now(), sink = 0;
    for (int k = 0; k < N; k++) {
        if (out_values) {
            for (int j = 0; j < out_values; j++)
                memcpy(body + 12 + 8 * j, j & 1 ? &vs[k] : &xs[k], 8);
            uint32_t c = crc32_bytes(body, out_n);
            memcpy(body + out_n, &c, 4);
            sink += (uint32_t)cobs_encode(body, out_n + 4, enc);
        }
        if (in_values) {
            long m = cobs_decode(in_enc, in_enc_n, dec);
            sink += crc32_bytes(dec, (size_t)m - 4);
        }
    }
    uint32_t t = (t0 - now()) * INSN_PER_COUNT / N;
    return t + (sink == 1u); /* keep the work */
}

int main(void)
{
    UART_BAUDDIV = 16;
    UART_CTRL = 3u;
    TIMER_RELOAD = 0xFFFFFFFFu;
    TIMER_VALUE = 0xFFFFFFFFu;
    TIMER_CTRL = 1u;
    while (!(UART_STATE & 2u)) /* a byte from the host: it is listening */
        ;
    (void)UART_DATA;
    static const char *names[3] = {"pi", "track", "nss"};
    const double *rec[3][4] = {{FW_PI_SS, FW_PI_SP, FW_PI_CS, FW_PI_CP},
                               {FW_TRACK_SS, FW_TRACK_SP, FW_TRACK_CS, FW_TRACK_CP},
                               {FW_NSS_SS, FW_NSS_SP, FW_NSS_CS, FW_NSS_CP}};
    for (int i = 0; i < 3; i++) {
        uint32_t c = time_kind(i > 0, rec[i][0], rec[i][1], rec[i][2], rec[i][3]);
        uint32_t p = time_plant();
        uint32_t f = time_frames(3, 1);
        uint32_t refs = time_frames(0, 64) / 32u, log = time_frames(13, 0);
        mps2_put(names[i]);
        mps2_put(" controller ");
        mps2_put_u32(c);
        mps2_put(" plant ");
        mps2_put_u32(p);
        mps2_put(" frames ");
        mps2_put_u32(f);
        mps2_put(" refs ");
        mps2_put_u32(refs);
        mps2_put(" log ");
        mps2_put_u32(log);
        mps2_put("\n");
    }
    mps2_put("done\n");
    for (;;)
        ;
}

void mps2_fault(void) {}
