"""``fleet_report.md``: what a fleet run found, for a person to read.

Counts (drives, failed, resumed), where it ran, the settings; the drives that failed
with their error; for a diagnosis the flagged drives (findings, or an ``unexplained`` or
``out_of_scope`` verdict) with the reason; the population of each scored column
(median, MAD, range); the robust outliers (:mod:`servo.fleet.outliers`), largest score
first.
"""
from __future__ import annotations

import json
import math

import numpy as np

from servo.fleet.outliers import MAD_TO_SD, THRESHOLD, Outlier

MAX_LISTED = 200


def _g(v) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def _settings(text: str) -> str:
    """The settings, less a simulation's base config (it is in ``fleet.json`` and the table)."""
    d = json.loads(text)
    if "base" in d:
        d["base"] = "(the whole config: see fleet.json)"
    return json.dumps(d, sort_keys=True)


def _population(rows: list[dict], columns: list[str]) -> list[str]:
    good = [r for r in rows if r.get("status") == "ok"]
    lines = ["| column | drives | median | MAD | min | max |", "|---|---|---|---|---|---|"]
    for c in columns:
        x = np.array([float(r[c]) for r in good if isinstance(r.get(c), (int, float)) and not isinstance(r.get(c), bool)])
        x = x[np.isfinite(x)]
        if not x.size:
            lines.append(f"| `{c}` | 0 | - | - | - | - |")
            continue
        med = float(np.median(x))
        mad = float(np.median(np.abs(x - med)))
        lines.append(f"| `{c}` | {x.size} | {_g(med)} | {_g(mad)} | {_g(float(x.min()))} | {_g(float(x.max()))} |")
    return lines


def _cut(lines: list[str], n: int) -> list[str]:
    return lines if n <= MAX_LISTED else lines + ["", f"({n - MAX_LISTED} more in the table)"]


def format_report(summary: dict, rows: list[dict], scored: list[str], found: list[Outlier]) -> str:
    """The Markdown text of ``fleet_report.md``."""
    s = summary
    out = [
        f"# Fleet report: servo fleet {s['command']}",
        "",
        f"* drives: {s['drives']} ({s['ok']} ok, {s['failed']} failed; {s['resumed']} taken from an earlier table "
        f"by --resume)",
        f"* ran on: {s['ran_on']}, {s['wall_s']:.1f} s",
        f"* settings: `{_settings(s['settings'])}`",
        f"* table: `{s['table']}` (one row per drive)",
        "",
    ]
    failed = [r for r in rows if r.get("status") != "ok"]
    out += [f"## Failed drives ({len(failed)})", ""]
    if failed:
        lines = ["| drive | error |", "|---|---|"] + [f"| {r['drive']} | {r['error']} |" for r in failed[:MAX_LISTED]]
        out += _cut(lines, len(failed))
    else:
        out.append("None.")
    out.append("")
    if s["command"] == "diagnose":
        flagged = [r for r in rows if r.get("status") == "ok" and r.get("flagged")]
        out += [f"## Flagged drives ({len(flagged)} of {s['ok']})", "",
                "A drive is flagged when its diagnosis names physics the baseline leaves out, or when its verdict "
                "is `unexplained` (the final model still fails a check) or `out_of_scope`.", ""]  # fmt: skip
        if flagged:
            lines = ["| drive | findings | verdict | reason |", "|---|---|---|---|"]
            for r in flagged[:MAX_LISTED]:
                reason = (r.get("flag_reason") or "-").replace("|", "/")
                lines.append(f"| {r['drive']} | {r.get('findings') or '-'} | {r.get('verdict') or '-'} | {reason} |")
            out += _cut(lines, len(flagged))
        else:
            out.append("None: no drive shows physics its baseline leaves out, and every verdict is consistent or "
                       "explained.")  # fmt: skip
        out.append("")
    out += ["## Population", "", *_population(rows, scored), ""]
    out += [f"## Robust outliers ({len(found)})", "",
            f"Robust score z = (value - median) / ({MAD_TO_SD} MAD) over the drives that succeeded, with the MAD of "
            f"the drive's side of the median; listed when |z| > {THRESHOLD}.  Scored: continuous figures only (the estimates and held-out errors, the RMS "
            f"errors of a simulation).", ""]  # fmt: skip
    if s.get("not_scored"):
        out += ["Not scored (quantised, fewer than 90 % distinct values, or a MAD of 0): "
                + ", ".join(f"`{c}`" for c in s["not_scored"]), ""]  # fmt: skip
    if found:
        lines = ["| drive | column | value | median | z |", "|---|---|---|---|---|"]
        lines += [f"| {o.drive} | `{o.column}` | {_g(o.value)} | {_g(o.median)} | {o.z:+.1f} |" for o in found[:MAX_LISTED]]
        out += _cut(lines, len(found))
    else:
        out.append("None.")
    out.append("")
    return "\n".join(out)


__all__ = ["format_report"]
