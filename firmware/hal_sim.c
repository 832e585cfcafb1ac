/* hal.h's drive half over the simulated drive (plant.c): the position read and the
 * current write, and the simulated drive's own rule for when a run begins (sim_poll).
 *
 * Time is counted in reads: a write takes effect over the next sample period, so the
 * plant steps under the current written last when the next sample is read.
 *
 * Parked: while the board is in its safe state (IDLE, HELLO, FAULTED) the simulated drive
 * rests at its power-up state (FW_DRIVE), as the Python emulator rebuilds its drive at
 * every CONFIG, so that every run starts from the same state.  The first read after that
 * (READY's sample, at CONFIG) is tick 0's sample and does not step the plant; currents
 * written while parked (the safe state's zero, READY's holding current) are held, not
 * stepped.  A second CONFIG while READY keeps the drive as it is (as a real drive would).
 */
#include "board.h"
#include "drive.h"
#include "hal.h"

static plant pl;
static int parked, pending;
static double u_pending;

void sim_park(void)
{
    if (parked)
        return;
    pl = FW_DRIVE;
    parked = 1;
    pending = 0;
}

void sim_poll(board *bd)
{
    board_poll(bd);
    if (bd->state != BOARD_READY && bd->state != BOARD_ACTIVE)
        sim_park();
}

void hal_read_position(double *x, double *v)
{
    if (parked) {
        parked = 0;
    } else if (pending) {
        plant_step(&pl, u_pending, 0.0);
        pending = 0;
    }
    plant_measure(&pl, 0.0, 0.0, x, v);
}

double hal_write_current(double amps)
{
    u_pending = amps;
    pending = !parked;
    double m = FW_DRIVE.p.u_max;
    return amps > m ? m : amps < -m ? -m : amps; /* plant_step's clip, as its ubuf[0] */
}
