"""The Stribeck term's shape exponent and its bristles (servo/physics/stribeck.py,
kernels/stribeck.py): the column's physics, the simulated drive that stands in for
the bristles, and the proving ground's recordings of other shapes and of a LuGre
element with a Stribeck level, named and explained with their parameters."""
import math
from types import SimpleNamespace

import numpy as np
import pytest

from kernels.stribeck import stribeck_bristle_trace
from servo import physics
from servo.physics.base import Simulation
from servo.physics.stribeck import GAUSSIAN, STAND_IN_SPAN, bristles, curve, gaussian_stand_in


def test_the_shape_exponent_spans_the_exponential_and_gaussian_curves():
    v = np.linspace(0, 5e-3, 11)
    assert np.allclose(curve(v, 1e-3, 1.0), np.exp(-v / 1e-3))
    assert np.allclose(curve(-v, 1e-3, 2.0), np.exp(-((v / 1e-3) ** 2)))


@pytest.mark.parametrize("delta", [0.4, 0.6, 1.0, 1.5, 2.0, 3.0])
def test_the_drives_gaussian_stand_in_is_the_nearest_gaussian(delta):
    """Over the grid's and the refinement's whole range of shapes (0.4-3): no Gaussian
    ``a*exp(-(r/b)^2)`` nearby is nearer the curve over the stand-in's span, and the
    Gaussian stands for itself."""
    a, b = gaussian_stand_in(delta)
    r = np.linspace(0, STAND_IN_SPAN, 801)
    err = lambda a_, b_: np.sum((curve(r, 1.0, delta) - a_ * curve(r, b_, GAUSSIAN)) ** 2)  # noqa: E731
    e0 = err(a, b)
    for da, db in ((1.02, 1), (0.98, 1), (1, 1.02), (1, 0.98)):
        assert err(a * da, b * db) > e0
    if delta == GAUSSIAN:
        assert (a, b) == (1.0, 1.0)


def _trace(x, v, vs, delta, length):
    out = np.empty(x.size)
    stribeck_bristle_trace(np.ascontiguousarray(x), np.ascontiguousarray(v), vs, delta, length, out)
    return out


def _trace_sample_by_sample(x, v, vs, delta, length):
    """The recursion of kernels/stribeck.py's module doc, one sample at a time in Python."""
    out = np.zeros(x.size)
    w = 0.0
    for k in range(1, x.size):
        dx = x[k] - x[k - 1]
        if dx != 0.0:
            phi = max(math.exp(-(abs(v[k] / vs) ** delta)), 1e-12)
            w_ss = math.copysign(phi, dx)
            w = w_ss + (w - w_ss) * math.exp(-abs(dx) / (length * phi))
        out[k] = w
    return out


@pytest.mark.parametrize("delta", [0.6, 1.0, 2.0, 2.7])
def test_the_blockwise_trace_is_the_recursion_sample_by_sample(delta):
    """The curve computed a block at a time by numpy (``kernels.stribeck.BLOCK``), the
    state carried across blocks: the same trace as the recursion run sample by sample,
    over two block boundaries, with rests (``dx = 0``, ``v = 0``) and both directions."""
    from kernels.stribeck import BLOCK

    rng = np.random.default_rng(7)
    n = 2 * BLOCK + 1234
    v = np.cumsum(rng.standard_normal(n)) * 2e-5
    v[rng.random(n) < 0.05] = 0.0
    x = np.cumsum(v) * 1e-4
    for vs, length in ((1e-3, 3e-8), (3e-4, 1e-6)):
        got = _trace(x, v, vs, delta, length)
        ref = _trace_sample_by_sample(x, v, vs, delta, length)
        assert np.abs(got - ref).max() <= 1e-12
        assert np.abs(ref).max() > 0.1  # the state moves: the comparison is not of zeros


@pytest.mark.parametrize("speed", [2e-4, 1e-3, 3e-3])
def test_bristles_settle_on_the_stribeck_curve_at_a_held_speed(speed):
    """LuGre's steady state: the bristle force is phi(v)*sgn(v), either way."""
    dt, vs, L = 1e-4, 1e-3, 3e-6
    t = np.arange(20000) * dt
    for s in (1.0, -1.0):
        w = _trace(s * speed * t, np.full(t.size, s * speed), vs, 2.0, L)
        assert w[-1] == pytest.approx(s * math.exp(-((speed / vs) ** 2)), rel=1e-9)


