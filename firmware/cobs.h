/* COBS (Cheshire and Baker, 1999), without a trailing zero: docs/protocol.md section 2. */
#ifndef SERVO_FW_COBS_H
#define SERVO_FW_COBS_H

#include <stddef.h>
#include <stdint.h>

/* Bytes cobs_encode writes for n input bytes, at most. */
#define COBS_MAX(n) ((n) + (n) / 254 + 1)

/* Stuff src[0..n) into dst (room for COBS_MAX(n)); returns the length written (no 0x00 in it). */
size_t cobs_encode(const uint8_t *src, size_t n, uint8_t *dst);

/* Unstuff src[0..n) (no delimiter) into dst (room for n); returns the length, or -1 if
 * the bytes are not valid COBS (a zero inside, a code past the end). */
long cobs_decode(const uint8_t *src, size_t n, uint8_t *dst);

#endif
