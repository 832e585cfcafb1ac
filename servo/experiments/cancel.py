"""The proof, end to end (issue 14.3): per cancellable term, a drive carrying it beyond
the paper's model, a diagnosis of a recording made on it, the compensator written from
that diagnosis twice (the paper's eq. 9 and the augmented one), and the paper's
measurements repeated with both.

Per :class:`Case` (:data:`CASES`):

1. **The drive**: the paper's drive (the default ``[drive]``, with its Dahl pivot, its
   flexible modes and its 10 us input delay) plus ONE effect (:attr:`Case.drive`).
2. **The recording**: the identification scenario of
   :mod:`servo.diagnose.concealed` (the PI holding loop tracking a long-stroke
   multi-sine reference plus a band-limited random current; :attr:`ChainSettings.recording`)
   on that drive, seed :attr:`ChainSettings.seed`.
3. **The diagnosis**: :func:`servo.diagnose.job.diagnose` with its defaults; the report
   (``report.json``) is what the compensator is written from.  Whether it named the
   effect is recorded; if it did not, the chain goes on with what it found.
4. **The compensators**: :func:`servo.compensate.job.compensate` on that report,
   ``paper=True`` ("paper": what eq. 9 alone holds of the diagnosed model) and
   ``paper=False`` ("augmented").  For the Dahl case, where eq. 9 itself holds the
   diagnosed Dahl element, the *before* is the paper's compensator as published for the
   nominal drive (the default ``[compensator]``, not retuned: Fig. 9-10's situation).
   Both are taken as ``servo compensate`` writes them.  A third compensator, the drive's exact model
   (``servo compensate`` of the drive's own config), gives the ceiling
   (:attr:`ChainSettings.exact`).
5. **The measurements**, each with both compensators on the same drive and inputs:

   * Fig. 8: stepped-sine Bode of the compensated plant (``u_n -> x``) at every level of
     :attr:`ChainSettings.sweep`; :func:`~servo.experiments.bode_analysis.linearity` in
     the band below the first flexible mode (spread across levels in dB, slope per level
     in dB/decade, phase range), and the gain error against the double integrator
     ``1/(J w^2)`` of the drive's own ``J`` (the largest over levels of the median over
     the band of ``|X/U| - 1/(J w^2)`` in dB).
   * ``servo run``: the run scenario (``[scenario]``, hold / 0.3 um / 20 um steps /
     force disturbance) on the fast path, reduced by :class:`servo.run.reduce.RunFigures`
     (the same figures ``servo run`` prints): overshoot and settling per step, error RMS
     per segment and over the run.
   * Tracking: a long-stroke reference like the recording's, slower (:data:`TRACKING`),
     with a *different* seed (phases the diagnosis never saw) and no excitation current;
     the tracking error RMS.

Everything is simulated on the fast path: the same bits as tick by tick and, through
the serial emulator in lockstep, as over the link (``tests/test_cancel_chain.py``).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from servo.compensate.job import compensate
from servo.compensate.propose import apply
from servo.config import Config, to_toml
from servo.diagnose.concealed import RATE_HZ, Scenario, scenario_inputs
from servo.diagnose.job import Options, diagnose
from servo.diagnose.report import build_report
from servo.experiments.bode import SweepSettings, check_holding_loop, sweep
from servo.experiments.bode_analysis import band_max, linearity
from servo.runtime.closedloop import run_in_memory, simulate
from servo.io import progress
from servo.io.atomic import atomic_write, write_json
from servo.io.recording import Recording
from servo.run.reduce import RunFigures
from servo.scenarios import scenario_inputs as run_inputs


@dataclass(frozen=True)
class Case:
    """One cancellable term: ``name`` (its key), ``physics`` (what the diagnosis should
    name), ``what`` (the effect in words), ``drive`` (the ``[drive]`` fields set on the
    paper's drive), ``before`` ("paper": eq. 9 of the diagnosed model; "nominal": the
    default ``[compensator]``, the paper's for the nominal drive); ``measure_at`` (m):
    where the arm is held for the measurements (the recording is made at the centre)."""

    name: str
    physics: str
    what: str
    drive: dict
    before: str = "paper"
    measure_at: float = 0.0


CASES = {
    c.name: c
    for c in (
        Case("asymmetric_friction", "asymmetric_friction", "viscous friction 50 % asymmetric: B(+) = 1.5 B, B(-) = 0.5 B",
             {"b_asymmetry": 0.5}),
        Case("stribeck_friction", "stribeck_friction", "a Coulomb friction beyond the Dahl element, 0.1 mA sliding, "
             "0.4 mA breakaway, Stribeck velocity 5 mm/s", {"Fc": 0.1e-3, "Fs": 0.4e-3, "stribeck_velocity": 5e-3}),
        Case("cogging", "cogging", "a force periodic in position, 0.1 mA, period 50 um",
             {"cogging": 1e-4, "cogging_period": 50e-6}),
        Case("position_dependent_gain", "position_dependent_gain", "force constant +50 % at +15 mm (linear); "
             "recorded at the centre, measured with the arm held at +7.5 mm", {"kf_linear": 0.5}, measure_at=7.5e-3),
        Case("hysteresis", "hysteresis", "a Dahl pivot other than the nominal one: sigma 416 A/m (+30 %), "
             "Ha 1.5 mA (+50 %)", {"sigma": 416.0, "Ha": 1.5e-3}, before="nominal"),
    )
}  # fmt: skip


#: the held-out tracking reference: the recording's strokes at a tenth of its frequencies
#: (the 100 Hz holding loop follows them; what it does not is mostly the uncancelled force)
TRACKING = Scenario(ref_hz=(0.3, 1.1, 3.7), exc_rms=0.0)


@dataclass(frozen=True)
class ChainSettings:
    """``recording``: the identification scenario; ``seed`` its seed (the drive's noise
    too); ``tracking_seed``: the held-out reference's phases; ``tracking_s``: its
    duration; ``sweep``: the Bode sweeps; ``run_s``: the ``servo run`` scenario's
    duration (None: the config's); ``exact``: measure a third compensator, the drive's
    exact model (``servo compensate`` of the drive's own config: what cancellation can
    reach on this drive, the ceiling the other two are read against)."""

    recording: Scenario = Scenario()
    seed: int = 0
    tracking: Scenario = TRACKING
    tracking_seed: int = 1
    tracking_s: float = 1.0
    sweep: SweepSettings = SweepSettings()
    run_s: float | None = None
    exact: bool = True


#: the quick settings of the test suite: the same code path, shorter signals
QUICK = ChainSettings(tracking_s=0.3,
                      sweep=SweepSettings(levels=(0.2e-3, 16e-3), f_min=20.0, f_max=800.0, n_freq=6, periods=4,
                                          settle_periods=3, settle_s=0.02), exact=False)  # fmt: skip


def drive_config(base: Config, case: Case, seed: int) -> Config:
    """``base`` with the case's effect on its drive, seeded, at the recording's rate."""
    return base.replace(drive=case.drive, run={"seed": int(seed), "sample_rate_hz": RATE_HZ})


def identification_recording(cfg: Config, sc: Scenario, seed: int) -> Recording:
    """The identification experiment on the drive of ``cfg`` (no compensator: the drive
    as it is), as a recording (t, u, x)."""
    r, e = scenario_inputs(sc, seed, cfg.dt)
    log = simulate(cfg, e, r=r)
    return Recording(log["t"], log["u"], log["x"], None, source=f"simulated drive, identification scenario, seed {seed}")


def bode_figures(cfg: Config, s: SweepSettings) -> tuple[dict, list]:
    """Fig. 8's numbers for the compensated plant of ``cfg`` (see module doc) and the
    sweeps, one per level."""
    sweeps = [sweep(cfg, level, s, True) for level in s.levels]
    band = min(band_max(cfg), s.f_max)
    lin = linearity(sweeps, band)
    m = sweeps[0].f <= band
    di = -20 * np.log10(cfg.drive.J * (2 * np.pi * sweeps[0].f[m]) ** 2)
    gain = [float(np.median(sw.mag_db[m] - di)) for sw in sweeps]
    slopes = list(lin["slope_db_per_decade"].values())
    return {
        "band_hz": lin["band_hz"],
        "spread_db_max": lin["spread_db_max"],
        "spread_db_rms": lin["spread_db_rms"],
        "slope_db_per_decade": lin["slope_db_per_decade"],
        "slope_min": min(slopes),
        "slope_max": max(slopes),
        "phase_deg_min": lin["phase_deg_min"],
        "phase_deg_max": lin["phase_deg_max"],
        "gain_error_db_per_level": gain,
        "gain_error_db": max(gain, key=abs),
    }, sweeps


def run_figures(cfg: Config, duration_s: float | None = None) -> dict:
    """The step and tracking figures ``servo run`` reports (:class:`RunFigures`) of the
    run scenario of ``cfg`` with its compensator, on the fast path."""
    if duration_s is not None:
        cfg = cfg.replace(run={"duration_s": duration_s})
    cfg = cfg.replace(run={"log_every": 1})
    log = run_in_memory(cfg, run_inputs(cfg), compensation=True)
    fig = RunFigures(cfg)
    fig(log.data[: log.rows])
    return fig.result()


def tracking_error(cfg: Config, sc: Scenario, seed: int, duration_s: float) -> np.ndarray:
    """The tracking error (m, one per tick after the fade-in) of the compensated loop of
    ``cfg`` following the long-stroke reference of ``sc`` (phases of ``seed``, no
    excitation current)."""
    r, _ = scenario_inputs(replace(sc, duration_s=duration_s), seed, cfg.dt)
    log = simulate(cfg, np.zeros_like(r), r=r, compensation=True)
    return log["e"][int(round(sc.fade_s / cfg.dt)) :]


def tracking_figures(cfg: Config, sc: Scenario, seed: int, duration_s: float, exact: np.ndarray | None = None) -> dict:
    """The error RMS and max (m) of :func:`tracking_error`; with ``exact`` (the error of
    the same loop with the drive's exact model as compensator), ``excess_rms_m``: the RMS
    of the difference, what the compensator's model leaves to the loop."""
    e = tracking_error(cfg, sc, seed, duration_s)
    out = {"error_rms_m": float(np.sqrt(np.mean(e**2))), "error_max_m": float(np.max(np.abs(e)))}
    if exact is not None:
        out["excess_rms_m"] = float(np.sqrt(np.mean((e - exact) ** 2)))
    return out


@dataclass
class CaseResult:
    """What one case produced: ``found`` (the diagnosis named the effect), ``findings``
    (every physics it named), ``report`` (its report.json), the two compensator sections
    and their measurements (``before``/``after``: ``{"bode", "run", "tracking"}``; None
    when the diagnosis's final model is not a drive, ``note`` says why), and
    the sweeps (``sweeps[label]``, one per level) for the figures; ``exact``: the
    measurements with the drive's exact model (None unless :attr:`ChainSettings.exact`)."""

    case: Case
    found: bool
    findings: list
    diagnosed: dict
    report: dict
    compensators: dict
    before: dict | None
    after: dict | None
    exact: dict | None = None
    sweeps: dict = field(default_factory=dict)
    note: str = ""


def _diagnosed_params(report: dict, physics: str) -> dict:
    for f in report["findings"]:
        if f["physics"] == physics:
            return {k: v for k, v in f["params"].items() if isinstance(v, (int, float))}
    return {}


def measure(cfg: Config, s: ChainSettings, exact: np.ndarray | None = None) -> tuple[dict, list]:
    """The three measurements of the module doc for the config ``cfg`` (drive and
    compensator); returns ``({"bode", "run", "tracking"}, sweeps)``; ``exact``: the
    tracking error with the exact compensator (:func:`tracking_figures`)."""
    bode, sweeps = bode_figures(cfg, s.sweep)
    return {"bode": bode, "run": run_figures(cfg, s.run_s),
            "tracking": tracking_figures(cfg, s.tracking, s.tracking_seed, s.tracking_s, exact)}, sweeps  # fmt: skip


def run_case(base: Config, case: Case, s: ChainSettings, workdir: Path) -> CaseResult:
    """The whole chain for ``case`` (module doc); the diagnosis's report.json is written
    into ``workdir`` (the compensator is read from it, as ``servo compensate`` does)."""
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    cfg = drive_config(base, case, s.seed)
    check_holding_loop(cfg, seconds=0.2, name=f"the drive with {case.name}")
    progress.stage(f"{case.name}: the identification recording and its diagnosis")
    rec = identification_recording(cfg, s.recording, s.seed)
    D = diagnose(rec, Options())
    report = build_report(D, ["report.json"])
    path = workdir / "report.json"
    write_json(path, report)
    names = [f["physics"] for f in report["findings"]]
    found = case.physics in names
    note = "" if found else f"the diagnosis did not name {case.physics}; the compensators hold what it found"
    if report["final_model"]["drive"] is None:  # nothing servo compensate can read: said, and the case ends here
        why = f"the diagnosis's final model is not a drive ({report['final_model']['drive_note']}): no compensator"
        return CaseResult(case, found, names, _diagnosed_params(report, case.physics), report, {}, None, None,
                          note="; ".join(x for x in (note, why) if x))  # fmt: skip
    paper = compensate(path, cfg, paper=True)
    full = compensate(path, cfg, paper=False)
    at = cfg.replace(drive={"initial_position": case.measure_at})
    cfg_before = at.replace(compensator={"enabled": True}) if case.before == "nominal" else apply(at, paper)
    cfg_after = apply(at, full)
    exact, e_exact, sweeps = None, None, {}
    if s.exact:
        progress.stage(f"{case.name}: the paper's measurements, the drive's exact model")
        atomic_write(workdir / "drive.toml", lambda f: Path(f).write_text(to_toml(cfg)))
        cfg_exact = apply(at, compensate(workdir / "drive.toml", cfg))
        e_exact = tracking_error(cfg_exact, s.tracking, s.tracking_seed, s.tracking_s)
        exact, sweeps["exact"] = measure(cfg_exact, s, e_exact)
    progress.stage(f"{case.name}: the paper's measurements, {'nominal' if case.before == 'nominal' else 'paper'} "
                   "compensator")  # fmt: skip
    before, sweeps["before"] = measure(cfg_before, s, e_exact)
    progress.stage(f"{case.name}: the paper's measurements, augmented compensator")
    after, sweeps["after"] = measure(cfg_after, s, e_exact)
    sections = {"before": {k: getattr(cfg_before.compensator, k) for k in full.section}, "after": dict(full.section)}
    return CaseResult(case, found, names, _diagnosed_params(report, case.physics), report, sections, before, after,
                      exact, sweeps, note)  # fmt: skip


__all__ = ["CASES", "QUICK", "TRACKING", "Case", "CaseResult", "ChainSettings", "bode_figures", "drive_config",
           "identification_recording", "measure", "run_case", "run_figures", "tracking_error", "tracking_figures"]  # fmt: skip
