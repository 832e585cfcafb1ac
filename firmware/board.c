#include "board.h"

#include <math.h>
#include <string.h>

#include "cobs.h"
#include "controller.h"
#include "crc32.h"
#include "hal.h"

enum { HELLO = 0x01, CONFIG = 0x02, START = 0x03, COMMANDS = 0x04, STOP = 0x05, LOOP = 0x06, REFS = 0x07, GAINS = 0x08 };
enum { INFO = 0x81, READY = 0x82, SAMPLES = 0x84, FAULT = 0x85, STATS = 0x86, LOG = 0x87, GAINS_ACK = 0x88 };
#define STATUS_HELD 0x01
#define MAX_TEXT 200
#define BODY_MAX 1024

/* ------------------------------------------------------------------ little endian */

static uint16_t get16(const uint8_t *p) { return (uint16_t)(p[0] | p[1] << 8); }
static uint32_t get32(const uint8_t *p) { return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24; }
static uint64_t get64(const uint8_t *p) { return (uint64_t)get32(p) | (uint64_t)get32(p + 4) << 32; }
static double getf64(const uint8_t *p)
{
    uint64_t u = (uint64_t)get32(p) | (uint64_t)get32(p + 4) << 32;
    double d;
    memcpy(&d, &u, 8);
    return d;
}
static void put16(uint8_t *p, uint32_t v) { p[0] = (uint8_t)v; p[1] = (uint8_t)(v >> 8); }
static void put32(uint8_t *p, uint32_t v) { put16(p, v); put16(p + 2, v >> 16); }
static void putf64(uint8_t *p, double d)
{
    uint64_t u;
    memcpy(&u, &d, 8);
    put32(p, (uint32_t)u);
    put32(p + 4, (uint32_t)(u >> 32));
}

/* ------------------------------------------------------------------ text, no printf */

typedef struct {
    char s[MAX_TEXT + 1];
    size_t n;
} text;

static text *t_str(text *t, const char *s)
{
    while (*s && t->n < MAX_TEXT)
        t->s[t->n++] = *s++;
    t->s[t->n] = 0;
    return t;
}

static text *t_u32(text *t, uint32_t v)
{
    char buf[11];
    int i = 10;
    buf[i] = 0;
    do {
        buf[--i] = (char)('0' + v % 10u);
        v /= 10u;
    } while (v);
    return t_str(t, buf + i);
}

static void say(board *bd, text *t)
{
    if (bd->info.log)
        bd->info.log(t->s);
}

static text *t_session(text *t, const board *bd)
{
    t->n = 0;
    return t_u32(t_str(t, "session "), bd->session);
}

/* ------------------------------------------------------------------ output */

static void fault(board *bd, uint16_t code, const char *why, const text *detail);

static void send(board *bd, uint8_t *body, size_t n)
{
    uint8_t enc[COBS_MAX(BODY_MAX + 4)];
    put32(body + n, crc32_bytes(body, n));
    size_t m = cobs_encode(body, n + 4, enc);
    if (bd->tx_len + m + 1 > BOARD_TX_BUF) {
        bd->tx_len = 0;
        if (bd->state != BOARD_FAULTED) {
            text t = {{0}, 0};
            t_u32(t_str(&t, "more than "), BOARD_TX_BUF);
            fault(bd, FAULT_OVERFLOW, "", t_str(&t, " bytes unsent: the host is not reading"));
        }
        return;
    }
    memcpy(bd->tx + bd->tx_len, enc, m);
    bd->tx[bd->tx_len + m] = 0;
    bd->tx_len += m + 1;
    bd->tx_seq++;
    bd->stats[ST_TX_FRAMES]++;
}

static void header(board *bd, uint8_t *body, uint8_t type)
{
    body[0] = BOARD_VERSION;
    body[1] = type;
    put16(body + 2, bd->tx_seq);
}

static void send_stats(board *bd)
{
    uint8_t body[4 + 4 * ST_COUNT + 4];
    header(bd, body, STATS);
    for (int i = 0; i < ST_COUNT; i++)
        put32(body + 4 + 4 * i, bd->stats[i]);
    send(bd, body, 4 + 4 * ST_COUNT);
}

/* ------------------------------------------------------------------ safe state, faults */

static void safe(board *bd)
{
    bd->applied = hal_write_current(0.0);
    bd->applied = 0.0;
}

