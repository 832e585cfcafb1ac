"""The ``servo bode`` job: sweeps at every level, with and without the compensator, on the
configured drive and (optionally) on the second drive; CSV, frequency responses, PNGs,
summary.

Files: ``bode.csv`` (one row per point: drive, compensation, level_A, f_hz, mag_db,
phase_deg, re, im, std, coherence, x_amp_m), ``frd.npz`` (every sweep, labelled, in the
version-independent format of :mod:`servo.io.frequency_response`:
``load_frequency_responses("frd.npz")[label].to_control()`` is a
``control.FrequencyResponseData``),
``bode_uncompensated.png``, ``bode_compensated.png`` (and ``bode_drive2_*.png``),
``summary.json``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from servo.config import Config
from servo.experiments.bode import SweepSettings, check_holding_loop, sweep
from servo.experiments.bode_analysis import band_max, linearity, loop_delay, resonance, second_drive
from servo.experiments.bode_plots import plot_bode
from servo.io.atomic import write_json
from servo.io.frequency_response import save_npz
from servo.io.progress import QUIET, current
from servo.io.provenance import or_default
from servo.io.runlog import write_csv


def run_sweeps(cfg: Config, s: SweepSettings, drives: dict, progress: bool = True) -> dict:
    """All sweeps: ``{(drive, compensation): [Sweep per level]}``.  Reports the
    frequencies done, and the sweep in hand, to the current progress reporter
    (:mod:`servo.io.progress`; ``progress=False``: not even there)."""
    rep = current() if progress else QUIET
    out, n_sweeps, done = {}, len(drives) * 2 * len(s.levels), 0
    rep.stage("Bode sweeps", n_sweeps * s.n_freq, "frequencies")
    for name, c in drives.items():
        for comp in (False, True):
            out[(name, comp)] = []
            for level in s.levels:
                what = f"sweep {done + 1}/{n_sweeps}: {name}, compensation {'on' if comp else 'off'}, {level * 1e3:g} mA"
                rep.update(done * s.n_freq, what)
                out[(name, comp)].append(sweep(c, level, s, comp, lambda i, n, k=done: rep.update(k * s.n_freq + i)))
                done += 1
    return out


def run_bode(cfg: Config, out: Path, s: SweepSettings, with_second: bool = True, progress: bool = True,
             provenance: dict | None = None) -> dict:  # fmt: skip
    """Every sweep, then the files of the module docstring into ``out``; returns the
    summary (``provenance`` recorded as given)."""
    drives = {"drive": cfg}
    if with_second:
        drives["drive2"] = second_drive(cfg)
    for name, c in drives.items():
        check_holding_loop(c, name="the second drive" if name == "drive2" else "the drive")
    res = run_sweeps(cfg, s, drives, progress)
    out.mkdir(parents=True, exist_ok=True)
    rows, responses = [], {}
    for (name, comp), sweeps in res.items():
        for sw in sweeps:
            for i in range(len(sw.f)):
                rows.append([0.0 if name == "drive" else 2.0, float(comp), sw.level, sw.f[i], sw.mag_db[i], sw.phase_deg[i],
                             sw.H[i].real, sw.H[i].imag, sw.std[i], sw.coherence[i], sw.x_amp[i]])  # fmt: skip
            responses[f"{name}, {sw.label}"] = sw.response()
    write_csv(out / "bode.csv", ["drive", "compensation", "level_A", "f_hz", "mag_db", "phase_deg", "re", "im", "std",
                                 "coherence", "x_amp_m"], np.array(rows))  # fmt: skip
    save_npz(out / "frd.npz", responses)
    band = band_max(cfg)
    files = ["bode.csv", "frd.npz"]
    titles = {
        ("drive", False): "Frequency response without compensation (paper Fig. 7)",
        ("drive", True): "Frequency response with compensation (paper Fig. 8)",
        ("drive2", False): "Second drive, without compensation (paper Fig. 9)",
        ("drive2", True): "Second drive, nominal compensator not retuned (paper Fig. 10)",
    }
    for (name, comp), sweeps in res.items():
        fn = f"bode_{'' if name == 'drive' else 'drive2_'}{'compensated' if comp else 'uncompensated'}.png"
        shade = band < s.f_max
        plot_bode(sweeps, out / fn, titles[(name, comp)] + (f"; shaded: band below {band:g} Hz" if shade else ""), band)
        files.append(fn)
    summary = {
        "settings": {**s.__dict__, "levels": list(s.levels)},
        "band_hz": band,
        "resonance_uncompensated": [resonance(sw, delay_s=loop_delay(cfg)) for sw in res[("drive", False)]],
        "resonance_compensated": [resonance(sw, delay_s=loop_delay(cfg)) for sw in res[("drive", True)]],
        "linearity_uncompensated": linearity(res[("drive", False)], band),
        "linearity_compensated": linearity(res[("drive", True)], band),
    }
    if with_second:
        summary["drive2"] = {
            "resonance_uncompensated": [resonance(sw, delay_s=loop_delay(cfg)) for sw in res[("drive2", False)]],
            "resonance_compensated": [resonance(sw, delay_s=loop_delay(cfg)) for sw in res[("drive2", True)]],
            "linearity_uncompensated": linearity(res[("drive2", False)], band),
            "linearity_compensated": linearity(res[("drive2", True)], band),
        }
    summary["low_coherence_points"] = {
        f"{name}, compensation {'on' if comp else 'off'}": int(sum(np.count_nonzero(sw.coherence < 0.9) for sw in sweeps))
        for (name, comp), sweeps in res.items()
    }
    summary["provenance"] = or_default(provenance, cfg)
    summary["files"] = sorted(files + ["summary.json"])
    write_json(out / "summary.json", summary)
    return summary


def _lin_line(name: str, lin: dict) -> str:
    slopes = ", ".join(f"{v:.2f}" for v in lin["slope_db_per_decade"].values())
    return (f"  {name}: spread across levels {lin['spread_db_max']:.2f} dB max (at {lin['spread_worst_hz']:.0f} Hz), "
            f"{lin['spread_db_rms']:.2f} dB RMS, within 1 dB above {lin['spread_below_1db_above_hz']:.0f} Hz; "
            f"slopes {slopes} dB/decade; phase {lin['phase_deg_min']:.1f} .. {lin['phase_deg_max']:.1f} deg")  # fmt: skip


def format_summary(summary: dict, out: Path) -> str:
    """The human summary ``servo bode`` prints."""
    b = summary["band_hz"]
    lines = [f"servo bode: {len(summary['settings']['levels'])} levels x {summary['settings']['n_freq']} frequencies "
             f"({summary['settings']['f_min']:g}-{summary['settings']['f_max']:g} Hz), VCM current -> position, PI holding loop"]  # fmt: skip
    lines.append("  without compensation (Fig. 7): equivalent resonance and damping per level")
    for r in summary["resonance_uncompensated"]:
        lines.append(f"    {r['level_A'] * 1e3:>7.3g} mA: f_n {r['f_n_hz']:6.1f} Hz, zeta {r['zeta']:.3f} "
                     f"(magnitude peak at {r['peak_hz']:.0f} Hz)")  # fmt: skip
    kc = [r["k_A_per_m"] for r in summary["resonance_compensated"]]
    lines.append(f"  with compensation: equivalent stiffness per level {', '.join(f'{k:.1f}' for k in kc)} A/m")
    lines.append(f"  band below the first flexible mode: up to {b:g} Hz")
    lines.append(_lin_line("without compensation", summary["linearity_uncompensated"]))
    lines.append(_lin_line("with compensation (Fig. 8)", summary["linearity_compensated"]))
    if "drive2" in summary:
        d2 = summary["drive2"]
        u, c = d2["linearity_uncompensated"]["spread_db_max"], d2["linearity_compensated"]["spread_db_max"]
        lines.append("  second drive, same compensator not retuned (Fig. 9-10):")
        lines.append("  " + _lin_line("without compensation", d2["linearity_uncompensated"]))
        lines.append("  " + _lin_line("with compensation", d2["linearity_compensated"]))
        ur, cr = d2["linearity_uncompensated"]["spread_db_rms"], d2["linearity_compensated"]["spread_db_rms"]
        ku = [r["k_A_per_m"] for r in d2["resonance_uncompensated"]]
        kc = [r["k_A_per_m"] for r in d2["resonance_compensated"]]
        lines.append(f"    equivalent stiffness k per level (A/m): without {', '.join(f'{k:.0f}' for k in ku)}; "
                     f"with {', '.join(f'{k:.0f}' for k in kc)}: range {max(kc) - min(kc):.0f} of {max(ku) - min(ku):.0f} A/m "
                     f"left ({100 * (max(kc) - min(kc)) / (max(ku) - min(ku)):.0f} %)")  # fmt: skip
        lines.append(f"    nonlinearity left: level spread {c:.2f} dB max / {cr:.2f} dB RMS, against {u:.2f} / {ur:.2f} dB "
                     f"without compensation ({100 * cr / ur:.0f} % of the RMS spread left)")
    low = {k: v for k, v in summary.get("low_coherence_points", {}).items() if v}
    lines.append("  points with coherence < 0.9: " + (", ".join(f"{k}: {v}" for k, v in low.items()) if low else "none"))
    lines.append(f"  wrote {out}/: " + ", ".join(summary["files"]))
    return "\n".join(lines)


__all__ = ["format_summary", "run_bode", "run_sweeps"]
