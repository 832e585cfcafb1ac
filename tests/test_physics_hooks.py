"""The effects' hooks for the forces the rest of the tool asks about (``servo/physics/``):
the holding current at start, the forces a model's current must cover, the fields a
force constant converts."""
from __future__ import annotations

import math

import pytest

from servo import physics
from servo.compensate.plausible import implausible
from servo.compensate.propose import largest_force
from servo.config import Config
from servo.runtime.simplant import build_plant, holding_command, holding_current


def _drive(**kw):
    return Config().replace(drive=kw).drive


def test_the_holding_current_is_every_force_at_rest_through_the_force_constant():
    x = 1.2e-3
    d = _drive(K=0.3, h0=-2e-3, k3=4e4, cogging=3e-4, cogging_period=7e-5, cogging_phase=0.4, kf_linear=0.2,
               kf_quadratic=-0.1, initial_position=x)  # fmt: skip
    r = x / d.stroke
    at_rest = 0.3 * x - 2e-3 + 4e4 * x**3 + 3e-4 * math.sin(2 * math.pi * x / 7e-5 + 0.4)
    by_hand = at_rest / (1 + 0.2 * r - 0.1 * r * r)
    assert holding_current(d, x) == pytest.approx(by_hand, rel=1e-14)
    assert physics.rest_force(d, x) * 1.0 / physics.force_gain(d, x) == holding_current(d, x)
    # the dead zone: the command is the current plus the half-width, on its side
    dz = _drive(dead_zone=5e-4, h0=-2e-3, K=0.0)
    assert holding_command(dz, holding_current(dz, 0.0)) == -2e-3 - 5e-4
    assert holding_command(dz, 0.0) == 0.0 and holding_command(_drive(), 1e-3) == 1e-3
    assert build_plant(dz, 2e-5).u_hold == -2e-3 - 5e-4


def test_an_effect_without_a_force_at_rest_adds_nothing_not_even_a_zeros_sign():
    d = _drive(K=0.0, h0=0.0)
    assert math.copysign(1.0, holding_current(d, -1e-3)) == 1.0
    assert holding_current(_drive(K=0.1, h0=0.0), -1e-3) == 0.1 * -1e-3


def test_the_largest_forces_of_one_name_add_up_across_effects():
    c = dict(B=2e-3, b_asymmetry=0.5, h0=1e-3, K=0.1, k3=1e4, sliding_level=1e-3, Ha=2e-3, coulomb_extra=1e-4,
             coulomb_static=3e-4, coulomb_asymmetry=-0.2, periodic_amplitudes=[1e-5, -2e-5], dead_zone=4e-4)  # fmt: skip
    f = physics.largest_forces(c, 1e-2, 0.5)
    assert f[physics.base.BIAS] == pytest.approx(1e-3 + 0.1 * 1e-2 + 1e4 * 1e-6)
    assert f[physics.base.SLIDING] == pytest.approx(2e-3 + 3e-4 * 1.2)
    assert f[physics.base.VISCOUS] == pytest.approx(2e-3 * 1.5 * 0.5)
    assert f["periodic force's amplitude"] == pytest.approx(3e-5) and f["input dead zone's half-width"] == 4e-4
    assert largest_force(c, 0.5, 1e-2) == pytest.approx(sum(f.values()))
    assert physics.base.VISCOUS not in physics.largest_forces(c, 1e-2, None)  # speed unknown


def test_a_model_is_refused_for_the_sliding_friction_of_both_elements_together():
    base = Config()
    u = base.controller.current_limit
    both = dict(J=1e-3, B=0.0, K=0.0, h0=0.0, Ha=0.6 * u, sigma=1e3, Fc=0.6 * u, Fs=0.6 * u)
    (why,) = implausible(both, base)
    assert "sliding friction level" in why and "beyond the current limit" in why
    assert implausible(dict(both, Fc=0.3 * u, Fs=0.3 * u), base) == []
    (why,) = implausible(dict(both, Fc=0.0, Fs=0.0, h0=0.5 * u, K=60 * u), base)  # 0.5 + 60*0.015 = 1.4 A
    assert why.startswith("the bias") and "1.4" in why


def test_the_fields_a_force_constant_converts_are_those_declared_in_the_force_unit():
    fields = physics.force_fields()
    assert {"B", "K", "h0", "Ha", "Fc", "Fs", "cogging", "sigma", "J", "k3", "dead_zone"} <= set(fields)
    for e in physics.EFFECTS.values():
        for k, f in {**e.drive, **e.compensator}.items():
            assert (k in fields) == (f.metadata["unit"].split("/")[0].split("*")[0] == "A"), (e.name, k)


def test_a_rate_of_the_rigid_body_beyond_nyquist_is_refused_by_its_effect():
    base = Config()
    nyquist = math.pi / base.dt
    rates = physics.rates(dict(B=2e-3, K=0.1), 1e-3)
    assert rates == {"viscous pole |B|/J": 2.0, "natural frequency sqrt(|K|/J)": 10.0}
    (why,) = implausible(dict(J=1e-3, B=1.01e-3 * nyquist, K=0.0), base)
    assert why.startswith("the viscous pole |B|/J") and "Nyquist" in why
    bias, why = implausible(dict(J=1e-3, B=0.0, K=1e-3 * (1.01 * nyquist) ** 2), base)  # a bias beyond the limit too
    assert bias.startswith("the bias") and why.startswith("the natural frequency") and "Nyquist" in why
    assert [w for w in implausible(dict(J=1e-3, B=0.99e-3 * nyquist, K=1e-3 * (0.99 * nyquist) ** 2), base)
            if "Nyquist" in w] == []