static void fault(board *bd, uint16_t code, const char *why, const text *detail)
{
    enum board_state was = bd->state;
    safe(bd);
    bd->stats[ST_FAULTS]++;
    bd->last_fault = code;
    text t = {{0}, 0};
    t_str(t_str(&t, why), detail ? detail->s : "");
    if (was == BOARD_HELLO || was == BOARD_READY || was == BOARD_ACTIVE) {
        uint8_t body[12 + MAX_TEXT + 4];
        header(bd, body, FAULT);
        put16(body + 4, code);
        put16(body + 6, 0);
        put32(body + 8, bd->k);
        memcpy(body + 12, t.s, t.n);
        bd->state = BOARD_FAULTED; /* an overflow inside these sends is not a second fault */
        send(bd, body, 12 + t.n);
        send_stats(bd);
    }
    bd->state = BOARD_FAULTED;
    text line;
    t_str(t_u32(t_str(t_session(&line, bd), ": FAULT "), code), " at tick ");
    t_str(t_str(t_str(t_u32(&line, bd->k), ": "), t.s), "; drive at zero current");
    say(bd, &line);
}

/* ------------------------------------------------------------------ the run */

static void reset_run(board *bd)
{
    bd->k = 0;
    bd->sampled = 0;
    bd->sent = 0;
    bd->next_cmd = 0;
    bd->batch_n = 0;
    bd->batch_tick0 = 0;
    bd->status = 0;
    bd->missed = 0;
    bd->in_a_row = 0;
    memset(bd->valid, 0, sizeof bd->valid);
}

static void sample(board *bd, uint32_t k)
{
    double x, v;
    hal_read_position(&x, &v);
    if (bd->batch_n == 0)
        bd->batch_tick0 = k;
    double *p = bd->batch + 3 * bd->batch_n;
    p[0] = x;
    p[1] = v;
    p[2] = bd->applied;
    if (++bd->batch_n == bd->b) {
        uint8_t body[12 + 24 * BOARD_MAX_BATCH + 4];
        header(bd, body, SAMPLES);
        put32(body + 4, bd->batch_tick0);
        body[8] = (uint8_t)bd->b;
        body[9] = bd->status;
        put16(body + 10, bd->missed > 0xFFFFu ? 0xFFFFu : bd->missed);
        for (uint32_t j = 0; j < 3 * bd->b; j++)
            putf64(body + 12 + 8 * j, bd->batch[j]);
        send(bd, body, 12 + 24 * bd->b);
        bd->sent = k + 1;
        bd->batch_n = 0;
        bd->status = 0;
    }
}

/* The command due at tick k (1), or none yet (0). */
static int due(const board *bd, uint32_t k, double *u)
{
    if (k < bd->d) {
        *u = bd->u_start;
        return 1;
    }
    uint32_t need = k - bd->d, i = need % BOARD_RING;
    if (bd->valid[i] && bd->ring_tick[i] == need) {
        *u = bd->ring_val[i];
        return 1;
    }
    return 0;
}

static uint32_t log_cols(const board *bd) { return bd->loop_kind == 2 ? 13u : 12u; }

/* Loop on the board, tick k with its reference r (m) and excitation u_exc (A): sample,
 * the controller kind, the current, one log row (kernels/compose.py's log_row). */
static void loop_tick(board *bd, uint32_t k, double r, double u_exc)
{
    double x, v, u;
    stage_state *c = &bd->loop.r.ss;
    hal_read_position(&x, &v);
    if (bd->loop_kind == 1)
        u = fw_pi_tick(c, &bd->loop.r.sp, &bd->loop.r.k.pi.c, &bd->loop.r.k.pi.p, x, v, r, u_exc);
    else
        u = fw_track_tick(c, &bd->loop.r.sp, &bd->loop.r.k.tr.c, &bd->loop.r.k.tr.p, x, v, r, u_exc);
    bd->applied = hal_write_current(u);
    if (k % bd->log_every)
        return; /* only every log_every-th tick's row is sent (LOOP) */
    if (bd->batch_n == 0)
        bd->batch_tick0 = k;
    double row[BOARD_LOG_MAX] = {(double)k, (double)k * bd->loop.r.sp.dt, c->x_prev + c->e, x, c->v, c->u, c->u_n,
                                 c->u_c, u_exc, c->H_dahl, c->regime, c->e, bd->loop.r.k.tr.c.pes};
    static double rows[BOARD_MAX_BATCH][BOARD_LOG_MAX];
    memcpy(rows[bd->batch_n], row, sizeof row);
    if (++bd->batch_n == bd->b) {
        static uint8_t body[12 + 8 * BOARD_MAX_BATCH * BOARD_LOG_MAX + 4];
        uint32_t nc = log_cols(bd);
        header(bd, body, LOG);
        put32(body + 4, bd->batch_tick0);
        body[8] = (uint8_t)bd->b;
        body[9] = (uint8_t)nc;
        put16(body + 10, 0);
        for (uint32_t i = 0; i < bd->b; i++)
            for (uint32_t j = 0; j < nc; j++)
                putf64(body + 12 + 8 * (i * nc + j), rows[i][j]);
        send(bd, body, 12 + 8 * bd->b * nc);
        bd->sent = k + 1;
        bd->batch_n = 0;
    }
}

