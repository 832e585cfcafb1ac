"""Short-horizon simulation of the drive model from measured states, for judging a model
by the output it predicts rather than by the force it explains.

The plant kernels (:mod:`kernels.plant`) advance a model of the drive; here they are run
from many starting states over a recorded input: for each start ``k`` the rigid body,
its Dahl state and its modes are set to estimates at sample ``k`` and the model is
stepped ``horizon`` samples under the recorded input, noise-free.
"""
from numba import float64, int64, void

from kernels._cache import kernel
from kernels.plant import modes_advance, plant_measure, plant_params_t, plant_state_t, plant_step


@kernel(void(float64[:, :, ::1], float64[::1], float64[:, ::1], float64[:, :, ::1]))
def mode_trace(mab, u, q, out):
    """Modal states ``out[k] = q`` (n, n_modes, 2) at each sample ``k`` (before the step
    of sample ``k``) under inputs ``u`` (n,), advancing ``q`` in place with the exact
    discretisation ``mab`` (see :func:`kernels.plant.modes_advance`)."""
    for k in range(u.shape[0]):
        for i in range(q.shape[0]):
            out[k, i, 0] = q[i, 0]
            out[k, i, 1] = q[i, 1]
        modes_advance(q, mab, 1.0, u[k])


@kernel(
    void(
        plant_state_t, plant_params_t, float64[:, ::1], float64[:, :, ::1], float64[::1], float64[::1],
        float64[::1], float64[::1], float64[::1], float64[::1], float64[:, :, ::1], int64[::1], int64,
        float64[:, ::1],
    ),
)  # fmt: skip
def multistep(ps, pp, q, mab, gain, ubuf, u, x0, v0, H0, q0, starts, horizon, out):
    """Predicted measured positions ``out[s, i]`` (m) at sample ``starts[s] + i + 1``.

    Each start sets the rigid position/velocity/Dahl force to ``x0[s]``, ``v0[s]``,
    ``H0[s]`` and the modes to ``q0[s]`` (n_modes, 2), then steps the plant of ``pp`` under
    ``u[starts[s] + i]`` (A), ``i < horizon``, with a noise-free sensor.  ``ps``, ``q``,
    ``ubuf`` are scratch (one plant state, (n_modes, 2), the input-delay buffer)."""
    for s in range(starts.shape[0]):
        k = starts[s]
        st = ps[0]
        st.x = x0[s]
        st.v = v0[s]
        st.H = H0[s]
        for i in range(q.shape[0]):
            q[i, 0] = q0[s, i, 0]
            q[i, 1] = q0[s, i, 1]
        for j in range(ubuf.shape[0]):
            ubuf[j] = u[k - 1 - j] if k - 1 - j >= 0 else u[0]
        for i in range(horizon):
            plant_step(ps, pp, q, mab, ubuf, u[k + i], 0.0)
            y, _ = plant_measure(ps, pp, q, gain, 0.0, 0.0)
            out[s, i] = y
