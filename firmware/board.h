/* The board side of the serial link (docs/protocol.md, version 3): framing, the session
 * state machine and the safe state, around the four functions of hal.h.
 *
 *   IDLE --HELLO--> HELLO --CONFIG--> READY --START--> ACTIVE --STOP--> HELLO
 *   any fault (corrupt or out-of-sequence frame, malformed frame, watchdog, ready
 *   timeout, missed deadlines, bad command, output overflow) --> FAULTED
 *
 * Zero current (hal_write_current(0.0)) at board_init and in IDLE, HELLO and FAULTED;
 * READY holds the board's holding current (board_info) for at most the CONFIG's ready timeout,
 * ACTIVE applies the host's commands for at most the watchdog without a COMMANDS frame.
 * A HELLO while READY or ACTIVE is refused (ignored, counted, logged).  A CONFIG beyond
 * the documented limits (b 1..32, d 0..1000, watchdog 1..60 000 000 us, ready timeout
 * 1..60 000 ms, late limit no longer than the watchdog, the board's sample rate) is
 * refused with FAULT 6.
 *
 * The loop on the board (docs/protocol.md section 9, lockstep): after READY the host
 * sends the controller's records (LOOP), then each tick's reference (REFS); the board
 * runs the kind's kernels (controller.c) and streams log rows (LOG).  New parameters of
 * the kind (GAINS) take effect at the tick the host names, before that tick's controller
 * runs, and are acknowledged (GAINS_ACK); a GAINS out of range (a non-finite value, a
 * negative gain, an unstable biquad, another structure) is a fault at zero current.
 *
 * No heap, no floating-point exceptions, no library beyond <string.h> and <math.h>
 * (isfinite).  One `board` is about 40 KB (the command ring and the output buffer).
 */
#ifndef SERVO_FW_BOARD_H
#define SERVO_FW_BOARD_H

#include <stddef.h>
#include <stdint.h>

#include "records.h"

#define BOARD_VERSION 3          /* protocol version spoken (min = max) */
#define BOARD_MAX_BATCH 32       /* b, samples per frame */
#define BOARD_MAX_LATENCY 1000   /* d, ticks */
#define BOARD_MAX_WATCHDOG_US 60000000u
#define BOARD_MAX_READY_MS 60000u
#define BOARD_RING 2048          /* command ring, ticks; > MAX_LATENCY + 2 * MAX_BATCH */
#define BOARD_RX_MAX 1034        /* longest encoded frame, bytes */
#define BOARD_TX_BUF 16384       /* bytes of unsent output before an OVERFLOW fault */
#define BOARD_LOOP_BYTES 2048    /* the controller's four records, at most */
#define BOARD_LOG_MAX 13         /* log columns: the 12 common ones and one of the kind's */

enum board_state { BOARD_IDLE, BOARD_HELLO, BOARD_READY, BOARD_ACTIVE, BOARD_FAULTED };

enum { CAP_VELOCITY = 1, CAP_LOCKSTEP = 2, CAP_CURRENT = 4, CAP_LOOP = 8 };

enum {
    FAULT_WATCHDOG = 1, FAULT_DEADLINE, FAULT_CORRUPT, FAULT_SEQUENCE, FAULT_COMMAND, FAULT_CONFIG,
    FAULT_VERSION, FAULT_PROTOCOL, FAULT_OVERFLOW, FAULT_INTERNAL
};

/* STATS counters, in wire order. */
enum {
    ST_TICKS, ST_RX_FRAMES, ST_TX_FRAMES, ST_CRC, ST_FRAMING, ST_MALFORMED, ST_SEQ_DROPPED, ST_SEQ_REPEATED,
    ST_SEQ_REORDERED, ST_MISSED, ST_LATE, ST_WATCHDOG, ST_FAULTS, ST_OVERRUNS, ST_COUNT
};

/* What the board is: INFO's fields, and where its session lines go. */
typedef struct {
    const char *name;           /* up to 32 bytes UTF-8 */
    double sample_rate_hz;      /* f_s, Hz */
    double current_limit;       /* amplifier limit, A */
    double holding_current;     /* A: applied in READY and until the first command is due (the
                                   current that holds the drive at rest: 0.0 for a drive with no
                                   bias force; READY reports what hal_write_current returned) */
    int has_velocity;           /* 1: hal_read_position measures velocity */
    int lockstep;               /* 1: advance when commands arrive (simulation); 0: board_tick paces */
    void (*log)(const char *line); /* one line per session event; may be NULL */
} board_info;

typedef struct {
    board_info info;
    enum board_state state;
    uint32_t session;
    /* receiver */
    uint8_t rx[BOARD_RX_MAX + 1];
    size_t rx_len;
    int rx_skipping;
    uint16_t rx_seq, tx_seq;
    /* output: encoded frames not yet taken by hal_stream */
    uint8_t tx[BOARD_TX_BUF];
    size_t tx_len;
    uint32_t stats[ST_COUNT];
    uint32_t refused_hellos;
    /* the run's CONFIG */
    uint32_t d, b, late_limit, watchdog_us, ready_us;
    /* the run */
    uint32_t k;                 /* next tick to run */
    int sampled;                /* lockstep: the sample of tick k is taken */
    uint32_t sent;              /* ticks whose sample has been sent */
    uint32_t next_cmd;          /* tick of the next command expected */
    double batch[3 * BOARD_MAX_BATCH];
    uint32_t batch_n, batch_tick0;
    uint8_t status;
    uint32_t missed, in_a_row;
    uint32_t last_cmd_us, ready_since_us;
    double u_start, u_last, applied;
    uint32_t ring_tick[BOARD_RING];
    double ring_val[BOARD_RING];
    double ring_exc[BOARD_RING]; /* loop on the board: u_exc; ring_val holds r */
    uint8_t valid[BOARD_RING];
    uint16_t last_fault;
    /* loop on the board (LOOP before START): the controller's records, the host's
     * reference and excitation per tick */
    uint8_t loop_kind;          /* 0: host in the loop; 1: pi; 2: two-rate cascade (track, nss) */
    uint32_t loop_total, loop_got;
    uint64_t seed;              /* CONFIG: the seed of a simulated drive's sensor noise (a real drive ignores it) */
    uint32_t log_every;         /* the LOG rows are those of ticks k with k % log_every == 0 (LOOP) */
    union {
        uint8_t bytes[BOARD_LOOP_BYTES];
        struct { stage_state ss; stage_params sp; union { struct { pi_state c; pi_params p; } pi;
                                                         struct { track_state c; track_params p; } tr; } k; } r;
    } loop;
    uint32_t refs_next;         /* tick of the next reference expected */
    /* new parameters of the kind (GAINS), applied before tick gains_tick runs */
    int gains_pending;
    uint32_t gains_tick;
    union {
        pi_params pi;
        track_params tr;
    } gains;
} board;

/* Power-up: zero current, IDLE. */
void board_init(board *bd, const board_info *info);

/* Exchange bytes with the host, handle every frame received, advance (lockstep), check
 * the watchdog and the ready timeout.  Call it often (every tick, and while idle). */
void board_poll(board *bd);

/* Real time: run tick k at its deadline (apply the due command or hold the last one,
 * sample, send).  Call once per period while ACTIVE; does nothing otherwise. */
void board_tick(board *bd);

/* The current the amplifier applies now (A); 0.0 in the safe state. */
double board_applied_current(const board *bd);

#endif
