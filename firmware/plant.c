#include "plant.h"

#include <math.h>

#include "dahl.h"
#include "fwmath.h"

static double force_constant(double x, const plant_params *p)
{
    double r = x / p->stroke;
    return 1.0 + p->kf1 * r + p->kf2 * r * r;
}

/* the input dead zone of half-width w: sgn(u)*max(|u| - w, 0) */
static double dead_zone(double u, double w)
{
    if (u > w)
        return u - w;
    if (u < -w)
        return u + w;
    return 0.0;
}

static double drive_force(double x, double u, double d, const plant_params *p)
{
    double f = force_constant(x, p) * u + d - p->K * x - p->h0;
    if (p->cog_amp != 0.0)
        f -= p->cog_amp * sin(2.0 * PI * x / p->cog_period + p->cog_phase);
    if (p->k3 != 0.0)
        f -= p->k3 * x * x * x;
    return f;
}

static double sliding_friction(double v, double s, const plant_params *p)
{
    double f = p->B * (1.0 + s * p->b_asym) * v;
    if (p->Fs > 0.0) {
        double fc = p->Fc * (1.0 + s * p->fc_asym);
        double fs = p->Fs * (1.0 + s * p->fc_asym);
        double w = v / p->vs;
        f += s * (fc + (fs - fc) * exp(-(w * w))); /* Numba: w**2 == w*w exactly */
    }
    return f;
}

static double breakaway(double s, const plant_params *p) { return p->Fs * (1.0 + s * p->fc_asym); }

static double acceleration(double x, double v, double s, double x0, double H0, double u, double d,
                           const plant_params *p)
{
    double H = dahl_flow(H0, x - x0, s, p->sigma, p->Ha, p->alpha);
    return (drive_force(x, u, d, p) - sliding_friction(v, s, p) - H) / p->J;
}

static void rigid_substep(plant_state *st, const plant_params *p, double u, double d, double h)
{
    double x0 = st->x, v0 = st->v, H0 = st->H;
    double s;
    if (v0 > 0.0) {
        s = 1.0;
    } else if (v0 < 0.0) {
        s = -1.0;
    } else {
        double f = drive_force(x0, u, d, p) - H0;
        if (f == 0.0)
            return;
        s = f > 0.0 ? 1.0 : -1.0;
        if (fabs(f) <= breakaway(s, p))
            return;
    }
    double k1x = v0;
    double k1v = acceleration(x0, v0, s, x0, H0, u, d, p);
    double k2x = v0 + 0.5 * h * k1v;
    double k2v = acceleration(x0 + 0.5 * h * k1x, k2x, s, x0, H0, u, d, p);
    double k3x = v0 + 0.5 * h * k2v;
    double k3v = acceleration(x0 + 0.5 * h * k2x, k3x, s, x0, H0, u, d, p);
    double k4x = v0 + h * k3v;
    double k4v = acceleration(x0 + h * k3x, k4x, s, x0, H0, u, d, p);
    double x1 = x0 + h / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x);
    double v1 = v0 + h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v);
    if (x1 > p->stroke) {
        x1 = p->stroke;
        v1 = py_min(v1, 0.0);
    } else if (x1 < -p->stroke) {
        x1 = -p->stroke;
        v1 = py_max(v1, 0.0);
    }
    double H1 = dahl_flow(H0, x1 - x0, s, p->sigma, p->Ha, p->alpha);
    if (s * v1 < 0.0 && p->Fs > 0.0) {
        double f = drive_force(x1, u, d, p) - H1;
        if (fabs(f) <= breakaway(f > 0.0 ? 1.0 : -1.0, p))
            v1 = 0.0;
    }
    st->x = x1;
    st->v = v1;
    st->H = H1;
}

/* q: (n_modes, 2) row-major; mab: (n_modes, 2, 6) row-major. */
static void modes_advance(double *q, const double *mab, int64_t n_modes, int64_t part, double u)
{
    for (int64_t i = 0; i < n_modes; i++) {
        const double *m = mab + (i * 2 + part) * 6;
        double q0 = q[2 * i], q1 = q[2 * i + 1];
        q[2 * i] = m[0] * q0 + m[1] * q1 + m[4] * u;
        q[2 * i + 1] = m[2] * q0 + m[3] * q1 + m[5] * u;
    }
}

static void rigid_advance(plant_state *st, const plant_params *p, double u, double d, double h)
{
    int64_t n = (int64_t)p->n_sub;
    double hs = h / (double)n;
    for (int64_t i = 0; i < n; i++)
        rigid_substep(st, p, u, d, hs);
}

/* kernels/delay.py shift_in: push u, return the value pushed out. */
static double shift_in(double *buf, int64_t n, double u)
{
    if (n == 0)
        return u;
    double out = buf[n - 1];
    for (int64_t i = n - 1; i > 0; i--)
        buf[i] = buf[i - 1];
    buf[0] = u;
    return out;
}

void plant_step_on(plant_state *st, const plant_params *p, double *q, const double *mab, int64_t n_modes,
                   double *ubuf, int64_t n_ubuf, double u_cmd, double d)
{
    double u = py_min(py_max(u_cmd, -p->u_max), p->u_max);
    shift_in(ubuf, n_ubuf, u);
    int64_t m = (int64_t)p->delay_whole;
    double u_late = ubuf[m];
    double u_early = ubuf[m + 1];
    if (p->dz_width > 0.0) {
        u_late = dead_zone(u_late, p->dz_width);
        u_early = dead_zone(u_early, p->dz_width);
    }
    if (p->delay_frac > 0.0) {
        rigid_advance(st, p, u_early, d, p->delay_frac);
        modes_advance(q, mab, n_modes, 0, u_early);
    }
    rigid_advance(st, p, u_late, d, p->dt - p->delay_frac);
    modes_advance(q, mab, n_modes, 1, u_late);
}

void plant_measure_on(plant_state *st, const plant_params *p, const double *q, const double *gain, int64_t n_modes,
                      double nx, double nv, double *out)
{
    double y = st->x, yd = st->v;
    for (int64_t i = 0; i < n_modes; i++) {
        y += gain[i] * q[2 * i];
        yd += gain[i] * q[2 * i + 1];
    }
    if (p->backlash > 0.0) {
        if (y > st->y_load + p->backlash)
            st->y_load = y - p->backlash;
        else if (y < st->y_load - p->backlash)
            st->y_load = y + p->backlash;
        y = st->y_load;
    }
    if (p->sensor_a > 0.0) {
        st->y_lp += p->sensor_a * (y - st->y_lp);
        y = st->y_lp;
    }
    y += p->noise_x * nx;
    if (p->quantum > 0.0)
        y = floor(y / p->quantum + 0.5) * p->quantum;
    if (p->has_velocity != 0.0)
        yd += p->noise_v * nv;
    else
        yd = NAN;
    out[0] = y;
    out[1] = yd;
}

void plant_step(plant *pl, double u_cmd, double d)
{
    plant_step_on(&pl->st, &pl->p, &pl->q[0][0], &pl->mab[0][0][0], pl->n_modes, pl->ubuf, pl->n_ubuf, u_cmd, d);
}

void plant_measure(plant *pl, double nx, double nv, double *x, double *v)
{
    double out[2];
    plant_measure_on(&pl->st, &pl->p, &pl->q[0][0], pl->gain, pl->n_modes, nx, nv, out);
    *x = out[0];
    *v = out[1];
}
