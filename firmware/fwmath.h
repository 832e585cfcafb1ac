/* What every kernel source shares: pi as Python's math.pi, and Python's (and Numba's)
 * max(a, b) / min(a, b), which return b if it compares greater (less), else a. */
#ifndef SERVO_FW_FWMATH_H
#define SERVO_FW_FWMATH_H

#define PI 3.141592653589793 /* == math.pi */

static inline double py_max(double a, double b) { return b > a ? b : a; }
static inline double py_min(double a, double b) { return b < a ? b : a; }

#endif
