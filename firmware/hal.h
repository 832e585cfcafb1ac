/* The hardware abstraction: what a board must provide to run this firmware.
 *
 * Four functions, called only from board.c, never from an interrupt:
 *
 *   hal_read_position  the sensors at this tick: position (m at the head) and velocity
 *                      (m/s; NaN without a velocity sensor);
 *   hal_write_current  the amplifier: apply this current (A) until the next call; returns
 *                      the current actually applied (after the amplifier's own limit), A;
 *   hal_now_us         the tick source: a free-running microsecond clock (wraps at 2^32);
 *   hal_stream         the byte stream to the host (UART, USB CDC, a pty): takes what it
 *                      can of the bytes to send, returns the bytes received, never blocks.
 *
 * Nothing else: the holding current of READY is a constant of the board (board_info's
 * holding_current, applied with hal_write_current), and the safe state is
 * hal_write_current(0.0): the board calls it at power-up (board_init), at every CONFIG
 * before the holding current, and on every fault, STOP and timeout.
 */
#ifndef SERVO_FW_HAL_H
#define SERVO_FW_HAL_H

#include <stddef.h>
#include <stdint.h>

/* Position x (m) and velocity v (m/s, NaN if not measured) of the drive now. */
void hal_read_position(double *x, double *v);

/* Apply `amps` (A) from now on; returns the current applied (A), e.g. after clipping. */
double hal_write_current(double amps);

/* Microseconds since an arbitrary origin, modulo 2^32. */
uint32_t hal_now_us(void);

/* Offer tx[0..tx_len) to the host (*tx_taken: bytes accepted), and copy up to rx_cap
 * received bytes into rx; returns the count received (0: none now).  Never blocks. */
size_t hal_stream(const uint8_t *tx, size_t tx_len, size_t *tx_taken, uint8_t *rx, size_t rx_cap);

#endif
