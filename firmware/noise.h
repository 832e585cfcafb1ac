/* The simulated drive's sensor noise: standard-normal draws from a seeded generator, in C.
 *
 * Not numpy's: numpy's default_rng (PCG64 and its ziggurat normal sampler) would be a
 * second port of a library's internals, kept bit-equal to each numpy release.  A drive's
 * noise has to have the right statistics, not numpy's bits: xoshiro256** (Blackman and
 * Vigna), seeded through splitmix64 from a 64-bit seed, and Marsaglia's polar method,
 * whose pairs serve one tick's (position, velocity) draws.  tests/test_firmware.py checks
 * the draws' mean, variance, normality and independence.  A run with the noise off is
 * bit-equal to the Python simulated drive; with it on, equal in distribution.
 */
#ifndef SERVO_FW_NOISE_H
#define SERVO_FW_NOISE_H

#include <stdint.h>

typedef struct {
    uint64_t s[4];
} noise_gen;

/* Seed the generator (any 64-bit value). */
void noise_seed(noise_gen *g, uint64_t seed);

/* Two independent standard-normal draws. */
void noise_pair(noise_gen *g, double *a, double *b);

#endif