/* GAINS due at tick k: the kind's parameters replaced, GAINS_ACK sent. */
static void apply_gains(board *bd)
{
    if (bd->loop_kind == 1)
        bd->loop.r.k.pi.p = bd->gains.pi;
    else
        bd->loop.r.k.tr.p = bd->gains.tr;
    bd->gains_pending = 0;
    uint8_t body[12 + 4];
    header(bd, body, GAINS_ACK);
    put32(body + 4, bd->k);
    body[8] = bd->loop_kind;
    body[9] = body[10] = body[11] = 0;
    send(bd, body, 12);
    text t;
    t_str(t_u32(t_str(t_session(&t, bd), ": new gains from tick "), bd->k), "");
    say(bd, &t);
}

static void advance(board *bd)
{
    if (bd->loop_kind) {
        while (bd->state == BOARD_ACTIVE) {
            uint32_t i = bd->k % BOARD_RING;
            if (!(bd->valid[i] && bd->ring_tick[i] == bd->k))
                return;
            if (bd->gains_pending && bd->gains_tick == bd->k)
                apply_gains(bd);
            if (bd->state != BOARD_ACTIVE)
                return;
            loop_tick(bd, bd->k, bd->ring_val[i], bd->ring_exc[i]);
            bd->k++;
            bd->stats[ST_TICKS]++;
        }
        return;
    }
    while (bd->state == BOARD_ACTIVE) {
        if (!bd->sampled) {
            sample(bd, bd->k);
            bd->sampled = 1;
            if (bd->state != BOARD_ACTIVE)
                return;
        }
        double u;
        if (!due(bd, bd->k, &u))
            return;
        bd->applied = hal_write_current(u);
        bd->k++;
        bd->sampled = 0;
        bd->stats[ST_TICKS]++;
    }
}

void board_tick(board *bd)
{
    if (bd->state != BOARD_ACTIVE)
        return;
    uint32_t k = bd->k;
    double u;
    if (due(bd, k, &u)) {
        if (k >= bd->d)
            bd->in_a_row = 0;
    } else {
        bd->stats[ST_MISSED]++;
        bd->missed++;
        bd->in_a_row++;
        bd->status |= STATUS_HELD;
        if (bd->in_a_row > bd->late_limit) {
            text t = {{0}, 0};
            t_u32(t_str(t_u32(t_str(&t, "the command of tick "), k - bd->d), " was not there at tick "), k);
            fault(bd, FAULT_DEADLINE, "", t_str(&t, ": host too slow or silent"));
            return;
        }
        u = bd->u_last;
    }
    sample(bd, k);
    if (bd->state != BOARD_ACTIVE)
        return;
    bd->applied = hal_write_current(u);
    bd->u_last = u;
    bd->k = k + 1;
    bd->stats[ST_TICKS]++;
}

/* ------------------------------------------------------------------ messages */

static void on_hello(board *bd, uint16_t seq, const uint8_t *body)
{
    if (bd->state == BOARD_READY || bd->state == BOARD_ACTIVE) {
        bd->refused_hellos++;
        text t;
        t_str(t_session(&t, bd), ": a HELLO refused: a session is running; it ends with its host's STOP, a fault or its watchdog");
        say(bd, &t);
        return;
    }
    safe(bd);
    bd->tx_len = 0;
    bd->session++;
    memset(bd->stats, 0, sizeof bd->stats);
    bd->stats[ST_RX_FRAMES] = 1;
    bd->state = BOARD_HELLO;
    bd->tx_seq = 0;
    bd->rx_seq = (uint16_t)(seq + 1);
    uint8_t out[32 + 32 + 4];
    header(bd, out, INFO);
    memcpy(out + 4, body + 4, 4); /* the nonce */
    out[8] = BOARD_VERSION;
    out[9] = BOARD_VERSION;
    put16(out + 10, (bd->info.has_velocity ? CAP_VELOCITY : 0) | CAP_CURRENT |
                        (bd->info.lockstep ? CAP_LOCKSTEP | CAP_LOOP : 0)); /* the loop on the board: lockstep only */
    putf64(out + 12, bd->info.sample_rate_hz);
    putf64(out + 20, bd->info.current_limit);
    put16(out + 28, BOARD_MAX_BATCH);
    put16(out + 30, BOARD_MAX_LATENCY);
    size_t n = strlen(bd->info.name);
    if (n > 32)
        n = 32;
    memcpy(out + 32, bd->info.name, n);
    send(bd, out, 32 + n);
}

