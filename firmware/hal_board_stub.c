/* What a real board provides: the four functions of hal.h, for an amplifier, an encoder,
 * a timer and a UART.  A template, not built by default: copy it, fill in the register
 * accesses of your part, build it with the portable sources (cobs.c, crc32.c, board.c,
 * controller.c, dahl.c) and your main (see docs/firmware.md, "Porting to a real board").
 *
 * Your main also fills board_info: the board's name, sample rate f_s (Hz, the timer's),
 * the amplifier's current limit (A), whether hal_read_position measures velocity, the
 * holding current (A) the session applies in READY (0.0 unless the drive needs a bias
 * current to rest where it is, e.g. against a flex cable's spring), lockstep = 0 (real
 * time), and a log function or NULL.
 */
#ifndef SERVO_FW_PORT
#error "hal_board_stub.c is a template: copy it and fill in your board's registers (docs/firmware.md)"
#endif
#include <math.h>

#include "hal.h"

/* The encoder (or the position channel of your ADC), read at the start of the tick:
 * position of the head in metres (counts times the scale), velocity in m/s if the board
 * measures it (a laser vibrometer, a tachometer), else NAN (the controller then
 * differentiates the position).  Must take the same time every tick. */
void hal_read_position(double *x, double *v)
{
    *x = 0.0; /* = (int32_t)ENCODER_COUNT * METRES_PER_COUNT */
    *v = NAN;
}

/* The amplifier's current command: the DAC or PWM set point for `amps`, clipped to the
 * amplifier's limit; return the current applied (the clipped value, or the current
 * sensor's reading if the board has one).  hal_write_current(0.0) is the safe state: it
 * must open the amplifier's input at once, from any context. */
double hal_write_current(double amps)
{
    const double limit = 1.0; /* A: the amplifier's limit, also INFO's */
    double a = amps > limit ? limit : amps < -limit ? -limit : amps;
    /* DAC_DATA = (uint32_t)((a / limit + 1.0) * 0.5 * DAC_FULL_SCALE); */
    return a;
}

/* A free-running microsecond counter (a 32-bit timer at 1 MHz, or a cycle counter
 * divided down); it wraps at 2^32. */
uint32_t hal_now_us(void)
{
    return 0u; /* = TIMER_COUNT */
}

/* The byte stream: hand the UART (or USB CDC endpoint) what it takes now from tx, and
 * copy the bytes received since the last call (an interrupt-filled ring buffer) to rx.
 * Never block: the tick is waiting. */
size_t hal_stream(const uint8_t *tx, size_t tx_len, size_t *tx_taken, uint8_t *rx, size_t rx_cap)
{
    (void)tx;
    (void)tx_len;
    (void)rx;
    (void)rx_cap;
    *tx_taken = 0;
    return 0;
}
