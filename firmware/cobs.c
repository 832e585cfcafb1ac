#include "cobs.h"

size_t cobs_encode(const uint8_t *src, size_t n, uint8_t *dst)
{
    size_t code_at = 0, out = 1;
    uint8_t code = 1;
    for (size_t i = 0; i < n; i++) {
        if (src[i] == 0) {
            dst[code_at] = code;
            code_at = out++;
            code = 1;
        } else {
            dst[out++] = src[i];
            if (++code == 0xFF) {
                dst[code_at] = code;
                code_at = out++;
                code = 1;
            }
        }
    }
    dst[code_at] = code;
    return out;
}

long cobs_decode(const uint8_t *src, size_t n, uint8_t *dst)
{
    size_t i = 0, out = 0;
    while (i < n) {
        uint8_t code = src[i++];
        if (code == 0 || i + code - 1 > n)
            return -1;
        for (uint8_t j = 1; j < code; j++) {
            if (src[i] == 0)
                return -1;
            dst[out++] = src[i++];
        }
        if (code != 0xFF && i < n)
            dst[out++] = 0;
    }
    return (long)out;
}
