"""Before a compensator is proposed: is it better, on the model it came from, than eq. 9
alone and than no compensator?

The model (:class:`~servo.compensate.model.SourceModel`) is a drive: the check puts it in
the base config's place (its controller, rate and scenario; the base's drive supplies
what the source lacks) and runs, in memory on the all-compiled path
(:func:`servo.runtime.closedloop.run_in_memory`, the bits ``servo run`` logs):

* **the closed loop** (``servo run``'s scenario: the reference steps, then the force
  disturbance; :class:`servo.run.reduce.RunFigures`) with no compensator, eq. 9's
  (``--paper``) and the augmented one: each step's overshoot and settling, the error RMS
  of the disturbance segment;
* **Fig. 8** (:data:`SWEEP`): the stepped-sine response of the compensated plant, the
  plant the controller sees ``P = X/U_n`` (:func:`servo.loop.measure.measure`), at
  several levels, and its spread across the levels at which the arm moves under both
  compensators (the median gain within :data:`MOVING_DB` of ``1/(J w^2)``: a static term
  acts only while the arm moves; at a level where it sticks both spreads measure the
  sticking, not the cancellation).

**Worse** (:func:`worse`), figure by figure, beyond the tolerances of
:class:`Tolerances`: a step that settles later (by more than 20 % and 1 ms) or never
where the other settled, that overshoots more by more than the 5 % settling band, a
disturbance error larger by more than 10 %, a Fig. 8 spread larger by more than 0.5 dB.

**The choice** (:func:`choose`): the augmented compensator is proposed where it is worse
than eq. 9 on no figure; where it is worse on some and eq. 9 on none, eq. 9's; where each
is worse on some, the one with fewer steps worse (eq. 9's on a tie).  The figures that
decided are said.  Then the
proposal against no compensator: worse steps are a refusal (``servo compensate`` writes
nothing unless ``--allow-worse``), a worse disturbance error a warning (cancelling the
pivot's friction removes the damping that helped reject a force: ``servo run`` shows it
on the default drive, docs/compensate.md).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from servo.compensate.model import CompensateError, SourceModel
from servo.compensate.propose import Proposal, apply
from servo.config import Config, ScenarioConfig
from servo.errors import ConfigError, ServoError, first_line
from servo.io import progress
from servo.loop.measure import LoopSettings, measure
from servo.run.reduce import RunFigures
from servo.runtime.closedloop import run_in_memory
from servo.scenarios import scenario_inputs

#: Fig. 8 of the check: four levels of the paper's figure, six frequencies below the
#: default drive's first mode (3 kHz / 3), four periods each
SWEEP = LoopSettings(levels=(0.2e-3, 1e-3, 4e-3, 16e-3), f_min=20.0, f_max=800.0, n_freq=6, periods=4,
                     settle_periods=3, settle_s=0.02)  # fmt: skip
#: a level counts in the spread when its median gain lies within this of 1/(J w^2) (dB)
MOVING_DB = 20.0


@dataclass(frozen=True)
class Tolerances:
    """How much worse a figure may be before it counts (module doc)."""

    settle_rel: float = 0.2
    settle_ms: float = 1.0
    overshoot_pct: float = 5.0
    disturbance_rel: float = 0.1
    spread_db: float = 0.5


def model_config(model: SourceModel, base: Config) -> Config:
    """The config the check runs: ``base`` with the model's drive in place of its own
    (the fields the model sets), the ``servo run`` steps scenario (``base``'s when it is
    one, else the default's), logged every tick."""
    cfg = base.replace(drive=dict(model.drive), run={"log_every": 1})
    if cfg.scenario.kind != "steps":
        cfg = cfg.replace(scenario={k: getattr(ScenarioConfig(), k) for k in ("kind", "step_times", "step_positions",
                                                                             "disturbance_amplitude")})  # fmt: skip
    return cfg


def run_figures(cfg: Config, compensation: bool) -> dict:
    """``servo run``'s figures of ``cfg`` with or without its compensator
    (:class:`RunFigures`: ``steps``, ``error_rms_by_segment_m``, ...)."""
    log = run_in_memory(cfg, scenario_inputs(cfg), compensation=compensation)
    fig = RunFigures(cfg)
    fig(log.data[: log.rows])
    return fig.result()


def fig8(cfg: Config, s: LoopSettings = SWEEP) -> tuple[np.ndarray, np.ndarray]:
    """The compensated plant ``P = X/U_n`` of ``cfg`` (m/A): frequencies (Hz, (n,)) and
    its magnitude in dB per level, shape ``(levels, n)``."""
    runs = [measure(cfg, s, level, True) for level in s.check(cfg).levels]
    return runs[0].f, np.array([20 * np.log10(np.abs(r.value("P"))) for r in runs])


def spreads(f: np.ndarray, a: np.ndarray, b: np.ndarray, levels, J: float) -> tuple[float | None, float | None, list]:
    """The Fig. 8 spreads (max over frequency of max - min over levels, dB) of the
    magnitudes ``a`` and ``b`` (dB, (levels, n) at ``f`` Hz) over the levels at which the
    arm moves under both (module doc), and those levels (A); None when fewer than two do."""
    di = -20 * np.log10(J * (2 * np.pi * f) ** 2)
    moving = [i for i in range(len(levels)) if all(np.median(m[i] - di) > -MOVING_DB for m in (a, b))]
    if len(moving) < 2:
        return None, None, []
    spread = lambda m: float(np.max(np.ptp(m[moving], axis=0)))  # noqa: E731
    return spread(a), spread(b), [float(levels[i]) for i in moving]


def _step_name(step: dict) -> str:
    return f"step {step['size_m'] * 1e6:+.3g} um"


def _settle(v) -> str:
    return "never settles" if v is None else f"{v:.1f} ms settling"


def worse(a: dict, b: dict, tol: Tolerances = Tolerances()) -> tuple[list[str], list[str]]:
    """Where the figures ``a`` are worse than ``b`` (each ``{"run": RunFigures result,
    "spread_db": float | None}``), as phrases: ``(steps, others)``, ``others`` the
    disturbance error and the Fig. 8 spread."""
    steps = []
    for sa, sb in zip(a["run"]["steps"], b["run"]["steps"]):
        ta, tb = sa["settling_ms"], sb["settling_ms"]
        later = (ta is None and tb is not None) or (
            ta is not None and tb is not None and ta > tb * (1 + tol.settle_rel) + tol.settle_ms)  # fmt: skip
        more = sa["overshoot_pct"] > sb["overshoot_pct"] + tol.overshoot_pct
        if later or more:
            steps.append(f"{_step_name(sa)} {sa['overshoot_pct']:.1f} % overshoot, {_settle(ta)}, against "
                         f"{sb['overshoot_pct']:.1f} %, {_settle(tb)}")  # fmt: skip
    others = []
    da = a["run"]["error_rms_by_segment_m"].get("disturbance")
    db = b["run"]["error_rms_by_segment_m"].get("disturbance")
    if da is not None and db is not None and da > db * (1 + tol.disturbance_rel):
        others.append(f"disturbance error {da * 1e9:.4g} nm RMS against {db * 1e9:.4g} nm")
    if a.get("spread_db") is not None and b.get("spread_db") is not None and a["spread_db"] > b["spread_db"] + tol.spread_db:
        others.append(f"Fig. 8 spread {a['spread_db']:.1f} dB against {b['spread_db']:.1f} dB")
    return steps, others


@dataclass
class Check:
    """The check's outcome: ``figures`` per compensator ("none", "eq. 9", "augmented":
    ``{"run": ..., "spread_db": ...}``), ``chosen`` ("augmented" or "eq. 9"), ``why``:
    the phrases where the augmented one is worse than eq. 9 and ``against`` where eq. 9
    is worse than the augmented one (both empty: no choice to make); ``steps_worse`` and
    ``others_worse``: where the chosen one is worse than no compensator;
    ``spread_levels_a``: the levels the spreads were taken over."""

    figures: dict
    chosen: str
    why: list = field(default_factory=list)
    against: list = field(default_factory=list)
    steps_worse: list = field(default_factory=list)
    others_worse: list = field(default_factory=list)
    spread_levels_a: list = field(default_factory=list)

    def as_dict(self) -> dict:
        return {"chosen": self.chosen, "augmented_worse_than_eq9": self.why, "eq9_worse_than_augmented": self.against,
                "steps_worse_than_none": self.steps_worse,
                "others_worse_than_none": self.others_worse, "spread_levels_a": self.spread_levels_a,
                "figures": self.figures}  # fmt: skip


def same(a: Proposal, b: Proposal) -> bool:
    """Whether two proposals write the same section (to rounding)."""
    return a.section.keys() == b.section.keys() and all(
        np.allclose(a.section[k], b.section[k], rtol=1e-9, atol=0.0) for k in a.section)  # fmt: skip


def _on_model(what: str, fn, *args):
    """``fn(*args)``, a run on the model: a fault of that run is one line naming it."""
    try:
        return fn(*args)
    except ServoError as exc:
        raise CompensateError(f"the check on the model failed, {what}: {first_line(exc)} (--no-check skips it)") from None


def choose(model: SourceModel, base: Config, eq9: Proposal, augmented: Proposal | None = None,
           tol: Tolerances = Tolerances(), label: str = "eq. 9") -> Check:  # fmt: skip
    """Run the check (module doc) of the proposals of ``model`` on ``base``: eq. 9's and,
    unless None (``--paper``, or nothing beyond eq. 9: :func:`same`), the augmented one;
    ``label``: the name of ``eq9`` when it is the only one.  Fig. 8 is left out (its
    spreads None) where the base config cannot run its sweep (a rate too low for 800 Hz,
    a current limit under 16 mA)."""
    cfg = model_config(model, base)
    progress.stage("checking on the model: the closed loop with no compensator")
    figs = {"none": {"run": _on_model("with no compensator", run_figures, cfg, False), "spread_db": None}}
    cands = {label: eq9} if augmented is None else {"eq. 9": eq9, "augmented": augmented}
    for name, p in cands.items():
        progress.stage(f"checking on the model: the closed loop with {name}'s compensator")
        figs[name] = {"run": _on_model(f"with {name}'s compensator", run_figures, apply(cfg, p), True), "spread_db": None}
    chosen, why, against, levels = next(iter(cands)), [], [], []
    if augmented is not None:
        progress.stage("checking on the model: Fig. 8 with each compensator")
        try:
            SWEEP.check(cfg)
        except ConfigError:
            sweeps = None
        else:
            sweeps = [_on_model(f"Fig. 8 with {n}'s compensator", fig8, apply(cfg, p)) for n, p in cands.items()]
        if sweeps is not None:
            (f, me), (_, ma) = sweeps
            figs["augmented"]["spread_db"], figs["eq. 9"]["spread_db"], levels = spreads(f, ma, me, SWEEP.levels,
                                                                                         cfg.drive.J)  # fmt: skip
        a_steps, a_others = worse(figs["augmented"], figs["eq. 9"], tol)
        e_steps, e_others = worse(figs["eq. 9"], figs["augmented"], tol)
        why, against = a_steps + a_others, e_steps + e_others
        # no worse anywhere; or, each worse somewhere, fewer steps worse
        chosen = "augmented" if not why or (against and len(a_steps) < len(e_steps)) else "eq. 9"
    steps, others = worse({**figs[chosen], "spread_db": None}, figs["none"], tol)
    return Check(figs, chosen, why, against, steps, others, levels)


__all__ = ["MOVING_DB", "SWEEP", "Check", "Tolerances", "choose", "fig8", "model_config", "run_figures", "same", "spreads",
           "worse"]
