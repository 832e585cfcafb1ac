"""The outputs of a diagnosis: ``report.json`` (schema in ``docs/diagnosis.md``), the
final model as a drive config, and the human summary (one line per finding)."""
from __future__ import annotations

import math
from dataclasses import asdict
from pathlib import Path

import numpy as np

from servo.config import from_dict, to_toml
from servo.diagnose.band import band_hz
from servo.diagnose.fit import Fit
from servo.diagnose.job import Diagnosis, Finding
from servo.diagnose import noise as noise_mod
from servo.diagnose.model import GATE
from servo.diagnose.scope import Unscoped
from servo.diagnose.terms import VOCABULARY
from servo.errors import ConfigError
from servo.physics import EFFECTS
from servo.io.atomic import atomic_write, write_json
from servo.io.units import substitute

SCHEMA = 1


def _num(v):
    if isinstance(v, (np.floating, float)):
        return float(v) if math.isfinite(v) else None
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.ndarray):
        return [_num(x) for x in v.tolist()]
    if isinstance(v, dict):
        return {k: _num(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_num(x) for x in v]
    return v


def _units(physics: str, params: dict, fu: str, pu: str = "m") -> dict:
    """The units of a term's parameters with forces in ``fu`` and positions in ``pu``
    (rad for a rotary axis: :func:`servo.io.units.substitute` of the term's template)."""
    return {k: "s" if k == GATE else substitute(VOCABULARY[physics].unit(k, "F"), fu, pu, "F") for k in params}


def fit_terms(fit: Fit, fu: str, frf_terms=(), pu: str = "m") -> list:
    """The terms of ``fit``; those of ``frf_terms`` (modes the frequency-domain path
    fitted, their gain held in the rows) are marked ``fitted_on: frequency response``."""
    out = []
    for i, t in enumerate(fit.model.terms):
        p = fit.term_params(i)
        d = {"physics": t.physics, "params": p, "std": fit.term_std(i), "units": _units(t.physics, p, fu, pu),
             "fixed": not t.free and t not in frf_terms}  # fmt: skip
        if t in frf_terms:
            d["fitted_on"] = "frequency response"
        out.append(d)
    return out


def _evidence(f: Finding) -> dict:
    if f.frf is not None:
        return {k: v for k, v in f.frf.items() if k != "reason"}
    if f.breakaway is not None:
        return {k: v for k, v in f.breakaway.items() if k != "reason"}
    if f.sensor and f.quant_heldout is not None:  # named on the default rows
        return {"test": "lattice, held-out lattice + share of the held-out residual", "fraction_on_lattice":
                f.lattice.fraction, "lattice_p": f.lattice.p, "output_t": f.quant_test[0], "output_p": f.quant_test[1],
                **f.quant_heldout, "level": f.level}  # fmt: skip
    if f.sensor:
        return {"test": "lattice + output improvement", "fraction_on_lattice": f.lattice.fraction,
                "lattice_p": f.lattice.p, "output_t": f.quant_test[0], "output_p": f.quant_test[1], "level": f.level}  # fmt: skip
    s = f.score
    out = {
        "test": "blocked CV, sign-flip test on gain blocks + BIC", "t": s.t, "p": s.p, "level": f.level,
        "delta_ic": s.delta_ic, "delta_ic_refined": s.refined_ic, "cv_improvement_pct": s.improvement_pct,
        "blocks_improved": f"{int(np.sum(s.S1 < s.S0))}/{s.S0.size}", "cv_sse_before": s.S0, "cv_sse_after": s.S1,
    }  # fmt: skip
    if f.frf_path is not None:  # the rows named another input-path term; the frequency response chose this one
        out["frequency_response"] = f.frf_path
    return out


def finding_dict(f: Finding, fu: str, pu: str = "m") -> dict:
    """A finding's entry; ``heldout`` its sign-flip test on the test part against the
    model without it (``p``: its chance of being spurious; ``level`` the one a finding
    beside the first had to pass, None for the first), None where the rows' proof does
    not make it (a sensor's lattice, a breakaway, a mode of the frequency response)."""
    return {
        "physics": f.physics, "params": f.params, "std": f.std, "units": _units(f.physics, f.params, fu, pu),
        "where": f.where, "evidence": _evidence(f), "error_before": f.before, "error_after": f.after,
        "heldout": f.heldout, "note": VOCABULARY[f.physics].judging.note(f.params),
    }  # fmt: skip


def drive_section(fit: Fit, extra: dict | None = None) -> tuple[dict | None, str]:
    """The final model as a ``[drive]`` section of a servo config (A, m), validated by
    :func:`servo.config.from_dict`; ``(None, why)`` when it is not a valid drive.  ``extra``:
    fields of findings that are not terms of the rows' fit (a sensor's lattice, a
    breakaway level)."""
    d = {**fit.drive(), **(extra or {})}
    d = {k: (float(v) if not isinstance(v, list) else [float(x) for x in v]) for k, v in d.items()}
    try:
        from_dict({"drive": d})
    except ConfigError as exc:
        return None, str(exc)
    return d, ""


def partial_note(fit: Fit) -> str:
    """What the final model's terms gated in time mean for ``final_model.toml`` ("" when
    it has none): the drive has no switch, so it holds them throughout."""
    on = [(t.physics, t.params[GATE]) for t in fit.model.terms if GATE in t.params]
    if not on:
        return ""
    what = ", ".join(f"{p} from t = {t0:.4g} s" for p, t0 in on)
    return (f"{what} (absent before): final_model.toml holds the term throughout (the simulated drive has no "
            "switch); it describes the recording from that time on, the part the proof covers")  # fmt: skip


#: the held-out errors of a report, None where no model was fitted
_NO_ERROR = {"train_force_rel_pct": None, "test_force_rel_pct": None, "test_output_nrmse": None}


def unscoped_report(D: Unscoped, files: list | None = None) -> dict:
    """``report.json`` of a recording outside the domain (:mod:`servo.diagnose.scope`):
    the verdict ``out_of_scope`` and its reason, the recording and the settings, every
    section of a diagnosis's report present and empty (no rows, no model)."""
    rec, opt = D.rec, D.opt
    report = {
        "schema": SCHEMA, "verdict": D.verdict["verdict"], "verdict_text": D.reason,
        "checks": {"baseline": None, "final_model": None},
        "recording": {"source": rec.source, "samples": rec.n, "sample_rate_hz": rec.sample_rate_hz,
                      "duration_s": float(rec.t[-1] - rec.t[0]), "force_unit": opt.force_unit,
                      "position_unit": opt.position_unit, "position_max_m": float(np.max(np.abs(rec.x))),
                      "position_span_m": float(np.ptp(rec.x)), "input_span": float(np.ptp(rec.u))},
        "settings": {"baseline": None if opt.model else (opt.baseline or "J,B,Fc,K,h0"), "model": opt.model,
                     "test_fraction": opt.test_fraction, "blocks": opt.blocks, "alpha": opt.alpha,
                     "horizon_s": opt.horizon_s, "robust": asdict(opt.settings) if opt.settings is not None else None},
        "rows": None,
        "baseline": {"source": "model file" if opt.model else "terms", "terms": [], "error": dict(_NO_ERROR)},
        "findings": [],
        "final_model": {"terms": [], "drive": None, "drive_note": "no model was fitted: the recording is out of scope",
                        "partial": "", "error": dict(_NO_ERROR)},
        "unconfirmed": [], "frf": None, "not_testable": {}, "implausible": {}, "candidates": [], "locate": None,
        "simulation_note": "", "files": sorted(files or []),
    }  # fmt: skip
    return _num(report)


def build_report(D: Diagnosis | Unscoped, files: list | None = None) -> dict:
    if isinstance(D, Unscoped):
        return unscoped_report(D, files)
    fu, pu = D.opt.force_unit, D.opt.position_unit
    sig = D.sig
    rec = D.rec
    brk = [f for f in D.findings if f.breakaway is not None]  # a breakaway found at rest (not a column)
    extra = {}
    for f in D.findings:  # the sensor's finding: its fields in the drive
        if f.sensor:
            extra.update(EFFECTS[f.physics].drive_map.to_drive({f.physics: f.params}, D.final_fit))
    if brk:
        extra.update(Fs=brk[0].params["Fs"], stribeck_velocity=brk[0].params["stribeck_velocity"])
    drive, why = drive_section(D.final_fit, extra)
    rounds = []
    for r in D.rounds:
        rounds.append([{"physics": s.physics, "t": s.t, "p": s.p, "level": r["level"], "delta_ic": s.delta_ic,
                        "delta_ic_refined": s.refined_ic, "cv_improvement_pct": s.improvement_pct,
                        "passed": s.passes(r["level"]),
                        "gated_in_time": bool(r.get("gated"))}
                       for s in sorted(r["scores"], key=lambda s: s.p)])  # fmt: skip
    loc = D.locate
    V = D.verdict
    report = {
        "schema": SCHEMA,
        "verdict": V["verdict"],
        "verdict_text": V["text"],
        "checks": {"baseline": V["baseline_checks"], "final_model": V["final_checks"]},
        "recording": {"source": rec.source, "samples": rec.n, "sample_rate_hz": rec.sample_rate_hz,
                      "duration_s": float(rec.t[-1] - rec.t[0]), "force_unit": fu, "position_unit": pu,
                      "speed_max_m_s": float(np.max(np.abs(sig.vf))), "position_max_m": float(np.max(np.abs(sig.x)))},
        "settings": {"baseline": None if D.opt.model else (D.opt.baseline or "J,B,Fc,K,h0"), "model": D.opt.model,
                     "test_fraction": D.opt.test_fraction, "blocks": D.opt.blocks, "alpha": D.opt.alpha,
                     "horizon_s": D.errors["horizon_s"], "robust": asdict(D.sig.settings)},
        "rows": {"total": sig.m, "row_dt_s": sig.row_dt, "train": int(D.design.train_rows.sum()),
                 "test": int((~D.design.train_rows).sum()), "usable_fraction": float(sig.valid.mean()),
                 "direction_threshold_m_s": sig.v_threshold, "position_noise_m": sig.noise_x, "tau_rows": loc["tau"],
                 "decimate": int(sig.settings.decimate), "band_hz": [0.0, band_hz(sig.settings, 1.0 / sig.dt)],
                 "band_note": D.band_note, "noise": noise_mod.describe(sig.noise, sig.noise_x, sig.noise_v)},
        "baseline": {"source": "model file" if D.opt.model else "terms", "terms": fit_terms(D.baseline_fit, fu, pu=pu),
                     "error": {"train_force_rel_pct": D.errors["train_force_rel_pct"]["before"],
                               "test_force_rel_pct": D.errors["test_force_rel_pct"]["before"],
                               "test_output_nrmse": D.errors["test_output_nrmse"]["before"]}},
        "findings": [finding_dict(f, fu, pu) for f in D.findings],
        "final_model": {"terms": fit_terms(D.final_fit, fu, D.frf_terms, pu) + [
                            {"physics": f.physics, "params": f.params, "std": {},
                             "units": {k: substitute(u, fu, pu, "F") for k, u in VOCABULARY[f.physics].units.items()},
                             "fixed": False} for f in D.findings if f.sensor] + [
                            {"physics": f.physics, "params": f.params, "std": f.std,
                             "units": _units(f.physics, f.params, fu, pu), "fixed": False, "fitted_on": "intervals at rest"}
                            for f in brk],
                        "drive": drive, "drive_note": why, "partial": partial_note(D.final_fit),
                        "error": {"train_force_rel_pct": D.errors["train_force_rel_pct"]["after"],
                                  "test_force_rel_pct": D.errors["test_force_rel_pct"]["after"],
                                  "test_output_nrmse": D.errors["test_output_nrmse"]["after"]}},
        "unconfirmed": [{**finding_dict(f, fu, pu), "reason": (f.frf or f.breakaway or {}).get("reason") or f.why or
                         "did not lower the held-out error of the test part",
                         "test_error_before": a, "test_error_after": b} for f, a, b in D.unconfirmed],
        "frf": D.frf.summary() if D.frf is not None else None,
        "not_testable": D.not_testable,
        "implausible": D.implausible,
        "candidates": rounds,
        "locate": {
            "tau_rows": loc["tau"],
            "time": {k: loc["time"][k] for k in ("false_alarm", "level_per_window", "noise_rms", "flagged", "windows")},
            "state": loc["state"],
            "spectrum": {k: loc["spectrum"][k] for k in ("false_alarm", "threshold_ratio", "flagged_hz")},
            "coherence": {k: loc["coherence"][k] for k in ("false_alarm", "threshold", "flagged_hz", "closed_loop_caveat")},
            "xcorr": {k: loc["xcorr"][k] for k in ("false_alarm", "bound", "flagged_lag_s", "closed_loop_caveat")},
        },
        "simulation_note": D.simulate_note,
        "files": sorted(files or []),
    }  # fmt: skip
    return _num(report)


def write_report(report: dict, out: Path) -> None:
    write_json(out / "report.json", report)


def write_drive_toml(report: dict, out: Path) -> bool:
    """``final_model.toml``: the final model as a servo config (``[drive]``), usable as
    ``servo run --config`` or ``servo diagnose --model``; False if not a valid drive."""
    d = report["final_model"]["drive"]
    if d is None:
        return False
    full = to_toml(from_dict({"drive": d}), comments=False)
    section = full[full.index("[drive]") :].split("\n\n")[0]
    text = "# servo diagnose: the final model as the simulated drive's [drive] section\n" + section + "\n"
    atomic_write(out / "final_model.toml", lambda f: Path(f).write_text(text))
    return True


def _fmt_params(params: dict, units: dict, std: dict | None = None, digits: int = 4) -> str:
    parts = []
    for k, v in params.items():
        if k in ("a_sin", "a_cos") or v is None:
            continue
        s = f"{k} {v:.{digits}g}"
        if std and std.get(k) is not None and math.isfinite(std[k]) and std[k] > 0:
            s += f" +- {std[k]:.2g}"
        u = units.get(k, "-")
        parts.append(s + ("" if u == "-" else f" {u}"))
    return ", ".join(parts)


def _err(e: dict) -> str:
    o = e.get("output_nrmse")
    return f"{e['force_rel_pct']:.3g} %" + (f" / NRMSE {o:.3g}" if o is not None else "")


def _change(f: dict) -> str:
    b, a = f["error_before"], f["error_after"]
    if b.get("frf_sse") is not None:
        o = (f"; output NRMSE {b['output_nrmse']:.3g} -> {a['output_nrmse']:.3g}"
             if b.get("output_nrmse") is not None and a.get("output_nrmse") is not None else "")  # fmt: skip
        return f"held-out frequency-response departure (sum of z^2) {b['frf_sse']:.4g} -> {a['frf_sse']:.4g}{o}"
    if a.get("rows_differ") is False and "share_of_heldout_rms" in f.get("params", {}):  # a quantum on the default rows
        return f"{_err(b)}, unchanged (the rows stay; named for its share of the held-out residual)"
    if a.get("rows_differ"):
        return (f"output NRMSE {b['output_nrmse']:.3g} -> {a['output_nrmse']:.3g} (force error {b['force_rel_pct']:.3g} % "
                f"-> {a['force_rel_pct']:.3g} %, on the narrower rows)")  # fmt: skip
    return f"{_err(b)} -> {_err(a)}"


def _spurious(f: dict) -> str:
    """A finding's chance of being spurious on the held-out part, for its summary line."""
    h = f.get("heldout")
    if not h or not h.get("blocks"):
        return ""
    lv = f", level {100 * h['level']:.2g} %" if h.get("level") is not None else ""
    return f"; chance of being spurious {100 * h['p']:.2g} % (held-out sign-flip test, {h['blocks']} blocks{lv})"


def format_summary(report: dict, out: Path) -> str:
    """The human summary: recording, baseline, one line per finding, final model."""
    rc, rows, b, fm = report["recording"], report["rows"], report["baseline"], report["final_model"]
    if rows is None:  # out of scope before any row was made (:mod:`servo.diagnose.scope`)
        return "\n".join([f"verdict: {report['verdict']}: {report['verdict_text']}",
                          f"servo diagnose: {rc['source']} ({rc['samples']} samples at {rc['sample_rate_hz']:.6g} Hz, "
                          f"{rc['duration_s']:.3g} s)", "  no rows and no model: nothing was fitted or named",
                          f"  wrote {out}/: " + ", ".join(report["files"])])  # fmt: skip
    lines = [
        f"verdict: {report['verdict']}: {report['verdict_text']}",
        f"servo diagnose: {rc['source']} ({rc['samples']} samples at {rc['sample_rate_hz']:.6g} Hz, {rc['duration_s']:.3g} s"
        + (f"; positions in {rc['position_unit']}, forces in {rc['force_unit']})" if rc.get("position_unit", "m") != "m" else ")"),
        f"  rows: {rows['total']} ({rows['train']} training, {rows['test']} held out for the proof), "
        f"{100 * rows['usable_fraction']:.0f} % usable (direction known)",
        f"  band: every force-balance test covers 0-{rows['band_hz'][1]:.4g} Hz ({rows['band_note']})",
    ]
    if rows.get("noise"):
        lines.append(f"  sensor noise: {noise_mod.describe_text(rows['noise'])}")
    fr = report.get("frf")
    if fr and fr["band_hz"]:
        how = "P_rx/P_ru, the recording's r as instrument" if fr.get("method") == "instrumental" else "H1"
        what = (f"{how}, {fr['nperseg']}-sample Welch segments in which the arm slides, {fr['train']['segments']} "
                f"training and {fr['test']['segments']} held out" + (f"; {fr['note']}" if fr["note"] else "")
                if fr["ran"] else fr["note"])  # fmt: skip
        lines.append(f"  frequency response: at full rate, covers {fr['band_hz'][0]:.4g}-"
                     f"{fr['band_hz'][1]:.4g} Hz ({what})")  # fmt: skip
    elif fr:
        lines.append(f"  frequency response: not compared ({fr['note']})")
    s = report["settings"]
    what = f"terms {s['baseline']}" if s["baseline"] else f"model file {s['model']}"
    be = b["error"]
    lines.append(f"  baseline ({what}): held-out force error {be['test_force_rel_pct']:.3g} %"
                 + (f", output NRMSE {be['test_output_nrmse']:.3g}" if be["test_output_nrmse"] is not None else ""))  # fmt: skip
    if report["findings"]:
        lines.append(f"  findings (family-wise false-alarm level {100 * s['alpha']:.0f} %), held-out error "
                     "(force / simulated output) before -> after:")  # fmt: skip
        for i, f in enumerate(report["findings"], 1):
            note = f" [{f['note']}]" if f.get("note") else ""
            lines.append(f"    {i}. {f['physics']}: {_fmt_params(f['params'], f['units'], f['std'])}{note}; "
                         f"where: {f['where'].get('text', '')}; {_change(f)}{_spurious(f)}")  # fmt: skip
    elif report["verdict"] == "consistent":
        lines.append(f"  no finding: the baseline explains these data to their noise "
                     f"(family-wise false-alarm level {100 * s['alpha']:.0f} %)")  # fmt: skip
    else:
        lines.append(f"  no finding: no vocabulary term lowers the held-out error enough to pass the test "
                     f"(family-wise false-alarm level {100 * s['alpha']:.0f} %); see the verdict")  # fmt: skip
    for u in report["unconfirmed"]:
        if u["test_error_before"].get("frf_sse") is not None:
            lines.append(f"  dropped: {u['physics']} (frequency response): "
                         f"{_fmt_params(u['params'], u['units'], u['std'])} ({u['reason']}; held-out departure "
                         f"{u['test_error_before']['frf_sse']:.4g} -> {u['test_error_after']['frf_sse']:.4g})")  # fmt: skip
            continue
        lines.append(f"  not confirmed on the held-out part (dropped): {u['physics']}: "
                     f"{_fmt_params(u['params'], u['units'], u['std'])} ({_err(u['test_error_before'])} -> "
                     f"{_err(u['test_error_after'])}; {u['reason']})")  # fmt: skip
    for name, why in report["implausible"].items():
        lines.append(f"  not named: {name}: {why}")
    fe = fm["error"]
    lines.append(f"  final model: held-out force error {be['test_force_rel_pct']:.3g} % -> {fe['test_force_rel_pct']:.3g} %"
                 + (f", output NRMSE {be['test_output_nrmse']:.3g} -> {fe['test_output_nrmse']:.3g}"
                    if fe["test_output_nrmse"] is not None else f" ({report['simulation_note']})"))  # fmt: skip
    where = "as written to final_model.toml" if fm["drive"] is not None else f"not a drive config: {fm['drive_note']}"
    if fm.get("partial"):
        where += f"; {fm['partial']}"
    lines.append(f"  final model ({where}; the findings' parameters above are as fitted when each was added):")
    for t in fm["terms"]:
        lines.append(f"    {t['physics']}: {_fmt_params(t['params'], t['units'], t['std'], digits=6)}"
                     + (" (fixed)" if t.get("fixed") else "")
                     + (f" (fitted on the {t['fitted_on']})" if t.get("fitted_on") else ""))  # fmt: skip
    lines.append(f"  wrote {out}/: " + ", ".join(report["files"]))
    return "\n".join(lines)


__all__ = ["build_report", "unscoped_report", "drive_section", "format_summary", "partial_note", "write_drive_toml", "write_report"]
