"""``servo fleet identify``: one recording's least squares of eq. (4) as one row.

A thin adapter over :func:`servo.identify.identification.identify`: the worker loads the recording
(:func:`servo.io.recording.load_recording`, with the source's column mapping and
scales) and fits it; the row holds each term's estimate and standard deviation (the
force unit of the recording per metre, second...), the relative error, the condition
numbers and the rows used.
"""
from __future__ import annotations

from servo.identify.identification import identify
from servo.identify.regressors import RobustSettings
from servo.io.recording import load_recording, parse_mapping

#: drives per Dask task (a fit takes tens of milliseconds)
BATCH = 4
#: the fewest recordings a default local cluster is started for (fewer run in this process):
#: a fit takes tens of ms, a cluster 4-8 s to start
CLUSTER_MIN = 256
TERMS = ("J", "B", "Fc", "K", "h0")


def settings(path: str = "robust", terms=("J", "B", "Fc", "K", "h0"), robust: RobustSettings | None = None,
             force_lag_s: float = 0.0) -> dict:  # fmt: skip
    """The settings of a fleet identification (JSON-able; part of the resume key)."""
    r = robust or RobustSettings()
    return {"command": "identify", "path": path, "terms": list(terms), "force_lag_s": float(force_lag_s),
            "robust": {k: getattr(r, k) for k in r.__dataclass_fields__}}  # fmt: skip


def run(src, s: dict) -> dict:
    """Columns of one recording (a :class:`servo.fleet.sources.Source`)."""
    rec = load_recording(src.path, parse_mapping(src.columns, "columns"), parse_mapping(src.scale, "scale"))
    ident = identify(rec, s["path"], tuple(s["terms"]), RobustSettings(**s["robust"]), s["force_lag_s"])
    f = ident.fit.as_dict()
    out = {"samples": int(rec.n), "sample_rate_hz": float(rec.sample_rate_hz)}
    for t in f["terms"]:
        out[t] = f["params"][t]
        out[f"{t}_std"] = f["std"][t]
    out.update(rel_error_pct=float(f["rel_error_pct"]), cond=float(f["cond"]), cond_scaled=float(f["cond_scaled"]),
               n_rows=int(f["n_rows"]))  # fmt: skip
    return out


def scored(columns: list[str]) -> list[str]:
    """Columns scored for outliers and plotted as histograms: the estimates and the fit's error."""
    return [c for c in TERMS + ("rel_error_pct",) if c in columns]


def pairs(columns: list[str]) -> list[tuple[str, str]]:
    """The main pairs to scatter: estimates that trade off against each other."""
    return [(a, b) for a, b in (("B", "Fc"), ("K", "h0"), ("J", "B"), ("Fc", "h0")) if a in columns and b in columns]


__all__ = ["BATCH", "CLUSTER_MIN", "pairs", "run", "scored", "settings"]
