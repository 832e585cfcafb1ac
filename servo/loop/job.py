"""The ``servo loop`` job: L, S and T measured in closed loop, set against the design.

For each compensator setting (on, off or both) and excitation level, one stepped-sine
run (:mod:`servo.loop.measure`) on the simulated drive or through a driver the caller
makes (the serial link); then the designs (:mod:`servo.loop.design`) and the margins of
everything on the same band (:mod:`servo.design.margins`).

Files written into one folder (all computed before the first is written):

* ``frd.npz`` -- every response in the format of :mod:`servo.io.frequency_response`
  (``load_frequency_responses(path)[label].to_control()`` is a
  ``control.FrequencyResponseData``): measured ``L``, ``S``, ``T``, ``P``, ``C``,
  ``L_u``, ``S_u``, ``T_u`` per run (labels ``"L, compensator on, 0.2 mA"``), and the
  designs' ``L``, ``S``, ``T`` on a 400-point grid (``"design L, nominal 1/(J s^2)"``);
* ``loop.csv`` -- the same as one table;
* ``loop.png`` -- Bode plot of ``L``, measured and designed, crossover and phase margin marked;
* ``sensitivity.png`` -- ``|S|`` and ``|T|``, measured and designed;
* ``summary.json`` -- settings, margins of every run and design, each measured margin's
  uncertainty (:mod:`servo.loop.quality`) and ``warnings`` for those beyond tolerance,
  agreement with the design, crossover shift without the compensator, link report,
  provenance;
* ``report.html`` -- all of it on one self-contained page (:mod:`servo.loop.page`).
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from servo.config import Config
from servo.errors import UnstableLoop
from servo.io import progress
from servo.io.atomic import write_json
from servo.io.frequency_response import FrequencyResponse, save_csv, save_npz
from servo.loop.design import (LoopDesign, compensator_response, controller_response, current_loop_design,
                               loop_design, sampled_plant)
from servo.design.margins import margins
from servo.loop.measure import RESPONSES, LoopMeasurement, LoopSettings, measure
from servo.io.provenance import or_default
from servo.loop.page import page
from servo.loop.plots import plot_loop, plot_sensitivity
from servo.loop.quality import uncertainty, warnings_for
from servo.runtime.controller import compensation_runs

#: points of a design written to the files and plotted
FILE_POINTS = 400
#: points of a design for its curves and the agreement (on the measured band)
MARGIN_POINTS = 1200
#: points of a design for its margins, log-spaced over the whole band up to Nyquist
FULL_BAND_POINTS = 8000
#: the design loops: key -> (plant model, compensated) of :func:`servo.loop.design.loop_design`
DESIGN_MODELS = {"nominal": ("nominal", True), "drive": ("drive", True), "pivot": ("drive", False)}
NAMES = {"nominal": "nominal 1/(J s^2)", "drive": "drive model, compensated",
         "pivot": "drive model, pivot small-signal, no comp."}  # fmt: skip


def designs(cfg: Config, f_min: float, f_max: float, n: int, comps) -> dict[str, LoopDesign]:
    """The designs a run set is compared with, on ``n`` log-spaced points of the band:
    the nominal ``1/(J s^2)`` loop, the drive model compensated (when a run has the
    compensator) and with the pivot's small-signal stiffness (when one has not)."""
    f = np.geomspace(f_min, f_max, n)
    out = {"nominal": loop_design(cfg, f, "nominal")}
    if True in comps:
        out["drive"] = loop_design(cfg, f, "drive", compensated=True)
    if False in comps:
        out["pivot"] = loop_design(cfg, f, "drive", compensated=False)
    return out


def full_band(cfg: Config) -> np.ndarray:
    """The whole band of a design's margins (Hz): from 1e-5 of the Nyquist frequency up
    to it, :data:`FULL_BAND_POINTS` log-spaced points."""
    nyq = 0.5 * cfg.run.sample_rate_hz
    return np.geomspace(1e-5 * nyq, nyq, FULL_BAND_POINTS)


def design_margins(cfg: Config, key: str) -> dict:
    """Margins of the design loop ``key`` (:data:`DESIGN_MODELS`; ``"current"``: the loop
    broken at the current with the compensator) over the whole band up to Nyquist, its
    stability by the Nyquist criterion, every crossing and peak refined on the design."""
    if key == "current":  # (C - F) * P_drive, the pivot on its pre-sliding slope
        P = sampled_plant(cfg, "drive", compensated=False)
        resp = lambda x: (controller_response(cfg, x) - compensator_response(cfg, x)) * P(x)  # noqa: E731
    else:
        P = sampled_plant(cfg, *DESIGN_MODELS[key])
        resp = lambda x: controller_response(cfg, x) * P(x)  # noqa: E731
    f = full_band(cfg)
    return margins(f, resp(f), dense=True, response=resp, nyquist_hz=f[-1])


