"""The proving-ground study: null recordings and effect families, diagnosed blind.

    python -m studies.proving.study --nulls 240 --seeds 8 --workers 2 --out proving-study
    python -m studies.proving.study ... --scheduler tcp://HOST:PORT   # on an existing Dask cluster

Null recordings cycle through every controller, excitation and rate of
:mod:`studies.proving.cases`; each family and size gets ``--seeds`` recordings,
each seed on the next combination.  Per recording: the findings, the verdict and the
baseline's held-out residual over the noise floor (``base_ratio``).  A family's
*effect on the held-out error* is measured against the recording's twin, the same case
and seed without the effect: the share of the baseline's held-out RMS error the twin does
not have (:mod:`studies.proving.twin`); detection is reported over the recordings
where it is at least 20 %.  The first measure, ``1 - 1/base_ratio`` (the share a model
reaching the recording's noise floor removes), is kept in a column of its own: it
counts a null's own misfit as the effect's, and misses a quantum whose noise the floor
holds.  Writes ``study.json`` and ``study.md``.
The diagnoses run on Dask through the fleet's path
(:func:`servo.fleet.runner.map_batches`), in batches of :data:`BATCH` recordings, each
made by the worker from its ``(family, size, seed)``; the runs come back in the jobs'
order.

The first scored seeds were nulls 50000+ and families 60000+ (offset 0); fresh
seeds were scored since on offsets 20000, 25000 and 65000
(docs/studies/2026-11-23-proving-ground-scores.md; the latest in docs/diagnosis.md, 10).
A change to the diagnosis is developed on other seeds (``--seed-offset 40000``, 45000,
52000; 70000 has been a second look) and scored once on unused ones, its levels fixed
first.

**The second grid** (``--grid kinds``, issue 24): every recording at 5 kHz on one of
sixteen cells, loop (``pdi`` closed, ``force`` open: :mod:`studies.proving.cases`) x
excitation (multisine, PRBS, chirp, steps) x sensor noise (white, coloured: pink or
first-order low-pass, alternating), :func:`grid_cell`.  Nulls fill the cells in turn
(``--nulls 64`` is four per cell); a family's sizes and seeds are an orthogonal array
over them (with ``--seeds 4``, each family meets each cell once, each size each
excitation once, both loops and both noises twice).  Its seeds are nulls 300000+ and
families 310000+ (plus the offset).  The tables (:func:`tables_kinds`) give, per cell,
family and excitation, with Wilson 95 % intervals: the nulls' ``consistent`` and false
alarms, detection (a right name) where the effect on the held-out error is at least
20 %, ``consistent`` while such an effect is present (must be 0), wrong names, and
recordings the diagnosis refused.  ``python -m studies.proving.independent`` scores an
outside generator's recordings through the same tables.
"""
from __future__ import annotations

import argparse
import itertools
import time
from pathlib import Path

from studies.proving.cases import (CONTROLLERS, EXCITATIONS, FAMILIES, FORCE_EXCITATIONS, RATES, Case, accepted,
                                   recording)  # fmt: skip
from servo.io.atomic import atomic_write, write_json

COMBOS = list(itertools.product(CONTROLLERS, EXCITATIONS, RATES))
EFFECT_MIN = 0.2
#: recordings per Dask task
BATCH = 4


def combo(family: str, size: float, seed: int) -> tuple:
    """The controller, excitation and rate of one recording: nulls cycle through
    :data:`COMBOS` with the seed; a family's sizes and seeds are spread over them too
    (each size starts at another offset), so that no family is measured on a few
    combinations only."""
    if family == "null":
        return COMBOS[(seed * 7) % len(COMBOS)]
    names = list(FAMILIES)
    k = names.index(family) * 17 + list(FAMILIES[family].sizes).index(size) * 31 if size in FAMILIES[family].sizes else 0
    return COMBOS[(seed * 7 + k) % len(COMBOS)]


#: the second grid's loops (closed, open), excitations and noise colours (module doc)
KIND_LOOPS = ("pdi", "force")
KIND_EXCITATIONS = FORCE_EXCITATIONS
KIND_NOISES = ("white", "coloured")
KIND_RATE = 5000.0
KIND_SEEDS = {"null": 300_000, "family": 310_000}


