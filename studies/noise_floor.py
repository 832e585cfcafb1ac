"""The sensor-noise floor against the truth on the proving ground's nulls.

    python -m studies.noise_floor --seeds 11,12

For every loop (closed ``pdi``, open ``force``), excitation (multisine, PRBS, chirp,
steps) and noise colour (white, pink, low-pass) of :mod:`studies.proving.cases`, and
each seed: the rows' noise floor (the true inertia times the std of a row of the
acceleration chain) from the diagnosis's estimate (:mod:`servo.diagnose.noise`) and from
the former one (what the Butterworth removes, taken as white), each over the floor the
recording's own noise sequence gives through the same chain; and the in-band figure,
the estimated noise through the position's Butterworth (the bristle and Dahl lengths'
floor, :func:`servo.physics.stribeck.resolvable_length`) over the true noise through it,
at decimation 10 and 3 (the smallest the band chooser tries; the spectrum is read from
``0.4*fs/q`` up).  Prints a Markdown table (docs/studies/2026-11-28-noise-floor.md,
docs/studies/2026-11-28-coloured-nulls.md).
"""
from __future__ import annotations

import argparse

import numpy as np

import studies.proving.integrate as ig
from servo.diagnose.band import settings_for
from servo.diagnose.signals import make_signals, second_difference
from servo.diagnose.verdict import acceleration_noise_gain
from studies.proving.cases import Case, recording, trajectories

FS = 5000.0
LOOPS = ("pdi", "force")
EXCITATIONS = ("multisine", "prbs", "chirp", "steps")
COLOURS = ("white", "pink", "lowpass")


def former_sigma(sig) -> float:
    """The former position noise (m): the robust std of what the Butterworth removes,
    scaled for the part of the band it keeps (white)."""
    s = sig.settings
    fs = 1.0 / sig.dt
    frac = min(s.cutoff(fs) / (fs / 2), 0.5)
    hp = (sig.x - sig.xf)[s.trim_start : sig.n - s.trim_end]
    return float(1.4826 * np.median(np.abs(hp - np.median(hp))) / np.sqrt(1.0 - frac))


def one(loop: str, excitation: str, colour: str, seed: int, q: int = 10) -> dict:
    """Both estimates over the truth for one null (module doc)."""
    case = Case("null", 0.0, loop, excitation, FS, 30000, colour)
    rec, _ = recording(case, seed)
    tr = trajectories(case, seed)
    sig = make_signals(rec, settings_for(q, FS, None))
    n = tr["p"][ig.P_NOISE] * tr["noise"]
    true = float(np.std(sig.rows(second_difference(sig.butter(n), sig.dt))))
    g = acceleration_noise_gain(sig.settings, FS)
    return {"new": sig.noise_x * g / true, "old": former_sigma(sig) * g / true,
            "beta": None if sig.noise is None else sig.noise.beta, "in_band": in_band(sig, n)}  # fmt: skip


def in_band(sig, n) -> float | None:
    """The estimated noise through the position's Butterworth over the true noise ``n``
    (m, (n,)) through it; None without a spectrum."""
    from servo.physics.stribeck import _butter_impulse

    if sig.noise is None:
        return None
    s = sig.settings
    h = _butter_impulse(int(s.butter_order), float(s.cutoff(FS) / (FS / 2)))
    return sig.noise.std_through(h, FS) / float(np.std(sig.butter(n)[s.trim_start : sig.n - s.trim_end]))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m studies.noise_floor", description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="11,12", help="comma list of seeds (default 11,12)")
    a = ap.parse_args(argv)
    seeds = [int(s) for s in a.seeds.split(",")]
    print("| loop | excitation | noise | former / true | new / true | fitted slope beta | in band / true, q = 10 | q = 3 |")
    print("|---|---|---|---|---|---|---|---|")
    worst_new, worst_old, worst_band = 1.0, 1.0, 1.0
    for loop in LOOPS:
        for exc in EXCITATIONS:
            for colour in COLOURS:
                rs = [one(loop, exc, colour, s) for s in seeds]
                old = [r["old"] for r in rs]
                new = [r["new"] for r in rs]
                worst_new = max(worst_new, *(max(x, 1 / x) for x in new))
                worst_old = max(worst_old, *(max(x, 1 / x) for x in old))
                betas = ", ".join("-" if r["beta"] is None else f"{r['beta']:.2f}" for r in rs)
                band = [[r["in_band"] for r in rs], [one(loop, exc, colour, s, q=3)["in_band"] for s in seeds]]
                worst_band = max(worst_band, *(max(x, 1 / x) for b in band for x in b if x is not None))
                cols = [", ".join("-" if x is None else f"{x:.2f}" for x in b) for b in band]
                print(f"| {loop} | {exc} | {colour} | {', '.join(f'{x:.2f}' for x in old)} | "
                      f"{', '.join(f'{x:.2f}' for x in new)} | {betas} | {cols[0]} | {cols[1]} |")  # fmt: skip
    print(f"\nworst factor off the truth: former {worst_old:.2f}, new {worst_new:.2f}; in band {worst_band:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