/* Why a CONFIG is refused (1, with the reason in t), or 0. */
static int config_problem(const board *bd, const uint8_t *c, text *t)
{
    uint32_t version = c[4], b = c[5], d = get16(c + 6), wd = get32(c + 8), late = get16(c + 12);
    uint32_t ready_ms = get16(c + 14);
    double rate = getf64(c + 16);
    t->n = 0;
    if (version != BOARD_VERSION) {
        t_u32(t_str(t_u32(t_str(t, "protocol version "), version), " not spoken (board: "), BOARD_VERSION);
        t_str(t, ")");
    } else if (b < 1 || b > BOARD_MAX_BATCH) {
        t_u32(t_str(t_u32(t_str(t, "batch "), b), " outside 1.."), BOARD_MAX_BATCH);
    } else if (d > BOARD_MAX_LATENCY) {
        t_u32(t_str(t_u32(t_str(t, "latency "), d), " ticks > "), BOARD_MAX_LATENCY);
    } else if (bd->info.lockstep && d + 1 < b) {
        t_str(t_u32(t_str(t_u32(t_str(t, "latency "), d), " ticks < batch - 1 = "), b - 1), ": the link would deadlock");
    } else if (!bd->info.lockstep && d < b) {
        t_u32(t_str(t_u32(t_str(t, "latency "), d), " ticks < batch "), b);
        t_str(t, ": in real time the first command of a frame could never arrive in time");
    } else if (wd < 1 || wd > BOARD_MAX_WATCHDOG_US) {
        t_str(t_u32(t_str(t_u32(t_str(t, "watchdog "), wd), " us outside 1.."), BOARD_MAX_WATCHDOG_US), " us");
    } else if (ready_ms < 1 || ready_ms > BOARD_MAX_READY_MS) {
        t_str(t_u32(t_str(t_u32(t_str(t, "ready timeout "), ready_ms), " ms outside 1.."), BOARD_MAX_READY_MS), " ms");
    } else if ((double)late * 1e6 > (double)wd * bd->info.sample_rate_hz) {
        t_str(t_u32(t_str(t_u32(t_str(t, "late limit "), late), " ticks is longer than the watchdog ("), wd), " us)");
    } else if (!(fabs(rate - bd->info.sample_rate_hz) <= 1e-12 * fmax(fabs(rate), fabs(bd->info.sample_rate_hz)))) {
        t_str(t_u32(t_str(t, "the host expects another sample rate than the board's "), (uint32_t)bd->info.sample_rate_hz), " Hz");
    } else if (get64(c + 24) > 0x7FFFFFFFFFFFFFFFu) {
        t_str(t, "seed over 2^63 - 1");
    } else {
        return 0;
    }
    return 1;
}

static void on_config(board *bd, const uint8_t *c, uint32_t now)
{
    text t;
    if (config_problem(bd, c, &t)) {
        fault(bd, FAULT_CONFIG, "", &t);
        return;
    }
    safe(bd);
    reset_run(bd);
    bd->b = c[5];
    bd->d = get16(c + 6);
    bd->watchdog_us = get32(c + 8);
    bd->late_limit = get16(c + 12);
    bd->ready_us = (uint32_t)get16(c + 14) * 1000u;
    bd->seed = get64(c + 24); /* before tick 0's sample: a simulated drive seeds its noise with it */
    bd->loop_kind = 0;
    bd->loop_total = bd->loop_got = 0;
    bd->log_every = 1;
    bd->refs_next = 0;
    bd->gains_pending = 0;
    double u_hold = hal_write_current(bd->info.holding_current);
    bd->u_start = bd->u_last = bd->applied = u_hold;
    double x, v;
    hal_read_position(&x, &v); /* tick 0's sample */
    bd->state = BOARD_READY;
    bd->ready_since_us = now;
    uint8_t out[56 + 4];
    header(bd, out, READY);
    memcpy(out + 4, c + 4, 28);
    putf64(out + 32, x);
    putf64(out + 40, v);
    putf64(out + 48, u_hold);
    send(bd, out, 56);
}

