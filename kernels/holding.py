"""PI holding loop (paper Fig. 2 and Fig. 6): keeps the arm near a fixed position while an
experiment runs.

    u_n = kp*e_p + I - kd*v + u_ff,      I += ki*dt*e   (unless winding up)

``e`` is the position error (m), ``e_p`` the proportional term's error (m): with setpoint
weighting ``b`` (a two-degree-of-freedom PID) ``e_p = b*r - x`` relative to the holding
position, so a reference step does not kick the loop through the proportional path (``b =
1``: ``e_p = e``).  ``v`` is the velocity (m/s), ``u_ff`` a feed-forward current (the
experiment's excitation, A).  The rate feedback ``kd*v`` is part of the loop because
the plant it holds is (after compensation, eq. 10) a double integrator, which a pure PI
cannot stabilise; set ``kd = 0`` for the textbook PI.

Anti-windup is conditional integration: when the output is clamped to ``[lo, hi]`` the
integrator stops integrating errors that push further into the limit.  A bumpless start
sets ``I`` so that the first output equals the current already applied
(:func:`holding_pi_bumpless`).
"""
from numba import float64
from numba.types import UniTuple

from kernels._cache import kernel


@kernel(
    UniTuple(float64, 2)(
        float64, float64, float64, float64, float64, float64, float64, float64, float64, float64,
        float64,
    ),
    helper=True,
)
def holding_pi(e, e_p, v, integ, u_ff, kp, ki, kd, dt, lo, hi):
    """One sample of the holding loop.  Returns ``(u_n, integ)``: the output (A) clamped to
    ``[lo, hi]`` and the updated integrator state (A)."""
    u = kp * e_p + integ - kd * v + u_ff
    winding = False
    if u > hi:
        u = hi
        winding = e > 0.0
    elif u < lo:
        u = lo
        winding = e < 0.0
    if not winding:
        integ += ki * dt * e
    return u, integ


@kernel(float64(float64, float64, float64, float64, float64), helper=True)
def holding_pi_bumpless(u_now, e, v, kp, kd):
    """Integrator value (A) that makes the first output equal ``u_now`` (A), the current
    already applied when the loop takes over (no feed-forward at that instant)."""
    return u_now - kp * e + kd * v
