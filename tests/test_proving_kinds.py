"""The proving ground's second set of kinds (studies.proving, issue 24): each option's
physics checked on the generator's own output, so that a wrong dead zone, gap, noise
colour, mode frequency, drift or stroke fails here before it bends a study."""
import math

import numpy as np
import pytest
from scipy import signal

import studies.proving.integrate as ig
from studies.proving import cases
from studies.proving.cases import FORCE_EXCITATIONS, STROKE, Case, recording, sensor_noise, trajectories
from studies.proving.study import KIND_EXCITATIONS, KIND_LOOPS, grid_cell, kind_jobs


def _params(**kw):
    p = np.zeros(ig.N_PARAMS)
    p[ig.P_RATE], p[ig.P_J], p[ig.P_NSUB], p[ig.P_COG_PERIOD] = 1000.0, 2.0, 4, 1.0
    for k, v in kw.items():
        p[getattr(ig, "P_" + k)] = v
    return p


def _open_loop(p, w, dist=None, modes=np.zeros((0, 3))):
    """Open loop (u = w), no noise: the motor's position ``x`` and the measured ``y``."""
    n = w.size
    u, y, x = np.zeros(n), np.zeros(n), np.zeros(n)
    dist = np.zeros(n) if dist is None else np.ascontiguousarray(dist, float)
    ig.run_full(p, np.zeros(n), np.ascontiguousarray(w, float), np.full(n, 1e30), np.ones(n), np.zeros(n),
                np.zeros(1), np.ones(1), np.zeros(0), np.zeros(0), dist, np.ascontiguousarray(modes, float), u, y, x,
                n)  # fmt: skip
    return x, y


def test_the_dead_zone_removes_its_half_width_from_the_input():
    """Input dead zone of half-width d on a free mass: nothing moves within it; beyond,
    J*x'' = u - sgn(u)*d, on both sides."""
    p = _params(DEADZONE=0.5)
    for u0 in (0.49, -0.49):
        x, _ = _open_loop(p, np.full(300, u0))
        assert np.all(x == 0.0)
    t = np.arange(400) / 1000.0
    for u0 in (1.3, -2.0):
        x, _ = _open_loop(p, np.full(400, u0))
        a = np.polyfit(t[50:], x[50:], 2)[0] * 2
        assert a == pytest.approx((u0 - math.copysign(0.5, u0)) / 2.0, rel=1e-9)


def test_backlash_holds_the_load_within_its_gap_and_lets_it_wait_a_full_gap_at_reversals():
    """The sensor reads the load: never more than the half-gap b from the motor, and at
    each reversal the load stands while the motor crosses the whole gap 2b."""
    b = 2e-3
    p = _params(BACKLASH=b, K=50.0, B=1.0)
    t = np.arange(6000) / 1000.0
    x, y = _open_loop(p, 1.0 * np.sin(2 * np.pi * 1.0 * t))
    assert np.max(np.abs(y - x)) <= b * (1 + 1e-12)
    assert np.max(np.abs(y - x)) == pytest.approx(b, rel=1e-9)  # the gap is taken up while moving
    assert np.ptp(y[2000:]) == pytest.approx(np.ptp(x[2000:]) - 2 * b, rel=1e-5)  # x sampled, the play sub-stepped
    k = 2000 + int(np.argmax(x[2000:3000]))  # a reversal of the motor: the load waits for 2b of travel
    after = np.nonzero(x[k:] < x[k] - 2 * b)[0][0]
    assert np.all(y[k : k + after - 1] == y[k])


def test_the_cubic_spring_sets_the_static_deflection():
    """Overdamped, no friction: the arm settles where K*x + k3*x^3 = u (hardening and softening)."""
    for k3 in (1e5, -1e5):
        p = _params(K=100.0, K3=k3, B=50.0)
        x, _ = _open_loop(p, np.full(20000, 1.0))
        xs = x[-1]
        assert 100.0 * xs + k3 * xs**3 == pytest.approx(1.0, rel=1e-6)
        assert abs(xs - 0.01) > 5e-4  # not the linear spring's deflection


def test_the_force_offset_moves_the_equilibrium_by_dist_over_k():
    p = _params(K=100.0, B=50.0)
    x, _ = _open_loop(p, np.zeros(20000), dist=np.full(20000, 0.5))
    assert x[-1] == pytest.approx(-0.5 / 100.0, rel=1e-6)


