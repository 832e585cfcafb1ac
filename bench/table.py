"""``python -m bench.table [results.json]``: the Markdown tables of ``bench/README.md``
from the results the benchmarks wrote (default ``bench/results/latest.json``)."""
from __future__ import annotations

import json
import sys
from pathlib import Path

from bench.conftest import RESULTS_DIR

#: (key in "figures", label, unit): unit "ns", "us" or "s" chooses how the figure prints.
ROWS = [
    ("controller_tick", "controller tick, compiled (Dahl + compensator + PI + limits)", "ns"),
    ("controller_tick_uncompensated", "controller tick, compensator off", "ns"),
    ("controller_tick_every_term", "controller tick, every compensator term on (issue 14)", "ns"),
    ("controller_tick_track", "controller tick, kind track (biquads at two rates) + compensator", "ns"),
    ("controller_tick_nss", "controller tick, kind nss (benchmark PID + notches) + compensator", "ns"),
    ("dahl_update_alpha_1", "Dahl update, alpha = 1", "ns"),
    ("dahl_update_alpha_1.5", "Dahl update, alpha = 1.5", "ns"),
    ("compensate", "compensator, eq. (9)", "ns"),
    ("holding_pi", "PI holding loop", "ns"),
    ("plant_step", "plant step (simulated drive)", "ns"),
    ("plant_measure", "plant sensor", "ns"),
    ("shift_in", "link command queue (3 ticks)", "ns"),
    ("closed_loop_kernels", "closed loop, kernels only (measure + tick + step)", "ns"),
    ("tick_path", "tick path: scheduler + driver interface + SimDriver, per tick", "us"),
    ("tick_path_every_term", "tick path, every compensator term on (issue 14; target 0.25 T)", "us"),
    ("fast_path", "fast path: all-compiled closed loop with logging, per sample", "ns"),
    ("first_tick", "first tick after configure (fresh `servo run`)", "us"),
    ("cold_start", "cold start of `servo run`: process start to first tick", "s"),
    ("controller_tick_c", "C reference: controller tick", "ns"),
    ("controller_tick_every_term_c", "C reference: controller tick, every compensator term on", "ns"),
    ("plant_step_c", "C reference: plant step", "ns"),
    ("closed_loop_c", "C reference: closed loop", "ns"),
    ("controller_tick_python", "pure Python: controller tick", "ns"),
]
RATIOS = [
    ("numba_over_c_controller_tick", "Numba / C, controller tick"),
    ("numba_over_c_controller_tick_every_term", "Numba / C, controller tick, every compensator term on"),
    ("every_term_over_paper_tick", "controller tick, every compensator term / the paper's terms"),
    ("numba_over_c_track_tick", "Numba / C, track-following tick"),
    ("numba_over_c_plant_step", "Numba / C, plant step"),
    ("numba_over_c_closed_loop", "Numba / C, closed loop"),
    ("tick_path_every_term_over_paper", "tick path, every compensator term / the paper's terms (rounds alternated)"),
    ("python_over_numba_controller_tick", "Python / Numba, controller tick"),
    ("cold_start_over_dependencies", "cold start / import of numba+numpy+scipy+matplotlib"),
    ("fast_path_over_c_with_logging", "fast path with its run log / C logging the same rows (loop thread's CPU)"),
    ("cold_start_over_import_floor", "`servo run` start to first tick / `import numpy, numba`"),
    ("diagnose_fixed_over_import_floor", "`servo diagnose` start to its recording read / `import numpy, numba`"),
    ("fleet_one_worker_over_in_process", "fleet: one Dask worker / in-process, time on an idle core (from CPU)"),
    ("fleet_in_process_over_two_workers", "fleet: in-process / two Dask workers, time on two idle cores (from CPU)"),
]


def _fmt(ns: float, unit: str) -> str:
    if unit == "s":
        return f"{ns / 1e9:.2f} s"
    if unit == "us":
        return f"{ns / 1e3:.1f} us"
    return f"{ns:.0f} ns" if ns >= 100 else f"{ns:.1f} ns"


def render(data: dict) -> str:
    period = data["period_ns"]
    out = ["| per sample (median) | measured | budget | share of the period |", "|---|---|---|---|"]
    for key, label, unit in ROWS:
        f = data["figures"].get(key)
        if f is None:
            continue
        value = _fmt(f["ns"], unit)
        if key == "fast_path":
            value += f" ({f['samples_per_s'] / 1e6:.2f} M samples/s, {f['real_time_factor']:.0f}x real time)"
        budget = _fmt(f["budget_ns"], unit) + f" ({f['fraction_of_period']:g} T)" if "budget_ns" in f else "-"
        share = f"{100 * f['ns'] / period:.2f} %" if unit != "s" else "-"
        out.append(f"| {label} | {value} | {budget} | {share} |")
    out += ["", "| ratio (same run, adjacent pairs) | measured | bound |", "|---|---|---|"]
    for key, label in RATIOS:
        r = data["ratios"].get(key)
        if r is not None:
            out.append(f"| {label} | {r['ratio']:.2f} | {r['bound']} |")
    c = data.get("c_reference") or {}
    m, v = data["machine"], data["versions"]
    out += [
        "",
        f"Measured {data['when']} on {m['cpu']} ({m['cores']} cores), Python {v['python']}, Numba {v['numba']}, "
        f"NumPy {v['numpy']}" + (f"; C: {c['version']}, `{' '.join(c['flags'])}`" if c else "; no C compiler")
        + f"; period T = {period / 1e3:g} us; command `{data['command']}`.",
    ]  # fmt: skip
    return "\n".join(out)


def main(argv: list[str]) -> int:
    path = Path(argv[0]) if argv else RESULTS_DIR / "latest.json"
    if not path.exists():
        print(f"bench.table: error: no results at {path}: run `python -m pytest bench` first", file=sys.stderr)
        return 2
    print(render(json.loads(path.read_text())))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
