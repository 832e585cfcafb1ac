/* The firmware built for the host: a process serving the board on a fresh pseudo-terminal
 * (the stream half of hal.h), its drive simulated (hal_sim.c).  POSIX, not part of the
 * portable firmware.
 *
 *   servo_fw_host [--realtime]
 *
 * prints "servo firmware: listening on /dev/pts/N", then one line per session event.
 * Lockstep by default (the board advances when commands arrive, as `servo emulate
 * --lockstep`); --realtime paces board_tick on the monotonic clock.  SIGTERM or SIGINT:
 * zero current, exit 0.
 */
#define _XOPEN_SOURCE 600
#define _DEFAULT_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "board.h"
#include "drive.h"
#include "hal.h"

static int master = -1;
static volatile sig_atomic_t stop;

static uint64_t now_ns(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (uint64_t)ts.tv_sec * 1000000000u + (uint64_t)ts.tv_nsec;
}

uint32_t hal_now_us(void) { return (uint32_t)(now_ns() / 1000u); }

size_t hal_stream(const uint8_t *tx, size_t tx_len, size_t *tx_taken, uint8_t *rx, size_t rx_cap)
{
    *tx_taken = 0;
    if (tx_len) {
        ssize_t w = write(master, tx, tx_len);
        if (w > 0)
            *tx_taken = (size_t)w;
    }
    ssize_t r = read(master, rx, rx_cap);
    return r > 0 ? (size_t)r : 0;
}

static void log_line(const char *line)
{
    printf("%s\n", line);
    fflush(stdout);
}

static void on_signal(int sig) { (void)sig; stop = 1; }

int main(int argc, char **argv)
{
    int realtime = argc > 1 && strcmp(argv[1], "--realtime") == 0;
    master = posix_openpt(O_RDWR | O_NOCTTY);
    if (master < 0 || grantpt(master) || unlockpt(master)) {
        perror("servo firmware: pty");
        return 1;
    }
    const char *path = ptsname(master);
    int slave = open(path, O_RDWR | O_NOCTTY); /* held open: a host may close and reopen */
    struct termios tio;
    tcgetattr(slave, &tio);
    cfmakeraw(&tio);
    tcsetattr(slave, TCSANOW, &tio);
    fcntl(master, F_SETFL, fcntl(master, F_GETFL) | O_NONBLOCK);
    signal(SIGTERM, on_signal);
    signal(SIGINT, on_signal);

    static board bd;
    board_info info = {"servo firmware (host build)", FW_SAMPLE_RATE_HZ, FW_DRIVE.p.u_max, FW_DRIVE.u_hold,
                       FW_HAS_VELOCITY, !realtime, log_line};
    board_init(&bd, &info);
    sim_park();
    printf("servo firmware: listening on %s (%s)\n", path, realtime ? "real time" : "lockstep");
    fflush(stdout);
    uint64_t period = (uint64_t)(1e9 / FW_SAMPLE_RATE_HZ + 0.5), next = 0;
    while (!stop) {
        if (realtime && bd.state == BOARD_ACTIVE) {
            if (next == 0)
                next = now_ns();
            struct timespec at = {(time_t)(next / 1000000000u), (long)(next % 1000000000u)};
            clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &at, NULL); /* the tick's deadline */
            sim_poll(&bd);
            board_tick(&bd);
            next += period;
            continue;
        }
        next = 0;
        struct pollfd p = {master, (short)(POLLIN | (bd.tx_len ? POLLOUT : 0)), 0};
        poll(&p, 1, 1);
        sim_poll(&bd);
    }
    hal_write_current(0.0);
    printf("servo firmware: stopped; drive at zero current\n");
    close(slave);
    close(master);
    return 0;
}