static void on_start(board *bd, uint32_t now)
{
    if (bd->loop_kind && bd->loop_got != bd->loop_total) {
        text t = {{0}, 0};
        fault(bd, FAULT_PROTOCOL, "", t_str(&t, "START before the controller's records were all sent"));
        return;
    }
    bd->state = BOARD_ACTIVE;
    bd->last_cmd_us = now;
    memset(bd->valid, 0, sizeof bd->valid);
    text t;
    t_str(t_str(t_session(&t, bd), ": started ("), bd->info.lockstep ? "lockstep" : "real time");
    t_u32(t_str(&t, ", d = "), bd->d);
    t_str(t_u32(t_str(&t, ", batch = "), bd->b), ")");
    say(bd, &t);
    if (bd->info.lockstep)
        advance(bd);
}

static void on_commands(board *bd, const uint8_t *body, uint32_t n, uint32_t now)
{
    uint32_t first = bd->next_cmd;
    text t = {{0}, 0};
    if (get32(body + 4) != first) {
        t_u32(t_str(t_u32(t_str(&t, "commands for tick "), get32(body + 4)), ", expected tick "), first);
        fault(bd, FAULT_COMMAND, "", &t);
        return;
    }
    if (first + n > bd->sent) {
        t_u32(t_str(t_u32(t_str(&t, "commands up to tick "), first + n - 1), ", but samples sent only up to tick "), bd->sent - 1);
        fault(bd, FAULT_COMMAND, "", &t);
        return;
    }
    for (uint32_t j = 0; j < n; j++)
        if (!isfinite(getf64(body + 12 + 8 * j))) {
            t_u32(t_str(t_u32(t_str(&t, "non-finite current command for ticks "), first), ".."), first + n - 1);
            fault(bd, FAULT_COMMAND, "", &t);
            return;
        }
    uint32_t due_passed = bd->k - bd->d; /* real time: commands of ticks before this are late */
    for (uint32_t j = 0; j < n; j++) {
        uint32_t tk = first + j, i = tk % BOARD_RING;
        bd->ring_tick[i] = tk;
        bd->ring_val[i] = getf64(body + 12 + 8 * j);
        bd->valid[i] = 1;
        if (!bd->info.lockstep && bd->k >= bd->d && tk < due_passed)
            bd->stats[ST_LATE]++;
    }
    bd->next_cmd = first + n;
    bd->last_cmd_us = now;
    if (bd->info.lockstep)
        advance(bd);
}

/* LOOP (READY): the controller's records, in pieces: kind, byte offset, total, bytes. */
static void on_loop(board *bd, const uint8_t *body, size_t n)
{
    uint32_t kind = body[4], off = get16(body + 6), total = get16(body + 8), len = (uint32_t)n - 12;
    uint32_t every = get16(body + 10) ? get16(body + 10) : 1u; /* 0: every tick (hosts of before) */
    uint32_t want = kind == 1 ? sizeof(stage_state) + sizeof(stage_params) + sizeof(pi_state) + sizeof(pi_params)
                              : sizeof(stage_state) + sizeof(stage_params) + sizeof(track_state) + sizeof(track_params);
    text t = {{0}, 0};
    if (!bd->info.lockstep || (kind != 1 && kind != 2) || total != want || off != bd->loop_got || off + len > total ||
        12u + 8u * bd->b * (kind == 2 ? 13u : 12u) > BODY_MAX || (off > 0 && every != bd->log_every)) {
        t_u32(t_str(t_u32(t_str(t_u32(t_str(&t, "LOOP kind "), kind), ", records of "), total), " bytes at "), off);
        fault(bd, FAULT_CONFIG, "", t_str(&t, ": not a controller this board runs, a batch too large for its log rows, "
                                              "another log period in a later piece, or a real-time board (the loop on the "
                                              "board runs in lockstep only)"));
        return;
    }
    bd->loop_kind = (uint8_t)kind;
    bd->loop_total = total;
    bd->log_every = every;
    memcpy(bd->loop.bytes + off, body + 12, len); /* the host's buf: the four records back to back */
    bd->loop_got = off + len;
}

