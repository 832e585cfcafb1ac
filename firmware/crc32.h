/* CRC-32/ISO-HDLC (zlib's): docs/protocol.md section 2. */
#ifndef SERVO_FW_CRC32_H
#define SERVO_FW_CRC32_H

#include <stddef.h>
#include <stdint.h>

/* CRC-32 of p[0..n); crc32_bytes("123456789", 9) == 0xCBF43926. */
uint32_t crc32_bytes(const uint8_t *p, size_t n);

#endif
