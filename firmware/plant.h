/* The simulated drive: the C port of kernels/plant.py (rigid body with friction, Dahl
 * hysteresis, bias, cogging, force-constant variation, hard stops, input delay, flexible
 * modes, sensor low-pass and quantiser), same operations in the same order.
 *
 * The kernels come twice: on the records and arrays of kernels/plant.py as the Numba
 * kernels take them (plant_step_on, plant_measure_on: what the benchmarks' C reference,
 * bench/c/servo_ref.c, calls), and on one `plant` holding them all (plant_step,
 * plant_measure: the firmware's simulated drive).  The noise draws and the disturbance
 * force are arguments; hal_sim.c supplies them (noise.c, the drive's disturbance).
 * The parameters come from the Python side (hil/firmware.py writes them as C source).
 */
#ifndef SERVO_FW_PLANT_H
#define SERVO_FW_PLANT_H

#include <stdint.h>

#include "records.h" /* plant_params, plant_state: kernels.plant's PLANT_PARAMS, PLANT_STATE */

#define PLANT_MAX_MODES 8
#define PLANT_MAX_UBUF 64

/* The whole drive: parameters, state, modes q[i] = (q_i, q_i'), their matrices
 * mab[i][part] = (a11, a12, a21, a22, b1, b2), gains, and the input-delay buffer. */
typedef struct {
    plant_params p;
    plant_state st;
    int n_modes;
    double q[PLANT_MAX_MODES][2];
    double mab[PLANT_MAX_MODES][2][6];
    double gain[PLANT_MAX_MODES];
    int n_ubuf;
    double ubuf[PLANT_MAX_UBUF];
    double u_hold;
} plant;

/* kernels.plant.plant_step: advance one sample period under command u_cmd (A, clipped to
 * u_max) and force d (A).  q: (n_modes, 2) and mab: (n_modes, 2, 6), row-major; ubuf:
 * the input-delay buffer, n_ubuf values. */
void plant_step_on(plant_state *st, const plant_params *p, double *q, const double *mab, int64_t n_modes,
                   double *ubuf, int64_t n_ubuf, double u_cmd, double d);

/* kernels.plant.plant_measure: the sensors now, out[0] = x (m), out[1] = v (m/s, NaN
 * without velocity); nx, nv: standard-normal noise draws (scaled by noise_x, noise_v).
 * Updates the sensor low-pass in st. */
void plant_measure_on(plant_state *st, const plant_params *p, const double *q, const double *gain, int64_t n_modes,
                      double nx, double nv, double *out);

/* plant_step_on on the whole drive. */
void plant_step(plant *pl, double u_cmd, double d);

/* plant_measure_on on the whole drive: *x (m), *v (m/s, NaN without velocity). */
void plant_measure(plant *pl, double nx, double nv, double *x, double *v);

#endif