def test_bristles_rise_over_their_length_after_a_reversal_at_low_speed():
    """At a speed far below vs the element is a Dahl element (exponent 1) of that length:
    1 - exp(-d/L) after a distance d from the opposite saturation, 2*(...) from -1."""
    vs, L, speed, dt = 1.0, 2e-6, 1e-4, 1e-4  # 20 lengths each way
    n = 4000
    x = np.concatenate([np.arange(n) * speed * dt, (n - 1) * speed * dt - np.arange(1, n) * speed * dt])
    v = np.concatenate([np.full(n, speed), np.full(n - 1, -speed)])
    w = _trace(x, v, vs, 2.0, L)
    assert w[n - 1] == pytest.approx(1.0, abs=1e-6)
    d = np.arange(1, n) * speed * dt
    assert np.allclose(w[n:], -1.0 + 2.0 * np.exp(-d / L), atol=1e-6)


def _sim_fields(P, Fc):
    dFs = P["stribeck_friction"]["dFs"]  # the drive's Fs of a Gaussian rise (to_drive)
    d = {**{k: p.default for e in physics.EFFECTS.values() for k, p in e.drive.items()}, "Fc": Fc, "Fs": Fc + dFs}
    return physics.simulated_drive(d, Simulation(P, 1.0, 1.0))


@pytest.mark.parametrize("Fc, dFs", [(2.0, 1.0), (1.0, 1.0)])
def test_a_bristle_held_rise_is_simulated_as_a_dahl_element_over_a_lowered_coulomb_level(Fc, dFs):
    """Steady state Fc + dFs*phi(v) at every speed: the lowered level, its Stribeck rise
    and the saturated Dahl element (where dFs <= Fc, the range where it is exact)."""
    P = {"coulomb_friction": {"Fc": Fc},
         "stribeck_friction": {"dFs": dFs, "stribeck_velocity": 1e-3, "stribeck_shape": 2.0, "stribeck_length": 3e-6}}
    assert bristles(P) == (dFs, 3e-6)
    f = _sim_fields(P, Fc)
    assert (f["Ha"], f["sigma"], f["alpha"]) == pytest.approx((dFs, dFs / 3e-6, 1.0))
    for v in (0.0, 5e-4, 1e-3, 5e-3):
        phi = math.exp(-((v / 1e-3) ** 2))
        sliding = f["Fc"] + (f["Fs"] - f["Fc"]) * phi + f["Ha"]
        assert sliding == pytest.approx(Fc + dFs * phi)
    # a model with its own Dahl element, or a rise without bristles, keeps the plain fields
    assert bristles({**P, "hysteresis": {"Ha": 0.5}}) is None
    P["stribeck_friction"]["stribeck_length"] = 0.0
    assert bristles(P) is None and _sim_fields(P, Fc)["Fc"] == Fc


def _diagnose(family, k):
    from servo.diagnose.job import diagnose
    from studies.proving.cases import Case, recording
    from studies.proving.study import kind_jobs

    f, size, seed, _, (ctl, exc, rate, noise) = kind_jobs([family], 0, 4)[k]
    rec, truth = recording(Case(f, size, ctl, exc, rate, noise=noise), seed)
    return diagnose(rec), truth


@pytest.mark.slow
@pytest.mark.parametrize("family, k, delta", [("stribeck_exp", 8, 1.0), ("stribeck_exp", 2, 1.0)])
def test_an_exponential_stribeck_curve_is_explained_with_its_shape(family, k, delta):
    """Closed-loop chirps of the proving ground (development seeds): the Gaussian-only
    term left these unexplained with the breakaway 40 % low."""
    D, truth = _diagnose(family, k)
    assert D.verdict["verdict"] == "explained"
    (f,) = D.findings
    assert f.physics == "stribeck_friction"
    assert f.params["dFs"] == pytest.approx(truth["Fs"] - truth["Fc"], rel=0.1)
    assert f.params["stribeck_shape"] == pytest.approx(delta, abs=0.15)
    assert f.params["stribeck_velocity"] == pytest.approx(0.05 * 1e-3 * 2 * math.pi * truth["fm_hz"], rel=0.1)


@pytest.mark.slow
@pytest.mark.parametrize("k", [8, 10])
def test_a_lugre_element_with_a_stribeck_level_is_explained_by_bristles(k):
    """The full LuGre model's Stribeck peak (proving ground ``lugre_stribeck``, level
    size*Fc, bristles 0.3 % of the stroke): one finding, its level, speed and length."""
    D, truth = _diagnose("lugre_stribeck", k)
    assert D.verdict["verdict"] == "explained"
    (f,) = D.findings
    assert f.physics == "stribeck_friction"
    assert f.params["dFs"] == pytest.approx(truth["size"] * truth["Fc"], rel=0.1)
    assert f.params["stribeck_length"] == pytest.approx(3e-3 * 1e-3, rel=0.2)
    assert f.params["stribeck_velocity"] == pytest.approx(0.05 * 1e-3 * 2 * math.pi * truth["fm_hz"], rel=0.1)