def check_designs_stable(cfg: Config, comps) -> dict:
    """The margins of the designs the runs of ``comps`` are set against; raises
    :class:`UnstableLoop` (one line) when one of them is unstable: its margins mean nothing and
    running it would drive the actuator away."""
    keys = ["nominal"] + (["drive"] if True in comps else []) + (["pivot"] if False in comps else [])
    out = {k: design_margins(cfg, k) for k in keys}
    for k, m in out.items():
        if m["stable"] is False:
            raise UnstableLoop(f"loop: the designed closed loop ({NAMES[k]}) of controller kind "
                               f"'{cfg.controller.kind}' is unstable ({m['unstable_poles']} closed-loop poles outside "
                               "the unit circle): no margins to report, nothing run")  # fmt: skip
    return out


def agreement(f_hz, L, S, design: LoopDesign, f_lo: float, f_hi: float) -> dict:
    """How far a measured loop ``L`` and sensitivity ``S`` (complex, at ``f_hz``) lie
    from the design's in ``[f_lo, f_hi]`` (Hz): the largest relative error
    ``|H/H_design - 1|`` of each, and the largest magnitude (dB) and phase (deg)
    differences of ``L``.  The design is read off its grid in log-magnitude and phase."""
    f = np.asarray(f_hz, dtype=float)
    m = (f >= f_lo) & (f <= f_hi)
    if not m.any():
        return {"band_hz": [f_lo, f_hi], "points": 0}
    f, L, S = f[m], np.asarray(L)[m], np.asarray(S)[m]
    lf = np.log(design.f_hz)
    Ld = np.exp(np.interp(np.log(f), lf, np.log(np.abs(design.L))) + 1j * np.interp(np.log(f), lf, np.unwrap(np.angle(design.L))))
    Sd = 1.0 / (1.0 + Ld)
    return {
        "band_hz": [f_lo, f_hi],
        "points": int(m.sum()),
        "L_rel_err_max": float(np.max(np.abs(L / Ld - 1.0))),
        "S_rel_err_max": float(np.max(np.abs(S / Sd - 1.0))),
        "L_mag_db_max": float(np.max(np.abs(20 * np.log10(np.abs(L / Ld))))),
        "L_phase_deg_max": float(np.max(np.abs(np.degrees(np.angle(L / Ld))))),
    }


def measure_all(cfg: Config, s: LoopSettings, comps, make_driver: Callable | None = None) -> list[LoopMeasurement]:
    """Every run: for each compensator setting in ``comps`` (bools) and level of ``s``
    (progress through :mod:`servo.io.progress`, silent unless the command line asked)."""
    runs = []
    todo = [(comp, level) for comp in comps for level in s.levels]
    for comp, level in progress.each(todo, "stepped-sine runs", lambda cl: f"compensator {'on' if cl[0] else 'off'}, "
                                     f"{cl[1] * 1e3:g} mA", "runs"):  # fmt: skip
        runs.append(measure(cfg, s, level, comp, make_driver))
    return runs