/* REFS (ACTIVE, loop on the board): r (m) and u_exc (A) of ticks tick0 .. tick0+n-1. */
static void on_refs(board *bd, const uint8_t *body, uint32_t n, uint32_t now)
{
    text t = {{0}, 0};
    if (get32(body + 4) != bd->refs_next) {
        t_u32(t_str(t_u32(t_str(&t, "references for tick "), get32(body + 4)), ", expected tick "), bd->refs_next);
        fault(bd, FAULT_COMMAND, "", &t);
        return;
    }
    for (uint32_t j = 0; j < n; j++) {
        double r = getf64(body + 12 + 16 * j), e = getf64(body + 20 + 16 * j);
        if (!isfinite(r) || !isfinite(e)) {
            fault(bd, FAULT_COMMAND, "", t_str(&t, "a non-finite reference or excitation"));
            return;
        }
        uint32_t tk = bd->refs_next + j, i = tk % BOARD_RING;
        bd->ring_tick[i] = tk;
        bd->ring_val[i] = r;
        bd->ring_exc[i] = e;
        bd->valid[i] = 1;
    }
    bd->refs_next += n;
    bd->last_cmd_us = now;
    advance(bd);
}

/* A biquad section (b0 b1 b2 1 a1 a2) with no pole outside the unit circle (the Jury
 * conditions, to 1e-9: an integrator's pole at z = 1 is on it). */
static int stable_section(const double *s) { return fabs(s[5]) <= 1.0 + 1e-9 && fabs(s[4]) <= 1.0 + s[5] + 1e-9; }

/* Why new parameters of the running kind are refused (1, the reason in t), or 0. */
static int gains_problem(const board *bd, const double *v, size_t n, text *t)
{
    for (size_t i = 0; i < n; i++)
        if (!isfinite(v[i])) {
            t_u32(t_str(t, "a non-finite parameter (value "), (uint32_t)i);
            t_str(t, ")");
            return 1;
        }
    if (bd->loop_kind == 1) {
        const pi_params *p = (const pi_params *)v, *now = &bd->loop.r.k.pi.p;
        if (p->dt != now->dt)
            t_str(t, "another sample period");
        else if (p->kp < 0.0 || p->ki < 0.0 || p->kd < 0.0)
            t_str(t, "a negative gain");
        else if (p->b < 0.0 || p->b > 1.0)
            t_str(t, "a setpoint weight outside 0..1");
        else if (!(p->u_n_max > 0.0))
            t_str(t, "an output limit not above 0 A");
        else
            return 0;
        return 1;
    }
    const track_params *q = (const track_params *)v, *now = &bd->loop.r.k.tr.p;
    if (q->pes_every != now->pes_every || q->n_slow != now->n_slow || q->n_fast != now->n_fast) {
        t_str(t, "another structure (PES rate or number of biquads)");
        return 1;
    }
    for (int64_t i = 0; i < (int64_t)q->n_slow; i++)
        if (!stable_section(q->sos_slow[i])) {
            t_u32(t_str(t, "a biquad with a pole outside the unit circle (slow section "), (uint32_t)i);
            t_str(t, ")");
            return 1;
        }
    for (int64_t i = 0; i < (int64_t)q->n_fast; i++)
        if (!stable_section(q->sos_fast[i])) {
            t_u32(t_str(t, "a biquad with a pole outside the unit circle (fast section "), (uint32_t)i);
            t_str(t, ")");
            return 1;
        }
    if (!(q->u_n_max > 0.0)) {
        t_str(t, "an output limit not above 0 A");
        return 1;
    }
    return 0;
}

/* GAINS (ACTIVE, loop on the board): u32 tick, u8 kernels, u8 reserved, u16 bytes, u32
 * reserved, then the kind's parameter record; applied before tick `tick` runs. */
static void on_gains(board *bd, const uint8_t *body, size_t n)
{
    uint32_t tick = get32(body + 4), kind = body[8], bytes = get16(body + 10);
    size_t want = bd->loop_kind == 1 ? sizeof(pi_params) : sizeof(track_params);
    text t = {{0}, 0};
    t_str(t_u32(t_str(&t, "GAINS for tick "), tick), ": ");
    if (kind != bd->loop_kind || bytes != want || n != 16 + want) {
        t_str(t_u32(t_str(&t, "kernels "), kind), ", not the running kind's parameters");
    } else if (bd->gains_pending) {
        t_str(t_u32(t_str(&t, "the GAINS for tick "), bd->gains_tick), " is not applied yet");
    } else if ((int32_t)(tick - bd->k) < 0) {
        t_str(t_u32(t_str(&t, "tick "), bd->k), " is already running");
    } else {
        double v[sizeof(track_params) / 8];
        for (size_t i = 0; i < want / 8; i++)
            v[i] = getf64(body + 16 + 8 * i);
        if (!gains_problem(bd, v, want / 8, &t)) {
            memcpy(&bd->gains, v, want);
            bd->gains_tick = tick;
            bd->gains_pending = 1;
            return;
        }
    }
    fault(bd, FAULT_COMMAND, "", &t);
}

