"""``servo fleet diagnose``: one recording's diagnosis as one row.

A thin adapter over :func:`servo.diagnose.job.diagnose` and
:func:`servo.diagnose.report.build_report`: the row is read from the report (the same
dictionary ``servo diagnose`` writes as ``report.json``), so what the report gains the
table can pick up.  Columns: ``findings`` (the physics named, in order, comma-separated),
``n_findings``, ``verdict`` when the report has one (a string, or its strict JSON when it
is a table) and ``verdict_text``, ``flagged`` and ``flag_reason`` (:func:`flag`), the
held-out errors before and after, and every parameter of the final model as
``<physics>.<param>`` with ``<physics>.<param>_std``.

A drive is **flagged** when the diagnosis found physics its baseline leaves out, *or*
when its verdict says the final model does not describe the recording
(:data:`FLAGGING_VERDICTS`: ``unexplained``, a mismatch no term of the vocabulary
accounts for; ``out_of_scope``, a recording the force balance does not describe): such a
drive has no findings, yet it is the one a drive maker must look at.
"""
from __future__ import annotations

from servo.io.atomic import strict_json

#: drives per Dask task (a diagnosis takes a fraction of a second or more)
BATCH = 1
#: what a worker imports as it joins (the diagnosis, its scipy modules and kernels)
WARM = ("servo.diagnose.job", "servo.diagnose.report", "servo.io.recording")
#: the fewest recordings a default local cluster is started for (fewer run in this process):
#: a diagnosis of a 1 s recording takes 0.4-0.9 s idle, a cluster 4-8 s to start
CLUSTER_MIN = 16
#: verdicts of :mod:`servo.diagnose.verdict` that flag a drive, findings or not
FLAGGING_VERDICTS = ("unexplained", "out_of_scope")


def settings(baseline: str | None = None, test_fraction: float = 0.25, blocks: int = 10, alpha: float = 0.05,
             horizon_s: float | None = None, cutoff_hz: float | None = None, decimate: int | None = None,
             force_unit: str = "A", band: str = "reversals") -> dict:  # fmt: skip
    """The settings of a fleet diagnosis (JSON-able; part of the resume key).  As
    ``servo diagnose``'s: ``decimate`` a fixed factor, or None (the default) for the
    decimation chosen from each recording by the rule ``band``
    (:mod:`servo.diagnose.band`)."""
    return {"command": "diagnose", "baseline": baseline, "test_fraction": test_fraction, "blocks": blocks,
            "alpha": alpha, "horizon_s": horizon_s, "cutoff_hz": cutoff_hz, "decimate": decimate, "band": band,
            "force_unit": force_unit}  # fmt: skip


def options(s: dict):
    """The :class:`servo.diagnose.job.Options` of fleet ``settings`` (those ``servo
    diagnose`` builds from the same options)."""
    from servo.diagnose.job import Options  # scipy.signal, the kernels: in the worker, not the client
    from servo.identify.regressors import RobustSettings

    fixed = None if s["decimate"] is None else RobustSettings(cutoff_hz=s["cutoff_hz"], decimate=s["decimate"])
    return Options(baseline=s["baseline"], test_fraction=s["test_fraction"], blocks=s["blocks"], alpha=s["alpha"],
                   horizon_s=s["horizon_s"], force_unit=s["force_unit"], settings=fixed, cutoff_hz=s["cutoff_hz"],
                   band=s["band"])  # fmt: skip


def flag(names: list[str], verdict, verdict_text: str | None = None) -> tuple[bool, str | None]:
    """Whether a drive is flagged and why (module doc): ``findings: hysteresis,offset``
    and/or ``verdict unexplained: <the verdict's text>``; (False, None) otherwise."""
    why = [f"findings: {','.join(names)}"] if names else []
    if isinstance(verdict, str) and verdict in FLAGGING_VERDICTS:
        why.append(f"verdict {verdict}" + (f": {verdict_text}" if verdict_text else ""))
    return bool(why), ("; ".join(why) or None)


def row_of_report(report: dict) -> dict:
    """The columns of a diagnosis report (``report.json``'s dictionary)."""
    names = [f["physics"] for f in report["findings"]]
    flagged, reason = flag(names, report.get("verdict"), report.get("verdict_text"))
    out = {"findings": ",".join(names), "n_findings": len(names), "flagged": flagged, "flag_reason": reason,
           "samples": int(report["recording"]["samples"])}  # fmt: skip
    if "verdict" in report:
        v = report["verdict"]
        out["verdict"] = v if isinstance(v, str) or v is None else strict_json(v).replace("\n", " ")
        out["verdict_text"] = " ".join(str(report.get("verdict_text") or "").split()) or None
    be, fe = report["baseline"]["error"], report["final_model"]["error"]
    for k in ("test_force_rel_pct", "test_output_nrmse"):
        out[f"{k}_before"] = be[k]
        out[f"{k}_after"] = fe[k]
    for term in report["final_model"]["terms"]:
        for k, v in term["params"].items():
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                out[f"{term['physics']}.{k}"] = float(v)
                s = (term.get("std") or {}).get(k)
                out[f"{term['physics']}.{k}_std"] = None if s is None else float(s)
    return out


def run(src, s: dict) -> dict:
    """Columns of one recording (a :class:`servo.fleet.sources.Source`)."""
    from servo.diagnose.job import diagnose
    from servo.diagnose.report import build_report
    from servo.io.recording import load_recording, parse_mapping

    rec = load_recording(src.path, parse_mapping(src.columns, "columns"), parse_mapping(src.scale, "scale"))
    return row_of_report(build_report(diagnose(rec, options(s))))


def scored(columns: list[str]) -> list[str]:
    """Columns scored for outliers and plotted as histograms: the final model's parameters
    and the held-out errors."""
    params = [c for c in columns if "." in c and not c.endswith("_std")]
    return params + [c for c in ("test_force_rel_pct_after", "test_output_nrmse_after") if c in columns]


def pairs(columns: list[str]) -> list[tuple[str, str]]:
    """The main pairs to scatter: friction levels, the bias, and the error before/after."""
    want = (("viscous_friction.B", "coulomb_friction.Fc"), ("stiffness.K", "offset.h0"),
            ("inertia.J", "viscous_friction.B"), ("test_force_rel_pct_before", "test_force_rel_pct_after"))  # fmt: skip
    return [(a, b) for a, b in want if a in columns and b in columns]


__all__ = ["BATCH", "CLUSTER_MIN", "FLAGGING_VERDICTS", "WARM", "flag", "options", "pairs", "row_of_report", "run", "scored", "settings"]
