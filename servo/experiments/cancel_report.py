"""The ``servo demo cancel`` job: the chain of :mod:`servo.experiments.cancel` for every
case, then its table (``TABLE.md``, ``summary.json``) and figures into one folder.

Files: ``<case>/report.json`` (the diagnosis the compensators were written from),
``<case>/drive.toml`` (the drive, whose exact model is the third compensator),
``<case>/bode_before.png``, ``<case>/bode_after.png`` and ``<case>/bode_exact.png`` (Fig. 8
with each compensator),
``TABLE.md`` (one table per case, before and after), ``summary.json`` (every number).
"""
from __future__ import annotations

from pathlib import Path

from servo.config import Config
from servo.experiments.bode_plots import plot_bode
from servo.experiments.cancel import CASES, CaseResult, ChainSettings, run_case
from servo.io.atomic import atomic_write, write_json

BEFORE = {"paper": "paper (eq. 9 of the diagnosis)", "nominal": "paper (nominal, not retuned)"}


def case_summary(r: CaseResult) -> dict:
    return {"case": r.case.name, "physics": r.case.physics, "what": r.case.what, "drive": r.case.drive,
            "measured_at_m": r.case.measure_at, "before_is": r.case.before, "found": r.found, "findings": r.findings,
            "diagnosed": r.diagnosed, "note": r.note, "compensators": r.compensators, "before": r.before,
            "after": r.after, "exact": r.exact}  # fmt: skip


def _steps(run: dict) -> list[str]:
    out = []
    for st in run["steps"]:
        settle = "never" if st["settling_ms"] is None else f"{st['settling_ms']:.1f} ms"
        out.append(f"{st['overshoot_pct']:.1f} % / {settle}")
    return out


def case_table(c: dict) -> list[str]:
    """The Markdown table of one case (``c``: :func:`case_summary`): before, after and,
    when measured, the drive's exact model."""
    if c["before"] is None:
        return [f"### {c['case']}", "", f"Drive: the paper's drive plus {c['what']}. Diagnosis: findings "
                f"{', '.join(c['findings']) or 'none'}; {c['note']}.", ""]  # fmt: skip
    cols = [c["before"], c["after"]] + ([c["exact"]] if c.get("exact") else [])
    head = [BEFORE[c["before_is"]], "augmented"] + (["exact model (ceiling)"] if c.get("exact") else [])
    bb = cols[0]["bode"]
    found = "found" if c["found"] else "**not found**"
    row = lambda name, f: f"| {name} | " + " | ".join(f(m) for m in cols) + " |"  # noqa: E731
    L = [f"### {c['case']}", "", f"Drive: the paper's drive plus {c['what']}. Diagnosis: {c['physics']} {found} "
         f"(findings: {', '.join(c['findings']) or 'none'}"
         + (f"; {', '.join(f'{k} {v:.4g}' for k, v in c['diagnosed'].items())}" if c["diagnosed"] else "") + ")."
         + (f" {c['note']}." if c["note"] else ""), "",
         "| measurement | " + " | ".join(head) + " |", "|---|" + "---|" * len(cols),
         row(f"Fig. 8 level spread, max / RMS (dB, {bb['band_hz'][0]:.0f}-{bb['band_hz'][1]:.0f} Hz)",
             lambda m: f"{m['bode']['spread_db_max']:.2f} / {m['bode']['spread_db_rms']:.2f}"),
         row("Fig. 8 slope per level (dB/decade)", lambda m: f"{m['bode']['slope_min']:.1f} .. {m['bode']['slope_max']:.1f}"),
         row("Fig. 8 phase (deg)", lambda m: f"{m['bode']['phase_deg_min']:.0f} .. {m['bode']['phase_deg_max']:.0f}"),
         row("gain against 1/(J w^2) (dB, worst level)", lambda m: f"{m['bode']['gain_error_db']:+.2f}")]  # fmt: skip
    for i in range(len(cols[0]["run"]["steps"])):
        L.append(row(f"servo run step {i + 1} overshoot / settling", lambda m: _steps(m["run"])[i]))
    for seg in cols[0]["run"]["error_rms_by_segment_m"]:
        if not seg.startswith("step"):
            L.append(row(f"servo run error RMS, {seg} (nm)", lambda m: f"{m['run']['error_rms_by_segment_m'][seg] * 1e9:.1f}"))
    L.append(row("servo run error RMS, whole run (nm)", lambda m: f"{m['run']['error_rms_m'] * 1e9:.1f}"))
    L.append(row("tracking error RMS, held-out long stroke (nm)", lambda m: f"{m['tracking']['error_rms_m'] * 1e9:.1f}"))
    if "excess_rms_m" in cols[0]["tracking"]:
        L.append(row("its difference from the exact model's, RMS (nm)",
                     lambda m: f"{m['tracking']['excess_rms_m'] * 1e9:.1f}"))  # fmt: skip
    stuck = [f"{lv * 1e3:g} mA" for lv, g in zip(summary_levels(c), bb["gain_error_db_per_level"]) if g < -20]
    if stuck:
        L += ["", f"At {', '.join(stuck)} the arm does not break away (the magnitude lies more than 20 dB under "
              "1/(J w^2)): a static term acts only while the arm moves; the spread includes that level."]  # fmt: skip
    return L + [""]