def test_a_mode_is_advanced_exactly():
    """The modes' update against the closed form: the free decay of a unit deflection and
    the static deflection under a held force, at a frequency near the Nyquist frequency."""
    w0, zeta, J = 2 * np.pi * 450.0, 0.02, 2.0
    modes = np.array([[450.0, zeta, 1.0]])
    ms = np.array([1.0, 0.0])
    dt = 1e-3 / 4
    wd = w0 * np.sqrt(1 - zeta**2)
    for k in range(1, 41):
        ig.modes_advance(modes, ms, 0.0, dt, J)
        t = k * dt
        exact = np.exp(-zeta * w0 * t) * (np.cos(wd * t) + zeta * w0 / wd * np.sin(wd * t))
        assert ms[0] == pytest.approx(exact, abs=1e-12)
    ms = np.zeros(2)
    for _ in range(200000):
        ig.modes_advance(modes, ms, 3.0, dt, J)
    assert ms[0] == pytest.approx(3.0 / (J * w0**2), rel=1e-9)


@pytest.mark.parametrize("seed", [3, 4])
def test_the_modes_stand_in_the_frequency_response_of_the_generated_data(seed):
    """Force-driven PRBS on the ``modes`` family (modal gain 0.5, above the study's
    sizes, so that each mode dominates its band): the H1 estimate from the input to the
    measured position peaks at each of the four modes (0.06-0.45 fs) within 1 %, at least
    three times its twin's there (the same drive without the modes)."""
    case = Case("modes", 0.5, "force", "prbs", 5000.0, 30000)
    tr = trajectories(case, seed=seed)
    tw = trajectories(Case("modes", 0.0, "force", "prbs", 5000.0, 30000), seed=seed)
    fs = case.rate_hz

    def h1(d):
        f, puu = signal.welch(d["u"], fs, nperseg=4096)
        _, pyu = signal.csd(d["u"], d["y"], fs, nperseg=4096)
        return f, np.abs(pyu / puu)

    f, h = h1(tr)
    _, h0 = h1(tw)
    for hz in tr["info"]["modes_hz"]:
        sel = (f > 0.9 * hz) & (f < 1.1 * hz)
        assert f[sel][np.argmax(h[sel])] == pytest.approx(hz, rel=0.01)
        assert (h / h0)[sel].max() > 3.0  # the twin, without the modes, has no such peak


@pytest.mark.parametrize("kind,slope,band", [("pink", -1.0, (5.0, 500.0)), ("lowpass", -2.0, (100.0, 1000.0))])
def test_coloured_noise_has_its_spectral_slope_and_unit_variance(kind, slope, band):
    """Welch PSD slope (log-log) of the coloured sensor noise: -1 for pink, -2 above the
    low-pass corner (2*fm = 5 Hz at 5 kHz), flat below it."""
    fs, fm = 5000.0, 2.5
    white = np.random.default_rng(1).standard_normal(200000)
    c = sensor_noise(kind, white, fs, fm)
    assert c.std() == pytest.approx(1.0, rel=1e-12)
    f, P = signal.welch(c, fs, nperseg=16384)
    sel = (f >= band[0]) & (f <= band[1])
    fit = np.polyfit(np.log10(f[sel]), np.log10(P[sel]), 1)[0]
    assert fit == pytest.approx(slope, abs=0.15)
    if kind == "lowpass":
        low = (f > 0.3) & (f < 1.0)
        assert abs(np.polyfit(np.log10(f[low]), np.log10(P[low]), 1)[0]) < 0.5
    assert sensor_noise("white", white, fs, fm) is white


def test_the_recording_carries_the_chosen_noise():
    """Same seed, another colour: the sensor error y - x of the closed loop's recording
    is the coloured sequence times the noise level."""
    tr = trajectories(Case("null", 0.0, "pdi", "multisine", 5000.0, 20000, "pink"), seed=4)
    err = tr["y"] - tr["x"]
    assert np.allclose(err, tr["p"][ig.P_NOISE] * tr["noise"], rtol=0, atol=1e-18)
    white = trajectories(Case("null", 0.0, "pdi", "multisine", 5000.0, 20000), seed=4)["noise"]
    f, Pw = signal.welch(white, 5000.0, nperseg=4096)
    _, Pp = signal.welch(tr["noise"], 5000.0, nperseg=4096)
    assert Pp[1:5].mean() > 20 * Pw[1:5].mean()  # the pink noise's power sits at low frequency


