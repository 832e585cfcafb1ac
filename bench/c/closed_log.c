/* The fast path's closed loop in C, logging: the loop body of kernels/compose.py's
 * closed_loop for the PI kind, on the functions of servo_ref.c (included, so that gcc
 * may inline them as it inlines its own loops there), with the fast path's estimator and
 * its log rows written to memory.  Per tick k (inputs at index i = k - k0):
 *
 *     plant_measure -> controller tick -> link latency (shift_in) -> plant_step
 *     -> error_stats every est_every ticks -> one log row every log_every ticks
 *
 * The log row is kernels/compose.py's log_row for the PI kind (which logs no columns of
 * its own): tick, t, r, x, v, u, u_n, u_c, u_exc, h_hat, regime, e; then the run
 * watchdog's tests of the row as the loop writes it (kernels/watch.py's watch_row:
 * watch = {position, limit, most}, ring of n_ring at-limit flags, carry = {flags in the
 * ring, rows seen, next slot, first row outside, first row over the share, its count}).  Built by
 * bench/cref.py with the same flags as servo_ref.c; bench/test_fastpath_c.py checks that
 * it logs the same bits as the Numba loop, then times the two.
 */
#include "servo_ref.c"

/* Returns the next free row of log (rows of `width` >= 12 doubles). */
int64_t ref_closed_loop_logged(plant_state *st, const plant_params *p, double *q, const double *mab,
                               const double *gain, int64_t n_modes, double *ubuf, int64_t n_ubuf, double *latency,
                               int64_t n_latency, stage_state *c, const stage_params *sp, pi_state *ci,
                               const pi_params *cp, const double *r, const double *u_exc, const double *d,
                               const double *noise, int64_t k0, int64_t n, int64_t est_every, int64_t log_every,
                               double *stats, double *log, int64_t width, int64_t row, const double *watch,
                               uint8_t *ring, int64_t n_ring, int64_t *carry)
{
    double dt = p->dt, xv[2];
    for (int64_t k = k0; k < k0 + n; k++) {
        int64_t i = k - k0;
        ref_plant_measure(st, p, q, gain, n_modes, noise[2 * i], noise[2 * i + 1], xv);
        double x = xv[0];
        double u = ref_controller_tick(c, sp, ci, cp, x, xv[1], r[i], u_exc[i]);
        ref_plant_step(st, p, q, mab, n_modes, ubuf, n_ubuf, shift_in(latency, n_latency, u), d[i]);
        if (k % est_every == 0) {
            double e = c->e;
            stats[0] += e * e;
            stats[1] += 1.0;
            if (fabs(e) > stats[2])
                stats[2] = fabs(e);
        }
        if (k % log_every == 0) {
            double *o = log + width * row;
            o[0] = (double)k;
            o[1] = (double)k * dt;
            o[2] = c->x_prev + c->e;
            o[3] = x;
            o[4] = c->v;
            o[5] = c->u;
            o[6] = c->u_n;
            o[7] = c->u_c;
            o[8] = u_exc[i];
            o[9] = c->H_dahl;
            o[10] = c->regime;
            o[11] = c->e;
            /* watch_row on x and u */
            if (carry[3] < 0 && !(fabs(o[3]) < watch[0]))
                carry[3] = row;
            if (carry[4] < 0) {
                int64_t count = carry[0], seen = carry[1], slot = carry[2];
                int64_t f = fabs(o[5]) >= watch[1] ? 1 : 0;
                if (seen >= n_ring)
                    count -= ring[slot];
                ring[slot] = (uint8_t)f;
                count += f;
                slot++;
                if (slot == n_ring)
                    slot = 0;
                seen++;
                carry[0] = count;
                carry[1] = seen;
                carry[2] = slot;
                if (seen >= n_ring && (double)count > watch[2]) {
                    carry[4] = row;
                    carry[5] = count;
                }
            }
            row++;
        }
    }
    return row;
}
