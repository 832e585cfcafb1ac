/* hal.h's drive half over the simulated drive (plant.c): the position read and the
 * current write.  A write takes effect over the next sample period, so the plant steps
 * when the next sample is read (or never, after the safe state's zero: the run is over);
 * hal_prepare rebuilds the plant from FW_DRIVE, so every run starts from the same state. */
#include "drive.h"
#include "hal.h"

static plant pl;
static int pending;
static double u_pending;

void hal_read_position(double *x, double *v)
{
    if (pending) {
        plant_step(&pl, u_pending, 0.0);
        pending = 0;
    }
    plant_measure(&pl, 0.0, 0.0, x, v);
}

double hal_write_current(double amps)
{
    u_pending = amps;
    pending = 1;
    double m = FW_DRIVE.p.u_max;
    return amps > m ? m : amps < -m ? -m : amps; /* plant_step's clip, as its ubuf[0] */
}

double hal_prepare(void)
{
    pl = FW_DRIVE;
    pending = 0;
    return pl.u_hold;
}
