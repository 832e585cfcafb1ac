"""The benchmark's evaluation of a :class:`~servo.design.design.Design`, linear and
independent of the project's runtime: ``python -m studies.hdd.evaluate``.

For every perturbed plant (54 in version 2: 18 mechanical x 3 force constants): the
exact multirate open loop at the PES rate (:func:`servo.design.loop.open_loop`): closed-loop
stability, then for a stable loop its margins (:func:`servo.design.margins.margins`: the
binding gain margin, phase margin at the lowest crossover, max|S|); then, if
stable, the PES of a linear simulation of the loop over the benchmark's 1000 revolutions
with its disturbances (:mod:`servo.hdd.linsim`; the same disturbance record for every
plant, as the benchmark does), the first 10 ms ignored, and its figures
(:mod:`servo.hdd.pes`): RRO peak-to-peak and NRRO 3 sigma in tracks; beside them the
stationary NRRO 3 sigma the disturbance models imply (Lyapunov), which the simulation
estimates.

    python -m studies.hdd.evaluate [--version 2] [--revolutions 1000] [--seed 0]
                                   [--designs reference,own] [--package DIR] [--out DIR]

prints the table of ``docs/hdd.md``; ``--package``: a copy of the benchmark package,
whose written-in runout ``RROSequence.mat`` joins the RRO (without it: the three
harmonics alone); ``--out`` (new or empty) also writes
``evaluation.json`` and ``pes_<design>.png`` (the nominal plant's PES figures).
"""
from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from servo.design import loop
from servo.design.design import Design
from servo.hdd import designs, linsim
from servo.hdd.benchmark import Benchmark, benchmark
from servo.hdd.disturbances import Disturbances, generate
from servo.hdd.pes import PesFigures, pes_figures
from servo.hdd.plant import plants


@dataclass
class PlantResult:
    """One perturbed plant: ``margins`` (:func:`servo.design.loop.margins`), and when
    stable the PES ``figures`` (tracks), the stationary NRRO (``theory``: 1 sigma, m, by
    source) and the steady RRO peak-to-peak (``rro_pp_theory``, tracks)."""

    name: str
    margins: dict
    figures: PesFigures | None = None
    theory: dict | None = None
    rro_pp_theory: float = math.nan

    def row(self) -> dict:
        m = self.margins
        out = dict(plant=self.name, stable=m["stable"], pole_radius=m["pole_radius"],
                   gain_margin_db=m["gain_margin_db"], gain_margin_side=m["gain_margin_side"],
                   gain_margin_upper_db=m["gain_margin_upper_db"], gain_margin_lower_db=m["gain_margin_lower_db"],
                   phase_margin_deg=m["phase_margin_deg"], crossover_hz=m["crossover_hz"],
                   delay_margin_s=m["delay_margin_s"], max_S_db=m["max_S_db"], max_S_hz=m["max_S_hz"],
                   max_T_db=m["max_T_db"])  # fmt: skip
        if self.figures is not None:
            out.update(rro_pp=self.figures.rro_pp, nrro_3sigma=self.figures.nrro_3sigma, sigma3=self.figures.sigma3,
                       nrro_3sigma_theory=3 * self.theory["total"] / TP, rro_pp_theory=self.rro_pp_theory)  # fmt: skip
        return out


TP = 2.54e-7  # overwritten per benchmark in evaluate(); both versions share it


def evaluate_plant(design: Design, bench: Benchmark, name: str, plant, dist: Disturbances, U,
                   margin_points: int = 20000) -> PlantResult:
    """:class:`PlantResult` of ``design`` on one plant under the disturbance record ``U``."""
    m = loop.margins(loop.open_loop(design, plant, bench.Td), n=margin_points)
    res = PlantResult(name, m)
    if not m["stable"]:
        return res
    cl = linsim.closed_loop(design, plant, bench.Td)
    pes = linsim.simulate(cl, U) / bench.Tp
    skip = int(math.ceil(bench.skip_s / bench.Ts))
    res.figures = pes_figures(pes, bench.sectors, 1.0 / bench.Ts, skip=skip, hist_range=0.5)
    res.theory = linsim.stationary_nrro(cl, bench, dist)
    rro = linsim.rro_response(cl, bench, dist, 1.0 / bench.Ts) / bench.Tp
    res.rro_pp_theory = float(rro.max() - rro.min())
    return res


def evaluate(design: Design, version: int = 2, revolutions: int | None = None, seed: int = 0,
             with_kf: bool = True, only: int | None = None, margin_points: int = 20000, package=None) -> dict:  # fmt: skip
    """Evaluate ``design`` on every perturbed plant of the benchmark (``only``: the first
    ``only`` plants; ``margin_points``: the margins' frequency grid; ``package``: the
    benchmark package's folder, for its written-in runout).  Returns ``{"plants": [PlantResult...], "summary": {...}}`` where the
    summary holds mean and worst RRO p-p and NRRO 3 sigma (tracks) over the plants, the
    number unstable, and the smallest margins."""
    bench = benchmark(version)
    if abs(design.fs_pes * bench.Ts - 1) > 1e-9:
        raise ValueError(f"the design's PES rate {design.fs_pes:g} Hz is not the benchmark's {1 / bench.Ts:g} Hz")
    revs = bench.revolutions if revolutions is None else int(revolutions)
    dist = generate(revs * bench.sectors * design.pes_every, version, seed, design.fs, package=package)
    U = linsim.inputs(dist)
    results = [evaluate_plant(design, bench, name, p, dist, U, margin_points) for name, p in plants(bench, with_kf)[:only]]
    return dict(plants=results, summary=summarise(results))


