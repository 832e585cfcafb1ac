/* Instructions per tick of the firmware's kernels on the MPS2 AN500 (Cortex-M7), counted
 * on QEMU with -icount shift=0 (one instruction per virtual nanosecond: TIMER0, at 25 MHz
 * of virtual time, counts 40 instructions per step).  Not a board's program: it runs the
 * closed loop of each controller kind against the simulated drive and writes, on UART0,
 *
 *   <kind> controller <n> plant <n> frames <n> loop_frames <n>     (instructions per tick)
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

#define REG(a) (*(volatile uint32_t *)(a))
#define UART_DATA REG(0x40004000u)
#define UART_STATE REG(0x40004004u)
#define UART_CTRL REG(0x40004008u)
#define UART_BAUDDIV REG(0x40004010u)
#define TIMER_CTRL REG(0x40000000u)
#define TIMER_VALUE REG(0x40000004u)
#define TIMER_RELOAD REG(0x40000008u)
#define CPACR REG(0xE000ED88u)
#define N 2000
#define INSN_PER_COUNT 40u /* 1 ns per instruction, 40 ns per 25 MHz count */

extern const double FW_PI_SS[], FW_PI_SP[], FW_PI_CS[], FW_PI_CP[];
extern const double FW_TRACK_SS[], FW_TRACK_SP[], FW_TRACK_CS[], FW_TRACK_CP[];
extern const double FW_NSS_SS[], FW_NSS_SP[], FW_NSS_CS[], FW_NSS_CP[];

static void put(const char *s)
{
    while (*s) {
        while (UART_STATE & 1u)
            ;
        UART_DATA = (uint8_t)*s++;
    }
}

static void put_u32(uint32_t v)
{
    char b[11];
    int i = 10;
    b[i] = 0;
    do {
        b[--i] = (char)('0' + v % 10u);
        v /= 10u;
    } while (v);
    put(b + i);
}

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

/* One SAMPLES frame out (b = 1: CRC, COBS) and one COMMANDS frame in (COBS, CRC). */
static uint32_t time_frames(void)
{
    static uint8_t body[40], enc[64], cmd[28], cmd_enc[40], dec[40];
    memcpy(cmd + 12, &us[0], 8);
    uint32_t c0 = crc32_bytes(cmd, 20);
    memcpy(cmd + 20, &c0, 4);
    size_t cmd_n = cobs_encode(cmd, 24, cmd_enc);
    uint32_t t0 = now(), sink = 0;
    for (int k = 0; k < N; k++) {
        memcpy(body + 12, &xs[k], 8);
        memcpy(body + 20, &vs[k], 8);
        uint32_t c = crc32_bytes(body, 36);
        memcpy(body + 36, &c, 4);
        sink += (uint32_t)cobs_encode(body, 40, enc);
        long m = cobs_decode(cmd_enc, cmd_n, dec);
        sink += crc32_bytes(dec, (size_t)m - 4);
    }
    uint32_t t = (t0 - now()) * INSN_PER_COUNT / N;
    return t + (sink == 1u); /* keep the work */
}

/* The loop on the board's frames of one tick at b = 1: a LOG frame out (13 columns: CRC,
 * COBS) and a REFS frame in (COBS, CRC). */
static uint32_t time_loop_frames(void)
{
    static uint8_t body[12 + 8 * 13 + 4], enc[140], refs[12 + 16 + 4], refs_enc[40], dec[40];
    memcpy(refs + 12, &xs[0], 8);
    uint32_t c0 = crc32_bytes(refs, 28);
    memcpy(refs + 28, &c0, 4);
    size_t refs_n = cobs_encode(refs, 32, refs_enc);
    uint32_t t0 = now(), sink = 0;
    for (int k = 0; k < N; k++) {
        for (int j = 0; j < 13; j++)
            memcpy(body + 12 + 8 * j, j & 1 ? &vs[k] : &xs[k], 8);
        uint32_t c = crc32_bytes(body, 12 + 8 * 13);
        memcpy(body + 12 + 8 * 13, &c, 4);
        sink += (uint32_t)cobs_encode(body, sizeof body, enc);
        long m = cobs_decode(refs_enc, refs_n, dec);
        sink += crc32_bytes(dec, (size_t)m - 4);
    }
    uint32_t t = (t0 - now()) * INSN_PER_COUNT / N;
    return t + (sink == 1u);
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
        uint32_t f = time_frames();
        uint32_t lf = time_loop_frames();
        put(names[i]);
        put(" controller ");
        put_u32(c);
        put(" plant ");
        put_u32(p);
        put(" frames ");
        put_u32(f);
        put(" loop_frames ");
        put_u32(lf);
        put("\n");
    }
    put("done\n");
    for (;;)
        ;
}

extern uint32_t __data_load, __data_start, __data_end, __bss_start, __bss_end, __stack_top;

void reset_handler(void)
{
    uint32_t *src = &__data_load, *dst = &__data_start;
    while (dst < &__data_end)
        *dst++ = *src++;
    for (dst = &__bss_start; dst < &__bss_end;)
        *dst++ = 0;
    CPACR |= 0xFu << 20;
    __asm__ volatile("dsb\n isb");
    main();
}

static void hang(void)
{
    for (;;)
        ;
}

__attribute__((section(".vectors"), used)) static void (*const vectors[16])(void) = {
    (void (*)(void))&__stack_top, reset_handler, hang, hang, hang, hang, hang, 0, 0, 0, 0, hang, hang, 0, hang, hang,
};