def analyse(cfg: Config, s: LoopSettings, runs: list[LoopMeasurement], checked: dict | None = None) -> tuple[dict, dict]:
    """Designs (on the file grid) and the summary's analysis of ``runs`` (``checked``: the
    designs' margins, :func:`check_designs_stable`, when the caller has them)."""
    comps = tuple(sorted({r.compensation for r in runs}, reverse=True))
    dense = designs(cfg, s.f_min, s.f_max, MARGIN_POINTS, comps)
    des_margins = {k: m for k, m in (checked or check_designs_stable(cfg, comps)).items() if k in dense}

    def band(key):
        fc = des_margins[key]["crossover_hz"]
        return (max(fc / 2.0, s.f_min), min(fc * 2.0, s.f_max)) if fc else (s.f_min, s.f_max)

    lo, hi = band("nominal")
    out_runs, warns = [], []
    for r in runs:
        ref = "drive" if r.compensation else "pivot"
        cur = current_loop_design(cfg, np.geomspace(s.f_min, s.f_max, MARGIN_POINTS), r.compensation)
        entry = {
            "label": r.label,
            "compensation": r.compensation,
            "level_A": r.level,
            "margins": margins(r.f, r.value("L")),
            "vs_nominal": agreement(r.f, r.value("L"), r.value("S"), dense["nominal"], lo, hi),
            f"vs_{ref}": agreement(r.f, r.value("L"), r.value("S"), dense[ref], *band(ref)),
            "at_current": {
                "margins": margins(r.f, r.value("L_u")),
                "design_margins": design_margins(cfg, "current") if r.compensation else des_margins["pivot"],
                "vs_design": agreement(r.f, r.value("L_u"), r.value("S_u"), cur, lo, hi),
            },
            "clipped_ticks": r.clipped,
            "fast_regime_ticks": r.fast_ticks,
            "window_ticks": r.window_ticks,
            "min_coherence": float(np.min(r.response("L").coherence)),
            "median_rel_std_L": float(np.median(r.response("L").rel_std)),
        }
        entry["margin_uncertainty"] = uncertainty(entry["margins"], r.f, r.value("L"), r.response("L").rel_std)
        warns += warnings_for(f"measured, {r.label}", entry["margins"], entry["margin_uncertainty"])
        if r.link is not None:
            entry["link"] = r.link
        out_runs.append(entry)
    shift = []
    for level in s.levels:
        on = [e for e in out_runs if e["compensation"] and e["level_A"] == level]
        off = [e for e in out_runs if not e["compensation"] and e["level_A"] == level]
        if on and off and on[0]["margins"]["crossover_hz"] and off[0]["margins"]["crossover_hz"]:
            a, b = on[0]["margins"]["crossover_hz"], off[0]["margins"]["crossover_hz"]
            shift.append({"level_A": level, "crossover_on_hz": a, "crossover_off_hz": b, "shift_hz": b - a,
                          "shift_rel": (b - a) / a})  # fmt: skip
    names = NAMES
    summary = {
        "designs": {names[k]: m for k, m in des_margins.items()},
        "agreement_band_hz": [lo, hi],  # vs_nominal, at_current; vs_drive/vs_pivot: half to twice that design's crossover
        "runs": out_runs,
        "crossover_shift": shift,
        "warnings": warns,
    }
    file_designs = {k: LoopDesign(d.f_hz[:: MARGIN_POINTS // FILE_POINTS], d.C[:: MARGIN_POINTS // FILE_POINTS],
                                  d.P[:: MARGIN_POINTS // FILE_POINTS], names[k]) for k, d in dense.items()}  # fmt: skip
    return file_designs, summary


def run_loop(cfg: Config, out: Path, s: LoopSettings, compensator: str | None = None, make_driver: Callable | None = None,
             where: str = "the simulated drive", provenance: dict | None = None, checked: dict | None = None) -> dict:  # fmt: skip
    """Every run, the analysis, then the files of the module docstring into ``out``;
    returns the summary (``provenance`` recorded as given).  ``compensator``: ``on``,
    ``off``, ``both``, or None: what ``[compensator] enabled`` says
    (:func:`~servo.runtime.controller.compensation_runs`).  The designs are checked
    stable before anything runs (``checked``: the caller did, :func:`check_designs_stable`)."""
    s = s.check(cfg)
    comps = compensation_runs(cfg, compensator)
    checked = checked or check_designs_stable(cfg, comps)
    runs = measure_all(cfg, s, comps, make_driver)
    file_designs, summary = analyse(cfg, s, runs, checked)
    responses: dict[str, FrequencyResponse] = {}
    for r in runs:
        for name in RESPONSES:
            responses[f"{name}, {r.label}"] = r.response(name)
    for d in file_designs.values():
        for name, unit in (("L", "-"), ("S", "-"), ("T", "-")):
            responses[f"design {name}, {d.model}"] = FrequencyResponse(
                d.f_hz, getattr(d, name), unit=unit, meta={"method": "design", "model": d.model})
    by_label = {e["label"]: e["margins"] for e in summary["runs"]}
    by_label.update({f"design: {k}": m for k, m in summary["designs"].items()})
    title = f"Open loop L on {where}, broken at the controller output"
    out.mkdir(parents=True, exist_ok=True)
    save_npz(out / "frd.npz", responses)
    save_csv(out / "loop.csv", responses)
    plot_loop(runs, list(file_designs.values()), by_label, out / "loop.png", title)
    plot_sensitivity(runs, list(file_designs.values()), out / "sensitivity.png")
    summary = {
        "where": where,
        "settings": {**s.__dict__, "levels": list(s.levels), "compensator": {(True,): "on", (False,): "off"}.get(comps, "both")},
        "sign_conventions": {k: v[3] for k, v in RESPONSES.items()},
        **summary,
    }
    summary["provenance"] = or_default(provenance, cfg)
    summary["files"] = sorted(["frd.npz", "loop.csv", "loop.png", "report.html", "sensitivity.png", "summary.json"])
    write_json(out / "summary.json", summary)
    page(summary, out).write(out)
    return summary


def _fmt_margins(m: dict) -> str:
    """Crossover, phase margin, the binding gain margin (side), max|S| (frequency)."""
    if m["stable"] is False:
        return "unstable: no margins"
    fc = "     -   " if m["crossover_hz"] is None else f"{m['crossover_hz']:7.1f} Hz"
    pm = "    -    " if m["phase_margin_deg"] is None else f"{m['phase_margin_deg']:5.1f} deg"
    gm = ("none in band" if m["gain_margin_db"] is None
          else f"{m['gain_margin_db']:+6.1f} dB {m['gain_margin_side']} at {m['gain_margin_hz']:.0f} Hz")  # fmt: skip
    return f"{fc}   {pm}   {gm:<26}  {m['max_S_db']:5.1f} dB at {m['max_S_hz']:.0f} Hz"


def format_summary(summary: dict, out: Path) -> str:
    """The human summary ``servo loop`` prints."""
    st = summary["settings"]
    lines = [f"servo loop: stepped sine on {summary['where']}, {st['n_freq']} frequencies {st['f_min']:g}-{st['f_max']:g} Hz, "
             f"{st['periods']} periods each; L broken at the controller output (L = -U_pi/U_n)"]  # fmt: skip
    lines.append(f"  {'':50} crossover   phase margin  gain margin (binding)       max|S|")
    for name, m in summary["designs"].items():
        lines.append(f"  {'design, ' + name:50} {_fmt_margins(m)}")
    lo, hi = summary["agreement_band_hz"]
    for e in summary["runs"]:
        lines.append(f"  {'measured, ' + e['label']:50} {_fmt_margins(e['margins'])}")
        ref = "vs_drive" if e["compensation"] else "vs_pivot"
        a, n = e[ref], e["vs_nominal"]
        if n.get("points"):
            lines.append(f"      vs 1/(J s^2) design, {lo:.0f}-{hi:.0f} Hz: |L| within {n['L_mag_db_max']:.2f} dB, phase within "
                         f"{n['L_phase_deg_max']:.1f} deg ({100 * n['L_rel_err_max']:.1f} %); S within {100 * n['S_rel_err_max']:.1f} %")  # fmt: skip
        if a.get("points"):
            lo2, hi2 = a["band_hz"]
            lines.append(f"      vs {'compensated drive' if e['compensation'] else 'pivot small-signal'} model, {lo2:.0f}-{hi2:.0f} Hz: "
                         f"|L| within {a['L_mag_db_max']:.2f} dB, phase within {a['L_phase_deg_max']:.1f} deg; "
                         f"S within {100 * a['S_rel_err_max']:.1f} %")  # fmt: skip
        if e["clipped_ticks"] or e["fast_regime_ticks"]:
            lines.append(f"      not small-signal: {e['clipped_ticks']} clipped ticks, {e['fast_regime_ticks']} ticks in the "
                         f"compensator's FAST regime of {e['window_ticks']}")  # fmt: skip
    for sh in summary["crossover_shift"]:
        lines.append(f"  without the compensator at {sh['level_A'] * 1e3:g} mA the crossover moves from {sh['crossover_on_hz']:.1f} "
                     f"to {sh['crossover_off_hz']:.1f} Hz ({100 * sh['shift_rel']:+.0f} %)")  # fmt: skip
    for e in summary["runs"]:
        if e["compensation"]:
            m = e["at_current"]["margins"]
            fc = "none" if m["crossover_hz"] is None else f"{m['crossover_hz']:.1f} Hz, phase margin {m['phase_margin_deg']:.1f} deg"
            lines.append(f"  at the current (L_u = -U_fb/U, compensator as feedback), {e['label']}: crossover {fc}")
    links = [e["link"] for e in summary["runs"] if e.get("link")]
    if links:
        h = [lk.get("host", {}) for lk in links]
        lines.append(f"  link: {sum(x.get('rx_frames', 0) for x in h)} frames received, "
                     f"{sum(x.get('crc_errors', 0) + x.get('seq_dropped', 0) for x in h)} host-side errors")  # fmt: skip
    for w in summary.get("warnings", []):
        lines.append(f"  warning: {w}")
    lines.append(f"  wrote {out}/: " + ", ".join(summary["files"]))
    return "\n".join(lines)


__all__ = ["agreement", "analyse", "check_designs_stable", "design_margins", "designs", "format_summary", "full_band",
           "measure_all", "run_loop"]