def _least(results: list[PlantResult], key: str, size=lambda v: v) -> float:
    """The smallest (by ``size``) of a margin over the plants; inf when none has one."""
    vals = [r.margins[key] for r in results if r.margins[key] is not None]
    return float(min(vals, key=size)) if vals else math.inf


def summarise(results: list[PlantResult]) -> dict:
    """Mean and worst of the figures over the plants (NaN figures when any is unstable)."""
    ok = [r for r in results if r.figures is not None]
    rro = np.array([r.figures.rro_pp for r in ok])
    nrro = np.array([r.figures.nrro_3sigma for r in ok])
    pes = np.array([r.figures.sigma3 for r in ok])
    th = np.array([3 * r.theory["total"] / TP for r in ok])
    rth = np.array([r.rro_pp_theory for r in ok])
    unstable = len(results) - len(ok)
    nan = math.nan
    return dict(
        plants=len(results), unstable=unstable,
        rro_pp_mean=float(rro.mean()) if ok and not unstable else nan,
        rro_pp_worst=float(rro.max()) if ok and not unstable else nan,
        sigma3_mean=float(pes.mean()) if ok and not unstable else nan,
        sigma3_worst=float(pes.max()) if ok and not unstable else nan,
        nrro_3sigma_mean=float(nrro.mean()) if ok and not unstable else nan,
        nrro_3sigma_worst=float(nrro.max()) if ok and not unstable else nan,
        nrro_3sigma_theory_mean=float(th.mean()) if ok and not unstable else nan,
        rro_pp_theory_mean=float(rth.mean()) if ok and not unstable else nan,
        # margins exist for stable loops only: over the plants when all are stable
        gain_margin_db_min=_least(results, "gain_margin_db", abs) if not unstable else nan,
        gain_margin_upper_db_min=_least(results, "gain_margin_upper_db") if not unstable else nan,
        phase_margin_deg_min=_least(results, "phase_margin_deg") if not unstable else nan,
        max_S_db_worst=max(r.margins["max_S_db"] for r in results) if not unstable else nan,
        crossover_hz_nominal=results[0].margins["crossover_hz"] if results[0].margins["stable"] else nan,
    )  # fmt: skip


def table(named: dict) -> str:
    """Markdown table of the summaries ``{design name: evaluate(...)}`` (figures in % of a track)."""
    head = ("| design | unstable | PES 3σ mean | PES 3σ worst | RRO p-p mean | RRO p-p worst | NRRO 3σ mean | NRRO 3σ worst | NRRO 3σ theory mean "
            "| min GM (dB) | min PM (deg) | worst max\\|S\\| (dB) | crossover (Hz) |")
    out = [head, "|" + "---|" * 13]
    for name, ev in named.items():
        s = ev["summary"]
        pct = lambda v: f"{100 * v:.2f}" if np.isfinite(v) else "—"  # noqa: E731
        out.append(f"| {name} | {s['unstable']}/{s['plants']} | {pct(s['sigma3_mean'])} | {pct(s['sigma3_worst'])} "
                   f"| {pct(s['rro_pp_mean'])} | {pct(s['rro_pp_worst'])} "
                   f"| {pct(s['nrro_3sigma_mean'])} | {pct(s['nrro_3sigma_worst'])} | {pct(s['nrro_3sigma_theory_mean'])} "
                   f"| {s['gain_margin_db_min']:.2f} | {s['phase_margin_deg_min']:.1f} | {s['max_S_db_worst']:.1f} "
                   f"| {s['crossover_hz_nominal']:.0f} |")  # fmt: skip
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m studies.hdd.evaluate", description=__doc__.splitlines()[0])
    ap.add_argument("--version", type=int, default=2, choices=(1, 2))
    ap.add_argument("--revolutions", type=int, default=None, help="default: the benchmark's 1000")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--designs", default=None, help="comma-separated: reference, own (default: both; version 1: reference)")
    ap.add_argument("--package", default=None, help="folder of the benchmark package (its RROSequence.mat joins the RRO)")
    ap.add_argument("--out", default=None, help="folder (new or empty) for evaluation.json and PES plots")
    a = ap.parse_args(argv)
    try:
        spec = a.designs if a.designs is not None else ("reference,own" if a.version == 2 else "reference")
        names = [n.strip() for n in spec.split(",") if n.strip()]
        known = {"reference": designs.reference, "own": designs.own}
        bad = [n for n in names if n not in known]
        if bad or not names:
            raise ValueError(f"unknown design {', '.join(bad) or '(none)'}: choose from {', '.join(known)}")
        if a.revolutions is not None and a.revolutions < 3:
            raise ValueError("--revolutions must be >= 3")
        if a.out and Path(a.out).exists() and (not Path(a.out).is_dir() or any(Path(a.out).iterdir())):
            raise ValueError(f"{a.out}: exists and is not an empty folder")
        results = {n: evaluate(known[n](a.version), a.version, a.revolutions, a.seed, package=a.package) for n in names}
        rro = "with the written-in RRO" if a.package else "RRO: the three harmonics alone"
        print(f"NSS HDD benchmark v{a.version}, linear evaluation ({a.revolutions or 1000} revolutions, seed {a.seed}, "
              f"{rro}); figures in % of a track")  # fmt: skip
        text = table(results)
        print(text)
        if a.out:
            from studies.hdd.report import write_report

            write_report(a.out, results, vars(a), text)
    except (ValueError, OSError) as exc:
        print(f"servo: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
