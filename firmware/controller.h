/* The controller kernels on their stage: one sample each (firmware/controller.c). */
#ifndef SERVO_FW_CONTROLLER_H
#define SERVO_FW_CONTROLLER_H

#include "records.h"

/* One sample of the PI holding loop ("pi") on the compensator stage: measured position x
 * (m), velocity v_meas (m/s, NaN if not measured), reference r (m, from the holding
 * position), excitation u_exc (A); updates the records, returns the current command (A). */
double fw_pi_tick(stage_state *c, const stage_params *p, pi_state *ci, const pi_params *cp, double x, double v_meas,
                  double r, double u_exc);

/* One sample of the two-rate track-following cascade ("track", "nss"), as fw_pi_tick. */
double fw_track_tick(stage_state *c, const stage_params *p, track_state *t, const track_params *q, double x,
                     double v_meas, double r, double u_exc);

#endif
