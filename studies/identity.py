"""Bit-identity of a change that must not change behaviour: dump, then compare.

    python -m studies.identity recordings DIR [--nulls 60 --seeds 2 --seed-offset 40000]
    python -m studies.identity recordings DIR --grid kinds --nulls 16 --seeds 1 --seed-offset 0
    python -m studies.identity dump DIR --recordings RECDIR     # run logs and diagnoses (--no-runs: diagnoses)
    python -m studies.identity compare DIR_A DIR_B

``recordings`` writes proving-ground recordings (nulls and every family at every size,
:mod:`studies.proving.cases`; ``--grid kinds`` the second grid's cells,
:func:`studies.proving.study.kind_jobs`) as NPZ files, so that two checkouts diagnose the very same
arrays.  ``dump`` runs ``servo run`` for every controller kind on the tick path and the
fast path (logs as NPZ) and diagnoses every recording (``build_report`` without the
provenance and the timings).  ``compare`` says which arrays or reports differ, to the
bit; it exits 1 on any difference.  Run each step with the checkout under test first on
``PYTHONPATH``.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

KINDS = ("pi", "track", "nss")


def _proving():
    try:  # the harness outlives the move of the proving ground out of the package
        from studies.proving import cases, study
    except ImportError:
        from servo.diagnose.proving import cases, study
    return cases, study


def make_recordings(out: Path, nulls: int, seeds: int, offset: int, grid: str = "combos") -> int:
    cases, study = _proving()
    out.mkdir(parents=True, exist_ok=True)
    fams = [f for f in cases.FAMILIES if f != "null"]
    if grid == "kinds":
        jobs = [(f, size, seed, cell) for f, size, seed, _, cell in study.kind_jobs(fams, nulls, seeds, offset)]
    else:
        jobs = [("null", 0.0, 50_000 + offset + s, None) for s in range(nulls)]
        jobs += [(f, size, 60_000 + offset + s, None) for f in cases.FAMILIES for size in cases.FAMILIES[f].sizes
                 for s in range(seeds)]  # fmt: skip
    n = 0
    for family, size, seed, cell in jobs:
        ctl, exc, rate = study.combo(family, size, seed) if cell is None else cell[:3]
        noise = "white" if cell is None else cell[3]
        try:
            rec, _ = cases.recording(cases.Case(family, size, ctl, exc, rate, noise=noise), seed)
        except Exception as e:  # a case the generator refuses is left out of both sides
            print(f"skip {family} {size} {seed}: {type(e).__name__}: {e}", file=sys.stderr)
            continue
        arrays = {k: getattr(rec, k) for k in ("t", "u", "x", "v", "r") if getattr(rec, k) is not None}
        np.savez(out / f"{family}-{size:g}-{seed}.npz", **arrays)
        n += 1
    return n


def _scrub(report: dict) -> dict:
    report.pop("provenance", None)
    report.pop("seconds", None)
    return report


def dump(out: Path, recdir: Path | None, runs: bool = True) -> None:
    out.mkdir(parents=True, exist_ok=True)
    for kind in KINDS if runs else ():
        for path in ("fast", "no-fast"):
            d = out / "runs" / f"{kind}-{path}"
            r = subprocess.run([sys.executable, "-m", "servo", "run", "--quiet", f"--{path}", "--set",
                                f"controller.kind={kind}", "--log-format", "npz", "--out", str(d)],
                               capture_output=True, text=True)  # fmt: skip
            if r.returncode:
                raise SystemExit(f"servo run {kind} --{path}: {r.stderr.strip()}")
    if recdir is None:
        return
    from servo.diagnose.job import diagnose
    from servo.diagnose.report import build_report
    from servo.io.recording import Recording

    rep = out / "diagnoses"
    rep.mkdir(exist_ok=True)
    for f in sorted(recdir.glob("*.npz")):
        z = np.load(f)
        rec = Recording(z["t"], z["u"], z["x"], z["v"] if "v" in z else None, source=f.name,
                        r=z["r"] if "r" in z else None)  # fmt: skip
        try:
            report = _scrub(build_report(diagnose(rec)))
        except Exception as e:
            report = {"error": f"{type(e).__name__}: {e}"}
        (rep / (f.stem + ".json")).write_text(json.dumps(report, sort_keys=True, default=repr))


def compare(a: Path, b: Path) -> int:
    diffs, n = [], 0
    for fa in sorted(a.rglob("*")):
        if fa.is_dir() or fa.suffix not in (".npz", ".json") or fa.name in ("summary.json",):
            continue
        fb = b / fa.relative_to(a)
        n += 1
        if not fb.exists():
            diffs.append(f"{fa.relative_to(a)}: missing in {b}")
        elif fa.suffix == ".json":
            if fa.read_bytes() != fb.read_bytes():
                diffs.append(f"{fa.relative_to(a)}: reports differ")
        else:
            za, zb = np.load(fa), np.load(fb)
            if sorted(za.files) != sorted(zb.files):
                diffs.append(f"{fa.relative_to(a)}: columns differ")
            for k in za.files:
                if k in zb.files and (za[k].shape != zb[k].shape or za[k].tobytes() != zb[k].tobytes()):
                    diffs.append(f"{fa.relative_to(a)}: column {k} differs")
    print("\n".join(diffs) or f"{n} files identical to the bit")
    return 1 if diffs or n == 0 else 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m studies.identity", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("recordings")
    r.add_argument("out", type=Path)
    r.add_argument("--nulls", type=int, default=60)
    r.add_argument("--seeds", type=int, default=2)
    r.add_argument("--seed-offset", type=int, default=40000)
    r.add_argument("--grid", choices=("combos", "kinds"), default="combos")
    d = sub.add_parser("dump")
    d.add_argument("out", type=Path)
    d.add_argument("--recordings", type=Path)
    d.add_argument("--no-runs", action="store_true", help="the diagnoses only")
    c = sub.add_parser("compare")
    c.add_argument("a", type=Path)
    c.add_argument("b", type=Path)
    a = ap.parse_args(argv)
    if a.cmd == "recordings":
        print(make_recordings(a.out, a.nulls, a.seeds, a.seed_offset, a.grid), "recordings written")
        return 0
    if a.cmd == "dump":
        dump(a.out, a.recordings, not a.no_runs)
        return 0
    return compare(a.a, a.b)


if __name__ == "__main__":
    sys.exit(main())