static void on_stop(board *bd)
{
    enum board_state was = bd->state;
    safe(bd);
    text t;
    if (was == BOARD_READY) {
        t_str(t_session(&t, bd), ": stopped by the host before START; drive at zero current");
        say(bd, &t);
    } else if (was == BOARD_ACTIVE) {
        t_str(t_u32(t_str(t_session(&t, bd), ": stopped by the host after "), bd->k), " ticks; drive at zero current");
        say(bd, &t);
    }
    send_stats(bd);
    bd->state = BOARD_HELLO;
}

/* Length of a host message of this type, or 0 if unknown; COMMANDS: from its count. */
static size_t expected_len(const uint8_t *body, size_t n)
{
    switch (body[1]) {
    case HELLO: return 12;
    case CONFIG: return 32;
    case START: case STOP: return 4;
    case COMMANDS:
        if (n < 12 || body[8] < 1 || body[8] > BOARD_MAX_BATCH)
            return (size_t)-1;
        return 12 + 8u * body[8];
    case LOOP:
        return n >= 13 && n <= BODY_MAX ? n : (size_t)-1;
    case REFS:
        if (n < 12 || body[8] < 1 || body[8] > BOARD_MAX_BATCH)
            return (size_t)-1;
        return 12 + 16u * body[8];
    case GAINS:
        return n >= 16 && n <= BODY_MAX ? n : (size_t)-1;
    default: return 0;
    }
}

static int in_session(const board *bd)
{
    return bd->state == BOARD_HELLO || bd->state == BOARD_READY || bd->state == BOARD_ACTIVE;
}

static void on_frame(board *bd, const uint8_t *body, size_t n, uint32_t now)
{
    text t = {{0}, 0};
    size_t want = n >= 4 ? expected_len(body, n) : (size_t)-1;
    if (n < 4 || want != n || (body[0] != BOARD_VERSION && body[1] != HELLO)) {
        bd->stats[ST_MALFORMED]++;
        if (in_session(bd)) {
            if (n < 4)
                t_str(&t, "a frame shorter than its header");
            else if (want == 0)
                t_u32(t_str(&t, "unknown message type "), body[1]);
            else if (want != n)
                t_u32(t_str(t_u32(t_str(&t, "a frame of type "), body[1]), " of the wrong length "), (uint32_t)n);
            else
                t_u32(t_str(&t, "protocol version "), body[0]);
            fault(bd, FAULT_PROTOCOL, "malformed frame from the host: ", &t);
        }
        return;
    }
    uint8_t kind = body[1];
    uint16_t seq = get16(body + 2);
    bd->stats[ST_RX_FRAMES]++;
    if (kind == HELLO) {
        on_hello(bd, seq, body);
        return;
    }
    if (bd->state == BOARD_READY)
        bd->ready_since_us = now; /* the host is there */
    if (bd->state == BOARD_IDLE || bd->state == BOARD_FAULTED) {
        if (kind == STOP && bd->state == BOARD_FAULTED)
            send_stats(bd);
        return; /* no session: stale bytes of an earlier one */
    }
    if (seq != bd->rx_seq) {
        int16_t delta = (int16_t)(uint16_t)(seq - bd->rx_seq);
        bd->stats[delta == -1 ? ST_SEQ_REPEATED : delta < -1 ? ST_SEQ_REORDERED : ST_SEQ_DROPPED]++;
        t_u32(t_str(t_u32(t_str(&t, "host frame seq "), seq), ", expected "), bd->rx_seq);
        t_str(&t, delta == -1 ? ": a repeated frame (duplicated)" : delta < -1 ? ": an older frame (reordered)" : ": frame(s) missing (dropped)");
        fault(bd, FAULT_SEQUENCE, "", &t);
        return;
    }
    bd->rx_seq = (uint16_t)(seq + 1);
    if (kind == COMMANDS && bd->state == BOARD_ACTIVE && !bd->loop_kind)
        on_commands(bd, body, body[8], now);
    else if (kind == REFS && bd->state == BOARD_ACTIVE && bd->loop_kind)
        on_refs(bd, body, body[8], now);
    else if (kind == GAINS && bd->state == BOARD_ACTIVE && bd->loop_kind)
        on_gains(bd, body, n);
    else if (kind == LOOP && bd->state == BOARD_READY)
        on_loop(bd, body, n);
    else if (kind == CONFIG && (bd->state == BOARD_HELLO || bd->state == BOARD_READY))
        on_config(bd, body, now);
    else if (kind == START && bd->state == BOARD_READY)
        on_start(bd, now);
    else if (kind == STOP)
        on_stop(bd);
    else {
        t_u32(t_str(&t, "message type "), kind);
        fault(bd, FAULT_PROTOCOL, "", t_str(&t, " is not expected in this state"));
    }
}