@pytest.mark.parametrize("size", [0.3, 3.0])
def test_the_drift_has_its_size_and_time_scale(size):
    """The drift starts at 0, spans ``size*Fc`` peak to peak, and holds 90 % of its power
    below 10/T (T the recording's length); the recording differs from its twin."""
    case = Case("drift", size, "force", "multisine", 5000.0, 30000)
    tr = trajectories(case, seed=2)
    d = tr["dist"]
    assert d[0] == 0.0
    assert np.ptp(d) == pytest.approx(size * tr["info"]["Fc"], rel=1e-12)
    T = case.samples / case.rate_hz
    D = np.abs(np.fft.rfft(d - d.mean())) ** 2
    f = np.fft.rfftfreq(d.size, 1 / case.rate_hz)
    assert D[f < 10 / T].sum() > 0.9 * D.sum()
    twin = trajectories(Case("drift", 0.0, "force", "multisine", 5000.0, 30000), seed=2)
    assert np.all(twin["dist"] == 0.0)
    assert np.all(twin["w"] == tr["w"])  # the same excitation: the drift is the only difference
    assert np.abs(tr["x"] - twin["x"]).max() > 1e-3 * STROKE


@pytest.mark.parametrize("excitation", FORCE_EXCITATIONS)
def test_the_open_loop_force_drive_stays_in_its_stroke_with_no_feedback(excitation):
    """The force drive's input is the holding bias plus the excitation, whatever the
    sensor reads (the same input under white and pink noise), and the arm stays within
    the stroke, null and with the largest effects."""
    for family, size in (("null", 0.0), ("cubic_soft", 0.5), ("dead_zone", 2.0), ("drift", 3.0)):
        a = trajectories(Case(family, size, "force", excitation, 5000.0, 30000), seed=5)
        assert np.abs(a["x"]).max() <= STROKE
        if family != "dead_zone":  # a wide dead zone may swallow a small drive whole
            assert np.abs(a["x"]).max() > 0.1 * STROKE  # it does move
        assert np.all(a["u"] == a["w"])
        b = trajectories(Case(family, size, "force", excitation, 5000.0, 30000, "pink"), seed=5)
        assert np.all(a["u"] == b["u"])
    with pytest.raises(ValueError, match="force drive takes"):
        trajectories(Case("null", 0.0, "force", "seeks", 5000.0, 30000), seed=5)


def test_steps_are_steps():
    """The steps excitation's reference is piecewise constant within the stroke, each
    level held 0.05-0.15 motion periods (fm = fs/2000)."""
    tr = trajectories(Case("null", 0.0, "pdi", "steps", 5000.0, 30000), seed=1)
    r = tr["r"][4000:]  # after the fade-in (2 motion periods)
    jumps = np.nonzero(np.diff(r) != 0)[0]
    holds = np.diff(jumps)
    fm = 2.5
    assert np.abs(r).max() <= STROKE
    assert holds.min() >= int(5000.0 * 0.05 / fm) - 1 and holds.max() <= int(5000.0 * 0.15 / fm) + 1
    assert len(jumps) > 50
    assert np.all(np.diff(tr["w"][4000:])[np.arange(4000, 29999) % 8 != 7] == 0)  # the small force: held 8 samples


def test_lugre_with_a_stribeck_level_slides_on_a_gaussian_curve():
    """The LuGre element advanced at a constant speed settles at ``level*exp(-(v/vs)^2)``."""
    L, level, vs = 1e-3, 0.4, 0.01
    p = _params(HYST=ig.HYST_LUGRE, HLEVEL=level, SIGMA0=level / L, LG_VS=vs)
    for v in (0.002, 0.01, 0.02):
        hs = np.zeros(2)
        h = 1e-3  # 20000 steps: about 40 bristle lengths at the slowest speed
        for _ in range(20000):
            ig.hyst_advance(hs, v * h, h, p, np.zeros(0))
        assert p[ig.P_SIGMA0] * hs[0] == pytest.approx(level * np.exp(-((v / vs) ** 2)), rel=1e-6)


def test_a_family_the_vocabulary_lacks_is_expected_unexplained(monkeypatch):
    from servo.diagnose import terms

    assert "backlash" not in terms.VOCABULARY or cases.expected_verdicts("backlash") == ("explained",)
    monkeypatch.delitem(terms.VOCABULARY, "backlash", raising=False)
    assert cases.expected_verdicts("backlash") == ("unexplained",)
    monkeypatch.setitem(terms.VOCABULARY, "backlash", object())
    assert cases.expected_verdicts("backlash") == ("explained",)
    assert cases.expected_verdicts("null") == ("consistent",)
    rec, truth = recording(Case("dead_zone", 1.0, "pdi", "prbs", 5000.0, 20000), seed=1)
    assert truth["verdicts"] == list(cases.expected_verdicts("dead_zone"))
    assert cases.accepted("lugre_stribeck", 0.5, 10) == ("stribeck_friction", "hysteresis")


