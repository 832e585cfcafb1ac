/* The simulated drive: the C port of kernels/plant.py (rigid body with friction, Dahl
 * hysteresis, bias, cogging, force-constant variation, hard stops, input delay, flexible
 * modes, sensor low-pass and quantiser), same operations in the same order.
 *
 * Not ported: the sensor noise draws (numpy's generator) and the scenario's disturbance
 * force; the firmware's drive is the noise-free, undisturbed plant (a simulated drive
 * with position_noise = velocity_noise = 0 and no disturbance gives the same bits).
 * The parameters come from the Python side (hil/firmware.py writes them as C source).
 */
#ifndef SERVO_FW_PLANT_H
#define SERVO_FW_PLANT_H

#define PLANT_MAX_MODES 8
#define PLANT_MAX_UBUF 64

/* kernels.plant.PLANT_PARAMS, field for field (SI units; forces in A of VCM current). */
typedef struct {
    double J, B, b_asym, Fc, Fs, fc_asym, vs, sigma, Ha, alpha, K, h0, cog_amp, cog_period, cog_phase, kf1, kf2,
        stroke, u_max, dt, delay_frac, delay_whole, n_sub, noise_x, noise_v, quantum, has_velocity, sensor_a;
} plant_params;

/* kernels.plant.PLANT_STATE: position (m), velocity (m/s), Dahl force (A), sensor low-pass (m). */
typedef struct {
    double x, v, H, y_lp;
} plant_state;

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

/* Advance one sample period under command u_cmd (A, clipped to u_max) and force d (A). */
void plant_step(plant *pl, double u_cmd, double d);

/* The sensors now: *x (m), *v (m/s, NaN without velocity); nx, nv: noise draws (0 here). */
void plant_measure(plant *pl, double nx, double nv, double *x, double *v);

#endif