def grid_cell(family: str, size_index: int, j: int) -> tuple[str, str, str]:
    """The loop, excitation and noise of the second grid's ``j``-th recording of a
    family at its ``size_index``-th size (module doc).  Nulls (``size_index`` 0) take
    the cells in turn; a family's recordings form an orthogonal array: for ``j`` in 0-3
    the four sizes meet every excitation once, and each size and each excitation both
    loops and both noises twice.  A coloured noise is pink or low-pass, alternating."""
    if family == "null":
        exc, loop, noisy, alt = j % 4, (j // 4) % 2, (j // 8) % 2, (j // 16) % 2
    else:
        exc, loop, noisy, alt = (size_index + j) % 4, j % 2, (j // 2 + size_index) % 2, (j // 4 + size_index) % 2
    noise = "white" if not noisy else ("pink", "lowpass")[alt]
    return KIND_LOOPS[loop], KIND_EXCITATIONS[exc], noise


def kind_jobs(families: list[str], nulls: int, seeds: int, offset: int = 0) -> list[tuple]:
    """The second grid's jobs ``(family, size, seed, False, (controller, excitation,
    rate, noise))``: ``nulls`` nulls, then ``seeds`` recordings of each family's sizes."""
    jobs = [("null", 0.0, KIND_SEEDS["null"] + offset + j, False, (*grid_cell("null", 0, j)[:2], KIND_RATE,
             grid_cell("null", 0, j)[2])) for j in range(nulls)]  # fmt: skip
    for f in families:
        for i, size in enumerate(FAMILIES[f].sizes):
            for j in range(seeds):
                ctl, exc, noise = grid_cell(f, i, j)
                jobs.append((f, size, KIND_SEEDS["family"] + offset + 100 * i + j, False, (ctl, exc, KIND_RATE, noise)))
    return jobs


def run_one(job: tuple) -> dict:
    """Diagnose one recording: ``(family, size, seed)``, or with a fourth item True, a
    closed loop's recording carries its excitation as ``r`` (``--excitation-as-r``);
    a fifth item ``(controller, excitation, rate, noise)`` sets the case instead of
    :func:`combo` (the second grid)."""
    family, size, seed, with_r, cell = (*job, False, None)[:5]
    ctl, exc, rate = combo(family, size, seed) if cell is None else cell[:3]
    noise = "white" if cell is None else cell[3]
    out = {"family": family, "size": size, "seed": seed, "controller": ctl, "excitation": exc, "rate_hz": rate}
    if cell is not None:
        out["noise"] = noise
    from servo.diagnose.job import diagnose

    try:
        rec, truth = recording(Case(family, size, ctl, exc, rate, noise=noise), seed, excitation=with_r)
        t0 = time.perf_counter()
        D = diagnose(rec)
    except Exception as exc_:  # a study records failures instead of stopping
        return {**out, "error": f"{type(exc_).__name__}: {str(exc_)[:200]}"}
    seconds = time.perf_counter() - t0  # the diagnosis alone, not its twin below
    v = D.verdict
    if size > 0:  # measured against its twin without the effect (module doc)
        from studies.proving.twin import twin_effect

        try:
            out["effect"] = twin_effect(Case(family, size, ctl, exc, rate, noise=noise), seed, rec)
        except Exception as exc_:  # the twin refused: the table falls back to the floor's measure, and counts it
            out["twin_error"] = f"{type(exc_).__name__}: {str(exc_)[:200]}"
    params = {f.physics: {k: float(x) for k, x in f.params.items() if isinstance(x, (int, float))} for f in D.findings}
    return {**out, "seconds": seconds, "findings": [f.physics for f in D.findings], "params": params,
            "verdict": v["verdict"], "expect": truth["expect"], "verdicts": truth["verdicts"],
            **levels(D),
            "frf_ran": bool(D.frf is not None and D.frf.ran),
            "frf_method": D.frf.method if D.frf is not None else None,
            "gated": {f.physics: f.term.params["from_s"] for f in D.findings if "from_s" in f.term.params},
            "frf_findings": [f.physics for f in D.findings if getattr(f, "frf", None) is not None],
            "frf_failed": bool(v["final_checks"].get("frf", {}).get("failed"))}  # fmt: skip


def levels(D) -> dict:
    """A diagnosis's decimation and its baseline's and final model's held-out residual
    over the floor; None each for a recording out of scope before any row was made
    (:class:`servo.diagnose.scope.Unscoped`)."""
    if D.sig is None:
        return {"decimate": None, "base_ratio": None, "final_ratio": None}
    v = D.verdict
    return {"decimate": int(D.sig.settings.decimate), "base_ratio": v["baseline_checks"]["level"]["ratio"],
            "final_ratio": v["final_checks"]["level"]["ratio"]}


def run_batch(jobs: list) -> list[dict]:
    """:func:`run_one` of each job, in order (what one Dask task runs)."""
    return [run_one(j) for j in jobs]


def failed_batch(jobs: list, why: str) -> list[dict]:
    """The runs of a batch whose workers kept dying."""
    return [{"family": j[0], "size": j[1], "seed": j[2], "error": why} for j in jobs]


def names_accepted(r: dict) -> tuple:
    """The names that count as a detection on a study record: its own ``accept`` (an
    outside generator's truth), else :func:`studies.proving.cases.accepted`."""
    if "accept" in r:
        return tuple(r["accept"])
    return accepted(r["family"], r["size"], r.get("decimate"))


def named_right(r: dict) -> bool:
    """Whether a study record's findings hold a name its family accepts
    (:func:`studies.proving.cases.accepted`)."""
    return any(n in r["findings"] for n in names_accepted(r))


def wilson(k: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """Wilson score 95 % interval of ``k/n`` (fractions)."""
    if n == 0:
        return 0.0, 1.0
    p = k / n
    c = (p + z * z / (2 * n)) / (1 + z * z / n)
    h = z * ((p * (1 - p) / n + z * z / (4 * n * n)) ** 0.5) / (1 + z * z / n)
    return max(0.0, c - h), min(1.0, c + h)


def ci(k: int, n: int) -> str:
    """Wilson 95 % interval of ``k/n``, in %."""
    lo, hi = wilson(k, n)
    return f"{100 * lo:.1f}-{100 * hi:.1f} %"


def _rate(k, n):
    return f"{k}/{n} ({ci(k, n)})" if n else "-"


def effect(r: dict) -> float:
    """A study record's effect on the held-out error: against its twin without the effect
    (:mod:`studies.proving.twin`), else (a record made before the twin) the first
    measure :func:`effect_vs_floor`."""
    return r["effect"] if "effect" in r else effect_vs_floor(r)


def effect_vs_floor(r: dict) -> float:
    """The first measure: ``1 - 1/base_ratio``, the share of the baseline's held-out RMS
    error that a model at the recording's noise floor removes (module doc); 0 for a
    recording out of scope before any row was made (no residual to measure)."""
    if r.get("base_ratio") is None:
        return 0.0
    return 1 - 1 / max(r["base_ratio"], 1e-300)


def tables(runs: list) -> str:
    ok = [r for r in runs if "error" not in r]
    nulls = [r for r in ok if r["family"] == "null"]
    lines = ["| null recordings | false alarm (any finding) | verdict `consistent` |", "|---|---|---|"]
    for key, vals in (("all", [None]), ("controller", CONTROLLERS), ("excitation", EXCITATIONS), ("rate_hz", RATES)):
        for val in vals:
            sel = nulls if val is None else [r for r in nulls if r[key] == val]
            k = sum(bool(r["findings"]) for r in sel)
            c = sum(r["verdict"] == "consistent" for r in sel)
            lines.append(f"| {'all' if val is None else f'{key} {val:g}' if isinstance(val, float) else f'{key} {val}'} | "
                         f"{_rate(k, len(sel))} | {_rate(c, len(sel))} |")  # fmt: skip
    if nulls and "frf_ran" in nulls[0]:
        ran = [r for r in nulls if r.get("frf_ran")]
        lines += ["", f"Frequency-domain path above the rows' band: compared on {len(ran)}/{len(nulls)} nulls (the rest "
                  f"have no input power above the band); a mode named there on {_rate(sum(bool(r['frf_findings']) for r in ran), len(ran))}; "
                  f"its held-out check failed on {_rate(sum(r.get('frf_failed', False) for r in ran), len(ran))}."]  # fmt: skip
    named: dict = {}
    for r in nulls:
        for f in r["findings"]:
            named[f] = named.get(f, 0) + 1
    if named:
        lines += ["", "Named on nulls: " + ", ".join(f"`{k}` {v}" for k, v in sorted(named.items(), key=lambda x: -x[1]))]
    lines += ["", f"| family (size is) | expected name | sizes | recordings with effect >= {100 * EFFECT_MIN:.0f} % | "
              "detected there | detected, all sizes | right verdict | the floor's measure: >= 20 %, detected there |",
              "|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for name, fam in FAMILIES.items():
        if name == "null":
            continue
        rs = [r for r in ok if r["family"] == name]
        if not rs:
            continue
        big = [r for r in rs if effect(r) >= EFFECT_MIN]
        big0 = [r for r in rs if effect_vs_floor(r) >= EFFECT_MIN]
        hit = (lambda r: named_right(r)) if fam.expect else (lambda r: not r["findings"])
        right = sum(r["verdict"] in r["verdicts"] for r in rs)
        lines.append(f"| `{name}` ({fam.what}) | {fam.expect or '(none)'}{' ' + fam.also if fam.also else ''} | {', '.join(f'{s:g}' for s in fam.sizes)} | "
                     f"{len(big)}/{len(rs)} | {_rate(sum(map(hit, big)), len(big))} | {sum(map(hit, rs))}/{len(rs)} | "
                     f"{right}/{len(rs)} | {len(big0)}/{len(rs)}: {sum(map(hit, big0))}/{len(big0)} |")  # fmt: skip
    lines += ["", f"| excitation | effect recordings with effect >= {100 * EFFECT_MIN:.0f} % | detected |", "|---|---|---|"]
    for exc in EXCITATIONS:
        sel = [r for r in ok if r["family"] != "null" and FAMILIES[r["family"]].expect and r["excitation"] == exc
               and effect(r) >= EFFECT_MIN]  # fmt: skip
        lines.append(f"| {exc} | {len(sel)} | {_rate(sum(map(named_right, sel)), len(sel))} |")
    twin_failed = [r for r in ok if "twin_error" in r]
    if twin_failed:
        lines += ["", f"{len(twin_failed)} effect recordings' twins failed to diagnose; their effect is the floor's "
                  "measure."]  # fmt: skip
    errs = [r for r in runs if "error" in r]
    if errs:
        lines += ["", f"{len(errs)} recordings failed to diagnose: " + "; ".join(sorted({r['error'] for r in errs}))[:600]]
    return "\n".join(lines) + "\n"


def _loop(r: dict) -> str:
    return "open" if r.get("controller") in ("open", "force") else "closed"


def _colour(r: dict) -> str:
    return "white" if r.get("noise", "white") == "white" else "coloured"


def _is_null(r: dict) -> bool:
    return r.get("null", r["family"] == "null")


def _wrong(r: dict) -> bool:
    """Whether a diagnosed record names anything its truth does not accept."""
    ok = () if _is_null(r) or r.get("expect") is None and "accept" not in r else names_accepted(r)
    return any(f not in ok for f in r["findings"])


def tables_kinds(runs: list, label: str = "family") -> str:
    """The second grid's tables (module doc): nulls per cell, families, family x
    excitation, family x loop, family x noise, and the effect recordings by loop,
    noise and excitation.  A refused recording (the
    diagnosis raised) is counted as refused and is never ``consistent``; a recording
    the generator could not make is left out and listed."""
    unmade = [r for r in runs if r.get("error", "").startswith("FloatingPointError: proving ground")]
    runs = [r for r in runs if r not in unmade]  # the generator's failures are no diagnosis's
    done = [r for r in runs if "error" not in r]
    nulls = [r for r in runs if _is_null(r)]
    lines = ["| nulls: loop, excitation, noise | recordings | refused | `consistent` | false alarm (any finding) | "
             "verdicts |", "|---|---|---|---|---|---|"]  # fmt: skip
    keys = sorted({(_loop(r), r.get("excitation", "-"), _colour(r)) for r in nulls})
    groups = [("all", nulls)]
    groups += [(f"{lo} loop", [r for r in nulls if _loop(r) == lo]) for lo in ("closed", "open")]
    groups += [(f"{c} noise", [r for r in nulls if _colour(r) == c]) for c in KIND_NOISES]
    groups += [(f"excitation {e}", [r for r in nulls if r.get("excitation") == e])
               for e in sorted({r.get("excitation", "-") for r in nulls})]  # fmt: skip
    groups += [(f"{lo}, {e}, {c}", [r for r in nulls if (_loop(r), r.get("excitation", "-"), _colour(r)) == (lo, e, c)])
               for lo, e, c in keys]  # fmt: skip
    for name, sel in groups:
        if not sel:
            continue
        ok = [r for r in sel if "error" not in r]
        seen: dict = {}
        for r in ok:
            seen[r["verdict"]] = seen.get(r["verdict"], 0) + 1
        lines.append(f"| {name} | {len(sel)} | {len(sel) - len(ok)} | "
                     f"{_rate(sum(r['verdict'] == 'consistent' for r in ok), len(sel))} | "
                     f"{_rate(sum(bool(r['findings']) for r in ok), len(ok))} | "
                     f"{', '.join(f'{k} {v}' for k, v in sorted(seen.items()))} |")  # fmt: skip
    named: dict = {}
    for r in nulls:
        for f in r.get("findings", []):
            named[f] = named.get(f, 0) + 1
    if named:
        lines += ["", "Named on nulls: " + ", ".join(f"`{k}` {v}" for k, v in sorted(named.items(), key=lambda x: -x[1]))]
    eff = [r for r in runs if not _is_null(r)]
    big = [r for r in done if not _is_null(r) and effect(r) >= EFFECT_MIN]
    lines += ["", f"| {label} | expected name | recordings | refused | effect >= {100 * EFFECT_MIN:.0f} % | detected there | "
              "`consistent` there | right verdict (diagnosed) | wrong names (diagnosed) | names given |",
              "|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    fams = list(dict.fromkeys(r["family"] for r in eff))
    for name in fams:
        rs = [r for r in eff if r["family"] == name]
        ok = [r for r in rs if "error" not in r]
        b = [r for r in big if r["family"] == name]
        expect = rs[0].get("expect") or "(none)"
        if "accept" in rs[0]:
            expect = ", ".join(rs[0]["accept"]) or "(none)"
        given: dict = {}
        for r in ok:
            for f in r["findings"]:
                given[f] = given.get(f, 0) + 1
        right = sum(r["verdict"] in r["verdicts"] for r in ok)
        lines.append(f"| `{name}` | {expect} | {len(rs)} | {len(rs) - len(ok)} | {len(b)} | "
                     f"{_rate(sum(map(named_right, b)), len(b)) if names_accepted(rs[0]) else '- (no name due)'} | "
                     f"{_rate(sum(r['verdict'] == 'consistent' for r in b), len(b))} | {right}/{len(ok)} | {_rate(sum(map(_wrong, ok)), len(ok))} | "
                     f"{', '.join(f'{k} {v}' for k, v in sorted(given.items(), key=lambda x: -x[1])) or '-'} |")  # fmt: skip
    excs = sorted({r.get("excitation", "-") for r in eff})
    for what, key, values in (("excitation", lambda r: r.get("excitation", "-"), excs),
                              ("loop", _loop, [v for v in ("closed", "open") if any(_loop(r) == v for r in eff)]),
                              ("noise", _colour, [v for v in KIND_NOISES if any(_colour(r) == v for r in eff)])):  # fmt: skip
        if len(values) < 2:
            continue
        lines += ["", f"Detected / `consistent` where the effect is >= {100 * EFFECT_MIN:.0f} %, per {label} and {what} "
                  "(k/n: n the recordings with such an effect there):", "",
                  f"| {label} | " + " | ".join(values) + " |", "|---|" + "---|" * len(values)]  # fmt: skip
        for name in fams:
            cells = []
            for val in values:
                b = [r for r in big if r["family"] == name and key(r) == val]
                cells.append(f"{sum(map(named_right, b))}/{len(b)} detected, {sum(r['verdict'] == 'consistent' for r in b)} "
                             "consistent" if b else "-")  # fmt: skip
            lines.append(f"| `{name}` | " + " | ".join(cells) + " |")
    lines += ["", f"| effect recordings, effect >= {100 * EFFECT_MIN:.0f} % | recordings | detected | `consistent` "
              "(must be 0) | wrong names |", "|---|---|---|---|---|"]  # fmt: skip
    sub = [("all", big)]
    sub += [(f"{lo} loop", [r for r in big if _loop(r) == lo]) for lo in ("closed", "open")]
    sub += [(f"{c} noise", [r for r in big if _colour(r) == c]) for c in KIND_NOISES]
    sub += [(f"excitation {e}", [r for r in big if r.get("excitation") == e]) for e in excs]
    for name, sel in sub:
        if sel:
            lines.append(f"| {name} | {len(sel)} | {_rate(sum(map(named_right, sel)), len(sel))} | "
                         f"{_rate(sum(r['verdict'] == 'consistent' for r in sel), len(sel))} | "
                         f"{_rate(sum(map(_wrong, sel)), len(sel))} |")  # fmt: skip
    twin_failed = [r for r in done if "twin_error" in r]
    if twin_failed:
        lines += ["", f"{len(twin_failed)} effect recordings' twins were refused; their effect is the floor's measure "
                  "(`1 - 1/base_ratio`)."]  # fmt: skip
    errs = [r for r in runs if "error" in r]
    if errs:
        why: dict = {}
        for r in errs:
            k = r["error"].split(":")[0] + ": " + r["error"].split(":", 1)[-1].strip()[:60]
            why[k] = why.get(k, 0) + 1
        lines += ["", f"{len(errs)} of {len(runs)} recordings refused: " +
                  "; ".join(f"{v} x {k}" for k, v in sorted(why.items(), key=lambda x: -x[1]))]  # fmt: skip
    if unmade:
        lines += ["", f"{len(unmade)} recordings the generator could not make (left out above): " +
                  "; ".join(r["error"][:160] for r in unmade)]  # fmt: skip
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    from servo.fleet.runner import Progress, Where, describe, map_batches
    from servo.io.progress import Reporter, reporting

    ap = argparse.ArgumentParser(prog="python -m studies.proving.study", description=__doc__.splitlines()[0])
    ap.add_argument("--nulls", type=int, default=240, help="null recordings (default 240)")
    ap.add_argument("--seeds", type=int, default=8, help="recordings per family and size (default 8)")
    ap.add_argument("--families", help="comma list (default all)")
    ap.add_argument("--seed-offset", type=int, default=0,
                    help="added to every seed: develop on an offset (e.g. 40000), score on 0")
    ap.add_argument("--workers", "--jobs", type=int, dest="workers",
                    help="local Dask worker processes (default: one per CPU; 0: this process)")
    ap.add_argument("--scheduler", metavar="tcp://HOST:PORT", help="run on this existing Dask cluster")
    ap.add_argument("--excitation-as-r", action="store_true",
                    help="closed loops' recordings carry their injected excitation as r, the frequency path's "
                         "instrument (default: no r, H1)")
    ap.add_argument("--grid", choices=("combos", "kinds"), default="combos",
                    help="combos: the first study's controllers, excitations and rates (default); kinds: the second "
                         "grid, loop x excitation x noise (module doc)")
    ap.add_argument("--out", default="proving-study")
    a = ap.parse_args(argv)
    fams = a.families.split(",") if a.families else [f for f in FAMILIES if f != "null"]
    unknown = [f for f in fams if f not in FAMILIES]
    if unknown:
        ap.error(f"--families: unknown {', '.join(unknown)} (known: {', '.join(FAMILIES)})")
    if a.grid == "kinds" and a.excitation_as_r:
        ap.error("--excitation-as-r is for the first grid")
    if a.grid == "kinds":
        jobs = kind_jobs(fams, a.nulls, a.seeds, a.seed_offset)
    else:
        jobs = [("null", 0.0, 50_000 + a.seed_offset + s) for s in range(a.nulls)]
        jobs += [(f, size, 60_000 + a.seed_offset + s) for f in fams for size in FAMILIES[f].sizes
                 for s in range(a.seeds)]  # fmt: skip
    if a.excitation_as_r:
        jobs = [(*j, True) for j in jobs]
    where = Where(a.scheduler, a.workers)
    t0 = time.time()
    with reporting(Reporter("studies.proving.study")) as reporter:
        runs = map_batches(run_batch, jobs, where, BATCH, Progress(reporter, len(jobs), "diagnoses"), failed_batch)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    text = tables_kinds(runs) if a.grid == "kinds" else tables(runs)
    write_json(out / "study.json", runs)
    atomic_write(out / "study.md", lambda tmp: Path(tmp).write_text(text))
    print(text)
    print(f"{len(runs)} recordings on {describe(where, len(jobs))} in {time.time() - t0:.0f} s; wrote {out}/study.json, "
          f"{out}/study.md")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