def test_the_grid_is_an_orthogonal_array():
    """Four seeds of a four-size family: each size meets each excitation once, both loops
    and both noises twice; each excitation both loops and both noises twice; the 16
    nulls of ``--nulls 16`` fill the 16 cells."""
    rows = [(i, *grid_cell("lugre", i, j)) for i in range(4) for j in range(4)]
    for i in range(4):
        mine = [r for r in rows if r[0] == i]
        assert sorted(r[2] for r in mine) == sorted(KIND_EXCITATIONS)
        assert sorted(r[1] for r in mine) == sorted(KIND_LOOPS * 2)
        assert sum(r[3] == "white" for r in mine) == 2
    for e in KIND_EXCITATIONS:
        mine = [r for r in rows if r[2] == e]
        assert sorted(r[1] for r in mine) == sorted(KIND_LOOPS * 2)
        assert sum(r[3] == "white" for r in mine) == 2
    cells = {(c, e, n != "white") for c, e, n in (grid_cell("null", 0, j) for j in range(16))}
    assert len(cells) == 16
    jobs = kind_jobs(["lugre"], 16, 4)
    assert len({j[2] for j in jobs}) == len(jobs)  # every recording its own seed


@pytest.mark.slow
def test_the_kinds_grid_study_scores_what_it_ran(tmp_path):
    """``--grid kinds`` in this process: the nulls and the family on their cells, their
    noise recorded, the tables written with the rows the brief asks for."""
    import json

    from studies.proving import study

    out = tmp_path / "st"
    assert study.main(["--grid", "kinds", "--nulls", "2", "--seeds", "1", "--families", "drift", "--workers", "0",
                       "--out", str(out)]) == 0  # fmt: skip
    runs = json.loads((out / "study.json").read_text())
    assert [(r["family"], r["size"]) for r in runs] == [("null", 0.0)] * 2 + [("drift", s) for s in (0.1, 0.3, 1.0, 3.0)]
    for r, job in zip(runs, study.kind_jobs(["drift"], 2, 1)):
        assert (r["controller"], r["excitation"], r["rate_hz"], r["noise"]) == job[4]
        assert "error" in r or r["verdicts"] == list(cases.expected_verdicts(r["family"]))
    text = (out / "study.md").read_text()
    assert "`consistent` there" in text and "| `drift` | drift | 4 |" in text
    with pytest.raises(SystemExit):
        study.main(["--grid", "kinds", "--excitation-as-r", "--out", str(out)])


@pytest.mark.slow
def test_an_outside_suite_is_scored_through_the_same_tables(tmp_path):
    """The shared independent suite (read from ../shared): its recordings written by its
    own ``main``, a case's effect measured against the suite's own twin, the records in
    the proving ground's form."""
    from studies.proving import independent
    from studies.proving.study import tables_kinds

    mod = independent.load_suite(independent.DEFAULT_SUITE)
    import contextlib
    import io

    with contextlib.redirect_stdout(io.StringIO()):
        mod.main(str(tmp_path))
    null = independent.score_case(mod, "null", tmp_path)
    delay = independent.score_case(mod, "delay", tmp_path)
    assert null["null"] and null["verdicts"] == ["consistent"] and "effect" not in null
    assert delay["accept"] == ["time_delay"] and delay["verdicts"] == ["explained"]
    assert delay["effect"] > 0.2  # a 3-sample delay at 20 kHz changes the held-out error
    t, u, x = independent._simulate(mod, "null", {})
    rec = np.loadtxt(tmp_path / "null.csv", delimiter=",", skiprows=1)
    assert np.allclose(rec[:, 1], u, rtol=1e-9) and np.allclose(rec[:, 2], x, rtol=1e-9, atol=1e-18)
    text = tables_kinds([null, delay], label="case")
    assert "| `delay` | time_delay | 1 | 0 |" in text


def test_bouc_wen_survives_a_steps_kick():
    """A step reference kicks the arm by more than the Bouc-Wen element's length in one
    sub-step; its position step is split there, so this recording (which diverged with
    one RK4 step per sub-step) stays finite and in its stroke."""
    tr = trajectories(Case("bouc_wen", 0.1, "pdi", "steps", 5000.0, 30000), seed=310102)
    assert np.all(np.isfinite(tr["y"])) and np.abs(tr["x"]).max() < 2 * STROKE
