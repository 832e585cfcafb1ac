"""An outside generator's recordings, scored through the proving ground's tables.

    python -m studies.proving.independent [SUITE.py] --out DIR

``SUITE.py`` (default ``../shared/proving/independent_v1.py`` beside the checkout) is
a recording generator written by someone who never read this project's code: a module
with ``CASES`` (name -> ``(overrides, fs, seconds, reference kind, amplitude, expected
physics)``), ``BASE``, ``GAINS``, ``reference`` and ``simulate``, and ``main(out)``
writing ``CASE.csv`` (``t,u,x``) and ``truth.json``.  Each recording is diagnosed with
the default options and scored as the proving ground's records are
(:func:`studies.proving.study.tables_kinds`): a case's right names are its truth's
``expect``, its right verdict ``consistent`` for a case that hides nothing and
``explained`` otherwise (the model with the right term explains it to its noise).
Its effect on the held-out error is measured against its twin, the same case with the
effect's overrides removed (:data:`NOT_THE_EFFECT` kept: seed, dither, the viscous
level), simulated by the suite's own ``simulate`` with the same draws
(:func:`studies.proving.twin.heldout_rms` on both, on the recording's path).
Writes ``study.json`` and ``study.md``.
"""
from __future__ import annotations

import argparse
import contextlib
import importlib.util
import io
import json
import tempfile
from pathlib import Path

import numpy as np

from servo.io.atomic import atomic_write, write_json

DEFAULT_SUITE = Path(__file__).resolve().parents[2].parent / "shared" / "proving" / "independent_v1.py"
#: overrides of a case that are its excitation or baseline, not its effect (kept in the twin)
NOT_THE_EFFECT = ("seed", "dither", "B")


def load_suite(path: str | Path):
    """The suite module at ``path``, its ``simulate`` compiled afresh without numba's
    on-disk cache (a module loaded from a path is not importable by name, which that
    cache needs; and nothing is written beside the suite)."""
    from numba import config, njit

    spec = importlib.util.spec_from_file_location("independent_suite", str(path))
    mod = importlib.util.module_from_spec(spec)
    kept = config.CACHE_DIR
    with tempfile.TemporaryDirectory() as tmp:
        config.CACHE_DIR = tmp  # its decorator's cache folder, which nothing uses, not beside the suite
        try:
            spec.loader.exec_module(mod)
        finally:
            config.CACHE_DIR = kept
    mod.simulate = njit(mod.simulate.py_func)
    return mod


def _simulate(mod, name: str, over: dict):
    """``(t, u, x)`` of case ``name`` of the suite with the overrides ``over`` (the
    suite's own reference and simulator, as its ``main`` calls them)."""
    _, fs, secs, kind, amp, _ = mod.CASES[name]
    p = dict(mod.BASE)
    p.update(over)
    n = int(fs * secs)
    rng = np.random.default_rng(sum(map(ord, name)))
    r = mod.reference(n, fs, kind, amp, rng)
    g = mod.GAINS
    U, X = mod.simulate(n, float(fs), 20, r, p["J"], p["B"], p["Fc"], p["K"], p["h0"], p["hyst"], p["sigma"], p["Ha"],
                        p["fs_ratio"], p["vs"], p["mode_f"], p["mode_z"], p["mode_g"], p["delay"], p["umax"],
                        p["kt_slope"], p["xspan"], p["cog_a"], p["cog_p"], p["basym"], g["kp"], g["kd"], g["ki"],
                        p["noise"], p["q"], p["dither"], p["seed"])  # fmt: skip
    return np.arange(n) / fs, U, X


def score_case(mod, name: str, folder: Path) -> dict:
    """Diagnose the suite's recording ``folder/name.csv`` and measure its effect (module doc)."""
    from servo.diagnose.job import diagnose
    from studies.proving.study import levels
    from servo.io.recording import Recording, load_recording
    from studies.proving.twin import heldout_rms

    over, fs, secs, kind, amp, expect = mod.CASES[name]
    null = not expect
    out = {"family": name, "size": 0.0 if null else 1.0, "seed": int(over.get("seed", mod.BASE["seed"])),
           "controller": "pdi", "excitation": kind, "rate_hz": float(fs), "noise": "white", "null": null,
           "expect": expect[0] if expect else None, "accept": list(expect),
           "verdicts": ["consistent"] if null else ["explained"]}  # fmt: skip
    try:
        rec = load_recording(folder / f"{name}.csv")
        D = diagnose(rec)
    except Exception as exc:  # a study records refusals instead of stopping
        return {**out, "error": f"{type(exc).__name__}: {str(exc)[:200]}"}
    v = D.verdict
    out.update({"findings": [f.physics for f in D.findings], "verdict": v["verdict"], **levels(D)})
    if not null:
        try:
            rms, settings = heldout_rms(rec)
            t, U, X = _simulate(mod, name, {k: val for k, val in over.items() if k in NOT_THE_EFFECT})
            rms0, _ = heldout_rms(Recording(t, U, X, None, source=f"{name} twin"), settings)
            out["effect"] = float(1.0 - rms0 / max(rms, 1e-300))
        except Exception as exc:  # the twin refused: the table falls back to the floor's measure
            out["twin_error"] = f"{type(exc).__name__}: {str(exc)[:200]}"
    return out


def run(suite: str | Path) -> list[dict]:
    """Write the suite's recordings into a temporary folder and score each (module doc)."""
    mod = load_suite(suite)
    with tempfile.TemporaryDirectory() as tmp:
        with contextlib.redirect_stdout(io.StringIO()):
            mod.main(tmp)
        truth = json.loads((Path(tmp) / "truth.json").read_text())
        return [score_case(mod, name, Path(tmp)) for name in truth]


def main(argv=None) -> int:
    from studies.proving.study import tables_kinds

    ap = argparse.ArgumentParser(prog="python -m studies.proving.independent", description=__doc__.splitlines()[0])
    ap.add_argument("suite", nargs="?", default=str(DEFAULT_SUITE), help=f"the generator (default {DEFAULT_SUITE})")
    ap.add_argument("--out", default="independent-study")
    a = ap.parse_args(argv)
    if not Path(a.suite).is_file():
        ap.error(f"no suite at {a.suite}")
    runs = run(a.suite)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    text = tables_kinds(runs, label="case")
    write_json(out / "study.json", runs)
    atomic_write(out / "study.md", lambda tmp: Path(tmp).write_text(text))
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