def summary_levels(c: dict) -> list[float]:
    """The Bode levels (A) of a case's measurements, in the order of its per-level lists."""
    return [float(k.split()[0]) * 1e-3 for k in c["before"]["bode"]["slope_db_per_decade"]]


def table(summary: dict) -> str:
    """``TABLE.md``: the settings, then one table per case."""
    s = summary["settings"]
    L = ["# The proof, end to end: paper's compensator vs augmented, per term", "",
         f"Recording {s['recording_s']:g} s at 50 kHz (seed {s['seed']}); Bode levels "
         + ", ".join(f"{x * 1e3:g}" for x in s["levels"]) + f" mA, {s['n_freq']} frequencies "
         f"{s['f_min']:g}-{s['f_max']:g} Hz; held-out tracking {s['tracking_s']:g} s (seed {s['tracking_seed']}). "
         "Steps: 1 = +0.3 um, 2 = back, 3 = +20 um, 4 = back.", ""]  # fmt: skip
    for c in summary["cases"]:
        L += case_table(c)
    return "\n".join(L)


def run_chain(cfg: Config, out: Path, s: ChainSettings, names: list[str] | None = None) -> dict:
    """Every case of ``names`` (default all of :data:`CASES`) into ``out``; returns the summary."""
    out = Path(out)
    cases = []
    for name in names or list(CASES):
        r = run_case(cfg, CASES[name], s, out / name)
        if r.before is None:
            cases.append(case_summary(r))
            continue
        names_ = {"before": BEFORE[r.case.before], "after": "augmented", "exact": "the drive's exact model as"}
        for label, sweeps in r.sweeps.items():
            title = f"{name}: {names_[label]} compensator (Fig. 8)"
            plot_bode(sweeps, out / name / f"bode_{label}.png", title, r.before["bode"]["band_hz"][1])
        cases.append(case_summary(r))
    sw = s.sweep
    summary = {"settings": {"recording_s": s.recording.duration_s, "seed": s.seed, "levels": list(sw.levels),
                            "n_freq": sw.n_freq, "f_min": sw.f_min, "f_max": sw.f_max, "periods": sw.periods,
                            "tracking_s": s.tracking_s, "tracking_seed": s.tracking_seed, "exact": s.exact},
               "cases": cases}  # fmt: skip
    write_json(out / "summary.json", summary)
    text = table(summary)
    atomic_write(out / "TABLE.md", lambda p: Path(p).write_text(text))
    return summary


__all__ = ["case_summary", "case_table", "run_chain", "table"]
