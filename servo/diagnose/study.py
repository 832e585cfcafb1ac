"""The detection study: concealed effects and null recordings, diagnosed blind.

    python -m servo.diagnose.study --seeds 20 --null-seeds 200 --jobs 2 --out study

For each effect of :data:`servo.diagnose.concealed.EFFECTS` and each of its sizes, the
recordings of ``--seeds`` seeds are diagnosed with the effect's baseline; an effect is
*detected* when its physics is among the findings.  The smallest size detected in at
least 95 % of the seeds is the detection threshold.  Null recordings (nothing missing)
give the false-alarm rate: the fraction with any finding, and per locate test the
fraction where it flagged anything.  Writes ``study.json`` (every run) and
``study.md`` (the tables of ``docs/diagnosis.md``).
"""
from __future__ import annotations

import argparse
import json
import math
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from servo.diagnose.concealed import EFFECTS, concealed_recording
from servo.diagnose.job import Options, diagnose

DETECT = 0.95


def run_one(job: tuple) -> dict:
    """Diagnose one concealed recording: ``(effect or None, size, seed)``."""
    effect, size, seed = job
    rec, truth = concealed_recording(effect, size, seed)
    t0 = time.perf_counter()
    try:
        D = diagnose(rec, Options(baseline=truth["baseline"]))
    except Exception as exc:  # a study records failures instead of stopping
        return {"effect": effect, "size": size, "seed": seed, "error": f"{type(exc).__name__}: {exc}"}
    loc = D.locate
    return {
        "effect": effect, "size": size, "seed": seed, "seconds": time.perf_counter() - t0,
        "findings": [f.physics for f in D.findings],
        "params": [{k: float(v) for k, v in f.params.items()} for f in D.findings],
        "unconfirmed": [f.physics for f, _, _ in D.unconfirmed],
        "locate": {
            "time": bool(loc["time"]["flagged"]),
            "state": any(v["flagged"] for v in loc["state"]["variables"].values()),
            "spectrum": bool(loc["spectrum"]["flagged_hz"]),
            "coherence": bool(loc["coherence"]["flagged_hz"]),
            "xcorr": bool(loc["xcorr"]["flagged_lag_s"]),
        },
    }  # fmt: skip


def _ci(k: int, n: int) -> str:
    """Clopper-Pearson 95 % interval of a rate, in %."""
    from scipy import stats

    lo = stats.beta.ppf(0.025, k, n - k + 1) if k > 0 else 0.0
    hi = stats.beta.ppf(0.975, k + 1, n - k) if k < n else 1.0
    return f"{100 * lo:.1f}-{100 * hi:.1f} %"


def tables(runs: list) -> str:
    """Markdown tables of the detection study and the null recordings."""
    out = ["| effect (size is) | sizes tried | detected at each size | smallest size detected at 95 % | "
           "other physics named (all sizes) |", "|---|---|---|---|---|"]  # fmt: skip
    for name, e in EFFECTS.items():
        rs = [r for r in runs if r["effect"] == name and "error" not in r]
        if not rs:
            continue
        sizes = sorted({r["size"] for r in rs})
        rates, smallest = [], None
        for s in sizes:
            sel = [r for r in rs if r["size"] == s]
            k = sum(name in r["findings"] for r in sel)
            rates.append(f"{k}/{len(sel)}")
            if smallest is None and k >= math.ceil(DETECT * len(sel)):
                smallest = s
        wrong = sum(any(f != name for f in r["findings"]) for r in rs)
        out.append(f"| `{name}` ({e.what}, {e.unit}) | {', '.join(f'{s:g}' for s in sizes)} | {', '.join(rates)} | "
                   f"{'%g' % smallest if smallest is not None else 'not within the sizes tried'} | "
                   f"{wrong}/{len(rs)} |")  # fmt: skip
    nulls = [r for r in runs if r["effect"] is None and "error" not in r]
    if nulls:
        n = len(nulls)
        k = sum(bool(r["findings"]) for r in nulls)
        named = {}
        for r in nulls:
            for f in r["findings"]:
                named[f] = named.get(f, 0) + 1
        out += ["", "| null recordings | count | rate (95 % interval) |", "|---|---|---|",
                f"| any finding (false alarm) | {k}/{n} | {100 * k / n:.1f} % ({_ci(k, n)}) |"]  # fmt: skip
        for f, c in sorted(named.items(), key=lambda x: -x[1]):
            out.append(f"| ... naming `{f}` | {c}/{n} | {100 * c / n:.1f} % |")
        for test in ("time", "state", "spectrum", "coherence", "xcorr"):
            c = sum(r["locate"][test] for r in nulls)
            out.append(f"| locate test `{test}` flags something | {c}/{n} | {100 * c / n:.1f} % ({_ci(c, n)}) |")
    errs = [r for r in runs if "error" in r]
    if errs:
        out += ["", f"{len(errs)} runs failed: " + "; ".join(sorted({r['error'] for r in errs}))[:500]]
    secs = [r["seconds"] for r in runs if "seconds" in r]
    if secs:
        out += ["", f"{len(runs)} diagnoses of 50 000-sample recordings, median {np.median(secs):.2f} s each."]
    return "\n".join(out) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m servo.diagnose.study", description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20, help="seeds per effect and size (default 20)")
    ap.add_argument("--null-seeds", type=int, default=200, help="null recordings (default 200)")
    ap.add_argument("--effects", help="comma list of effects (default all)")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    ap.add_argument("--out", default="study", help="output folder (default ./study)")
    a = ap.parse_args(argv)
    names = a.effects.split(",") if a.effects else list(EFFECTS)
    jobs = [(None, 0.0, 10_000 + s) for s in range(a.null_seeds)]
    jobs += [(n, size, s) for n in names for size in EFFECTS[n].sizes for s in range(a.seeds)]
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    with ProcessPoolExecutor(a.jobs) as ex:
        runs = list(ex.map(run_one, jobs, chunksize=4))
    (out / "study.json").write_text(json.dumps(runs, indent=1))
    text = tables(runs)
    (out / "study.md").write_text(text)
    print(text)
    print(f"{len(runs)} runs in {time.time() - t0:.0f} s; wrote {out}/study.json, {out}/study.md")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
