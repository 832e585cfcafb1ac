"""A closed loop's settling reversals: the crossing placed with the viscous force known
(docs/diagnosis.md 1, docs/studies/2026-11-28-closed-step-nulls.md).

A closed loop that steps its reference reverses the arm 10-30 samples after each kick,
while the speed on either side still changes fast: the viscous force ``B*v`` changes
by more than the friction's switch within the crossing's window, and not linearly in
time.  With only the recorded force taken out of the filtered velocity, the kinked
parabola put the switch 0.18 sample early on average, the rows beside every reversal
carried the misfit, and low-pass sensor noise (whose floor in the band is low) showed
it: `unexplained`, structured against distance since reversal, and a
`stribeck_friction` named on two development nulls.  The crossing's fit now takes out
the velocity of the force that is not the friction's (:meth:`Signals.known_force`).
"""
import numpy as np
import pytest
from scipy import signal

from servo.diagnose.signals import align, derivative, reversal_times
from servo.identify.regressors import RobustSettings


def _viscous_coulomb_mass(u: np.ndarray, Fc: float, B: float, v0: float) -> tuple[np.ndarray, float]:
    """Exact samples of ``x'' = u[k] - Fc*sgn(x') - B*x'`` under the held input ``u``
    (unit mass, unit sample period; the velocity relaxes exponentially within a
    sample), and the time of the one reversal (the caller keeps ``|u| > Fc`` there)."""

    def relax(x0: float, v0_: float, a: float, r: float) -> tuple[float, float]:
        vi, e = a / B, np.exp(-B * r)
        return x0 + vi * r + (v0_ - vi) * (1.0 - e) / B, vi + (v0_ - vi) * e

    n = u.size
    x, v, t_rev = np.zeros(n + 1), v0, np.nan
    for k in range(n):
        s = np.sign(v)
        a = u[k] - Fc * s
        x1, v1 = relax(x[k], v, a, 1.0)
        if np.isnan(t_rev) and v * v1 < 0:  # the velocity crosses zero inside this sample
            tc = -np.log(a / B / (a / B - v)) / B
            xc, _ = relax(x[k], v, a, tc)
            x1, v1 = relax(xc, 0.0, u[k] + Fc * s, 1.0 - tc)  # the friction flips with the direction
            t_rev = k + tc
        x[k + 1], v = x1, v1
    return x[:n], t_rev


@pytest.mark.parametrize("v0", [-3.0, -2.7, -2.4])
def test_the_crossing_with_a_fast_changing_viscous_force_is_where_the_friction_switches(v0):
    s = RobustSettings()
    n = 600
    u = np.full(n, 0.01)
    Fc, B = 0.004, 0.02  # B*v is 15 x Fc at the start, falling exponentially through the reversal
    x, t_rev = _viscous_coulomb_mass(u, Fc, B, v0)
    assert 60 < t_rev < n - 60
    b, a = signal.butter(s.butter_order, s.cutoff(1.0) / 0.5)
    xf = signal.filtfilt(b, a, x, padlen=3 * s.butter_order)
    vf = derivative(xf, 1.0)
    force = signal.filtfilt(b, a, align(u), padlen=3 * s.butter_order)
    known = reversal_times(vf, s, 1.0, 1e-9, force - B * vf, 1.0)  # what Signals.known_force gives
    input_only = reversal_times(vf, s, 1.0, 1e-9, force, 1.0)
    assert known.size == 1 and input_only.size == 1
    assert known[0] == pytest.approx(t_rev, abs=0.01)
    # with the input alone the viscous force's change read as part of the kink
    assert abs(input_only[0] - t_rev) > 0.5


def test_known_force_is_the_input_less_the_first_fits_smooth_forces():
    """The force the crossings' fit takes out is the filtered input less ``B*v + K*x +
    h0`` of eq. (3) fitted on the usable rows, with that fit's inertia."""
    from servo.diagnose.band import settings_for
    from servo.diagnose.signals import held_sign, make_signals
    from studies.proving.cases import Case, recording

    rec, truth = recording(Case("null", 0.0, "pdi", "steps", 5000.0, noise="lowpass"), 1300027)
    sig = make_signals(rec, settings_for(3, 5000.0))
    force, J = sig.known_force()
    coef = sig.balance_fit(sig.force(), held_sign(sig.vf))
    assert J == pytest.approx(truth["J"], rel=0.02)
    np.testing.assert_allclose(force, sig.force() - coef[1] * sig.vf - coef[2] * sig.xf - coef[3])
    assert coef[1] == pytest.approx(truth["B"], rel=0.2)


def _closed_steps_null(j: int):
    from studies.proving.cases import Case, recording
    from studies.proving.study import KIND_RATE, KIND_SEEDS, grid_cell

    ctl, exc, noise = grid_cell("null", 0, j)
    assert (ctl, exc) == ("pdi", "steps")
    return recording(Case("null", 0.0, ctl, exc, KIND_RATE, noise=noise), KIND_SEEDS["null"] + j)[0], noise


@pytest.mark.slow
@pytest.mark.parametrize("offset, j", [(0, 27), (1_000_000, 27), (1_000_000, 59)])
def test_closed_loop_steps_nulls_with_lowpass_noise_name_nothing(offset, j):
    """Development nulls (closed loop, reference steps, low-pass sensor noise) that were
    `unexplained` at 1.28-1.45 x the floor, structured against distance since reversal
    (offset 0, null 27), and named a `stribeck_friction` (offset 1e6, nulls 27 and 59):
    no finding, no structure against the state, and the level within 1.3 x a floor that
    reads this noise 0.85-0.89 x its true level in the band (the rest of the gap)."""
    from servo.diagnose.job import diagnose
    from studies.proving.cases import Case, recording
    from studies.proving.study import KIND_RATE, KIND_SEEDS, grid_cell

    ctl, exc, noise = grid_cell("null", 0, j)
    assert (ctl, exc, noise) == ("pdi", "steps", "lowpass")
    rec, _ = recording(Case("null", 0.0, ctl, exc, KIND_RATE, noise=noise), KIND_SEEDS["null"] + offset + j)
    D = diagnose(rec)
    assert D.findings == [], [f.physics for f in D.findings]
    checks = D.verdict["baseline_checks"]
    assert not checks["state"]["failed"], checks["state"].get("flagged")
    assert checks["level"]["ratio"] < 1.3


@pytest.mark.slow
@pytest.mark.parametrize("j", [3, 11, 35, 43])
def test_closed_loop_steps_nulls_with_white_or_pink_noise_are_consistent(j):
    """The closed loop's steps nulls of development offset 0 with white or pink noise:
    `consistent`, nothing named, the level at the floor."""
    from servo.diagnose.job import diagnose

    rec, noise = _closed_steps_null(j)
    assert noise in ("white", "pink")
    D = diagnose(rec)
    assert D.verdict["verdict"] == "consistent", D.verdict.get("text")
    assert D.findings == []
    assert D.verdict["baseline_checks"]["level"]["ratio"] < 1.1
