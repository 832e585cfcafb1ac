/* hal.h's drive half over the simulated drive (plant.c): the position read and the
 * current write, and the simulated drive's own rule for when a run begins (sim_poll).
 *
 * Time is counted in reads: a write takes effect over the next sample period, so the
 * plant steps under the current written last, and the disturbance force of that period
 * (FW_DISTURBANCE, as servo/scenarios/steps.py computes it: the same bits), when the next
 * sample is read.  Each read draws the sensor noise (noise.c, seeded at every run with the
 * seed of the host's CONFIG, `board.seed`: equal to the Python drive's in distribution,
 * not in bits).
 *
 * Parked: while the board is in its safe state (IDLE, HELLO, FAULTED) the simulated drive
 * rests at its power-up state (FW_DRIVE), as the Python emulator rebuilds its drive at
 * every CONFIG, so that every run starts from the same state.  The first read after that
 * (READY's sample, at CONFIG) is tick 0's sample and does not step the plant; currents
 * written while parked (the safe state's zero, READY's holding current) are held, not
 * stepped.  A second CONFIG while READY keeps the drive as it is (as a real drive would).
 */
#include <math.h>

#include "board.h"
#include "drive.h"
#include "fwmath.h"
#include "hal.h"
#include "noise.h"

static plant pl;
static int parked, pending;
static double u_pending;
static uint32_t steps; /* sample periods since the run began */
static noise_gen gen;
static const board *owner; /* the board sim_poll serves: its CONFIG's seed */

void sim_park(void)
{
    if (parked)
        return;
    pl = FW_DRIVE;
    parked = 1;
    pending = 0;
    steps = 0;
}

/* The disturbance (A) over period k: servo/scenarios/steps.py's operations in its order. */
double sim_disturbance(uint32_t k)
{
    const disturbance *d = &FW_DISTURBANCE;
    double t = (double)k * d->dt;
    if (t < d->start_s)
        return 0.0;
    return d->amplitude * sin(2.0 * PI * d->hz * (t - d->start_s));
}

void sim_poll(board *bd)
{
    owner = bd;
    board_poll(bd);
    if (bd->state != BOARD_READY && bd->state != BOARD_ACTIVE)
        sim_park();
}

void hal_read_position(double *x, double *v)
{
    if (parked) { /* READY's sample, at CONFIG: the run begins, with the CONFIG's seed */
        parked = 0;
        noise_seed(&gen, owner ? owner->seed : 0u);
    } else if (pending) {
        plant_step(&pl, u_pending, sim_disturbance(steps));
        steps++;
        pending = 0;
    }
    double nx = 0.0, nv = 0.0;
    if (pl.p.noise_x != 0.0 || pl.p.noise_v != 0.0)
        noise_pair(&gen, &nx, &nv);
    plant_measure(&pl, nx, nv, x, v);
}

double hal_write_current(double amps)
{
    u_pending = amps;
    pending = !parked;
    double m = FW_DRIVE.p.u_max;
    return amps > m ? m : amps < -m ? -m : amps; /* plant_step's clip, as its ubuf[0] */
}