/* A corrupt chunk (CRC, COBS, oversize): a fault in a session, else ignored. */
static void corrupt(board *bd, int counter, const char *why)
{
    bd->stats[counter]++;
    if (in_session(bd)) {
        text t = {{0}, 0};
        fault(bd, FAULT_CORRUPT, "corrupt frame from the host ", t_str(&t, why));
    }
}

static void chunk(board *bd, uint32_t now)
{
    uint8_t dec[BOARD_RX_MAX];
    long n = cobs_decode(bd->rx, bd->rx_len, dec);
    if (n < 0) {
        corrupt(bd, ST_FRAMING, "(bad byte stuffing)");
        return;
    }
    if (n < 5 || crc32_bytes(dec, (size_t)n - 4) != get32(dec + n - 4)) {
        corrupt(bd, ST_CRC, "(CRC mismatch)");
        return;
    }
    on_frame(bd, dec, (size_t)n - 4, now);
}

static void receive(board *bd, const uint8_t *data, size_t n, uint32_t now)
{
    for (size_t i = 0; i < n; i++) {
        uint8_t c = data[i];
        if (c == 0) {
            if (bd->rx_skipping)
                bd->rx_skipping = 0;
            else if (bd->rx_len)
                chunk(bd, now);
            bd->rx_len = 0;
        } else if (!bd->rx_skipping) {
            if (bd->rx_len == BOARD_RX_MAX) {
                bd->rx_len = 0;
                bd->rx_skipping = 1;
                corrupt(bd, ST_FRAMING, "(no delimiter)");
            } else {
                bd->rx[bd->rx_len++] = c;
            }
        }
    }
}

/* ------------------------------------------------------------------ time, polling */

static void check_timeouts(board *bd, uint32_t now)
{
    text t = {{0}, 0};
    if (bd->state == BOARD_ACTIVE && now - bd->last_cmd_us > bd->watchdog_us) {
        bd->stats[ST_WATCHDOG]++;
        t_str(t_u32(t_str(&t, "no command for "), (now - bd->last_cmd_us) / 1000u), " ms (watchdog ");
        t_str(t_u32(&t, bd->watchdog_us / 1000u), " ms)");
        fault(bd, FAULT_WATCHDOG, "", &t);
    } else if (bd->state == BOARD_READY && now - bd->ready_since_us > bd->ready_us) {
        bd->stats[ST_WATCHDOG]++;
        t_str(t_u32(t_str(&t, "no START or STOP for "), (now - bd->ready_since_us) / 1000u), " ms after READY: the host is gone");
        fault(bd, FAULT_WATCHDOG, "", &t);
    }
}

static void flush(board *bd, uint8_t *rx, size_t *n, size_t rx_cap)
{
    size_t taken = 0;
    *n = hal_stream(bd->tx, bd->tx_len, &taken, rx, rx_cap);
    if (taken) {
        memmove(bd->tx, bd->tx + taken, bd->tx_len - taken);
        bd->tx_len -= taken;
    }
}

void board_poll(board *bd)
{
    uint8_t rx[256];
    size_t n;
    flush(bd, rx, &n, sizeof rx);
    if (n)
        receive(bd, rx, n, hal_now_us());
    check_timeouts(bd, hal_now_us());
    if (bd->tx_len)
        flush(bd, rx, &n, 0); /* what this poll produced, out now */
}

void board_init(board *bd, const board_info *info)
{
    memset(bd, 0, sizeof *bd);
    bd->info = *info;
    bd->state = BOARD_IDLE;
    safe(bd);
}

double board_applied_current(const board *bd) { return bd->applied; }
