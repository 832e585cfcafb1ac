"""The verdict of a diagnosis: does the model explain the recording to its noise?

A model's held-out force residual (each training block predicted by the fit on the
other blocks, the test part by the fit on the training part; usable rows only) is held
against the **noise floor** the recording itself implies: the position noise's spectrum
(read where the input drives nothing the model misses, :mod:`servo.diagnose.noise`)
goes through the acceleration path (Butterworth, second difference, the rows'
decimation filter) and the fitted inertia, ``floor = |J| * sigma_x * g`` with ``g`` the
2-norm of that chain's impulse response (:func:`acceleration_noise_gain`) and
``sigma_x`` the white noise of the same std through it (a coloured noise's own floor).  On null
recordings of both generators (nothing missing, position noise only) the held-out
residual is 1.00-1.05 times this floor.

Checks on one model (:func:`assess`), each a test at the diagnosis' level ``alpha``
with a practical margin (:data:`MARGIN`, 20 % in RMS) so that a statistically
detectable but negligible excess does not count:

* ``level``: the RMS of the whole held-out residual over the floor (chi-square with
  ``n/tau`` degrees of freedom, ``tau`` the residual's integrated autocorrelation time);
* ``windows``: the same per time window (:data:`N_WINDOWS`, Bonferroni over them): an
  effect present in only part of the recording shows here; read on the rows beyond the
  decimation filter's reach at :data:`LEAK_LEVEL` from the samples the rows cannot trust
  (:func:`window_rows`: a stick's misfit and the ends' filter transient leak into the
  first rows beside them);
* ``gap``: the test part against the training part's cross-validated residual
  (F test): a model that predicts the training part and fails the test part is a
  located mismatch, with the range of ``u``, ``x``, ``v`` and direction the test part
  reaches that training did not (:func:`ranges_beyond_training`);
* ``state``: bin means of the residual against position, velocity, direction and
  distance since reversal (:func:`servo.diagnose.locate.state_test`), their null
  covariance holding the training fit's error on the test part
  (:func:`estimation_error`: the test part is predicted by one fit, whose error is
  itself a structure against position where the test part reaches further);
* ``output``: the short-horizon simulated output does worse than coasting
  (NRMSE > 1);
* ``frf``: above the rows' band, the test part's frequency response departs from the
  model's (:mod:`servo.diagnose.frf_modes`, added by :func:`add_frf`; not failed when
  that path could not run, e.g. no input power above the band).

The verdict (:func:`decide`) is one of

* ``consistent``: the model as given (baseline) passes every check and nothing was found;
* ``explained``: the final model (baseline plus findings) passes every check;
* ``unexplained``: the final model fails a check; the text says where and by how much,
  and that no vocabulary term accounted for it;
* ``out_of_scope``: the recording is not described by the force balance the tool fits
  (no inertia significantly positive, or the fitted balance explains almost none of the
  force on its own training rows).
"""
from __future__ import annotations

import math

import numpy as np
from scipy import signal, stats

from servo.diagnose.locate import state_test
from servo.identify.regressors import matlab_decimate

VERDICTS = ("consistent", "explained", "unexplained", "out_of_scope")
#: verdict -> the status of its report page (:data:`servo.io.page.STATUS`)
PAGE_STATUS = {"consistent": "ok", "explained": "ok", "unexplained": "warn", "out_of_scope": "bad"}
#: a residual counts as above its floor (or the test part above training) only beyond
#: this RMS ratio, whatever the test says: 20 % more RMS is 44 % more power
MARGIN = 1.2
#: the same for one time window: on null recordings a window's residual varies more than
#: its chi-square predicts (the closed loop's power changes with the motion: up to 1.35 x
#: the floor over 20 windows of 20 null recordings), so a window must stand out further
WINDOW_MARGIN = 1.6
N_WINDOWS = 20
#: the ``windows`` check reads only rows whose decimation filter's response to every
#: direction-uncertain sample is below this fraction of its peak (27 rows at the default
#: settings, against the fits' 15 at 1 %, :data:`servo.diagnose.signals.REACH_LEVEL`):
#: the misfit of the uncertain samples (a stick, the friction a constraint force there)
#: reaches 150-380 x the floor on the development nulls, and 1 % of it, leaked into the
#: first usable rows beside a rest, made a short window of them read 1.6-1.9 x the floor
LEAK_LEVEL = 1e-3
#: the force balance is out of scope when the final model's held-out force error is at
#: least this (%): it explains under 10 % of the force's power
OUT_OF_SCOPE_PCT = 95.0
#: the fitted inertia must exceed this many of its standard deviations
J_SIGMAS = 5.0


def acceleration_noise_gain(settings, fs: float) -> float:
    """Std of an acceleration row per unit of white position noise (1/s^2): the 2-norm
    of the impulse response of Butterworth (zero-phase), second difference and the rows'
    decimation filter, summed over the ``q`` phases of the decimation."""
    from servo.diagnose.signals import second_difference

    q = settings.decimate
    b, a = signal.butter(settings.butter_order, settings.cutoff(fs) / (fs / 2))
    n = 400 * q + 1
    tot = 0.0
    for off in range(q):
        z = np.zeros(n)
        z[n // 2 + off] = 1.0
        h = second_difference(signal.filtfilt(b, a, z, padlen=3 * settings.butter_order), 1.0 / fs)
        r = matlab_decimate(h, q, settings.decimate_order, settings.decimate_ripple_db) if q > 1 else h
        tot += float(np.sum(np.asarray(r) ** 2))
    return math.sqrt(tot)


def force_floor(sig, J: float, noise_x: float | None = None) -> float:
    """Force-residual std (force unit) that the position noise alone produces: white, of
    std ``noise_x`` (m; default the rows' estimate ``sig.noise_x``)."""
    noise = sig.noise_x if noise_x is None else noise_x
    return abs(J) * noise * acceleration_noise_gain(sig.settings, 1.0 / sig.dt)


def _chi2_bound(n_eff: float, level: float) -> float:
    """RMS ratio a chi-square mean square with ``n_eff`` degrees of freedom exceeds with
    probability ``level``."""
    n_eff = max(n_eff, 1.0)
    return math.sqrt(stats.chi2.isf(level, n_eff) / n_eff)


def ranges_beyond_training(design, train: np.ndarray, test: np.ndarray) -> list:
    """What the test rows reach that the training rows did not: per variable (``u`` the
    aligned force, ``x``, ``v``, ``direction``) the share of test rows outside the
    training range and how far.  Only variables with at least 1 % of the test rows
    outside are listed."""
    from servo.diagnose.model import Model

    sig = design.sig
    u = design.target_raw(Model())
    out = []
    for name, vals, unit in (("u", u, "F"), ("x", sig.x_rows, "m"), ("v", sig.v_rows, "m/s")):
        lo, hi = float(vals[train].min()), float(vals[train].max())
        te = vals[test]
        beyond = (te < lo) | (te > hi)
        share = float(beyond.mean()) if te.size else 0.0
        if share >= 0.01:
            out.append({"variable": name, "unit": unit, "train_range": [lo, hi],
                        "test_range": [float(te.min()), float(te.max())], "share_of_test_rows": share})  # fmt: skip
    s_tr, s_te = np.sign(sig.v_rows[train]), np.sign(sig.v_rows[test])
    for d in (1.0, -1.0):
        if np.mean(s_te == d) >= 0.01 and not np.any(s_tr == d):
            out.append({"variable": "direction", "unit": "-", "train_range": None, "test_range": [d, d],
                        "share_of_test_rows": float(np.mean(s_te == d))})  # fmt: skip
    return out


def window_rows(sig) -> np.ndarray:
    """The rows (m,) the ``windows`` check reads: usable rows (``sig.valid``) beyond the
    decimation filter's reach at :data:`LEAK_LEVEL` from every sample the rows cannot
    trust: the direction-uncertain ones (``Signals.uncertain``, which the fits' rule
    keeps out at 1 %) and the samples trimmed at both ends, where the Butterworth's
    zero-phase padding leaves a transient that does not obey the force balance (the
    first row of a null read 9-19 x the floor)."""
    from servo.diagnose.signals import filter_reach, rows_clear_of

    uncertain = sig.uncertain.copy()
    st = sig.settings
    uncertain[: st.trim_start] = True  # the Butterworth's edge transient (module doc)
    if st.trim_end > 0:
        uncertain[sig.n - st.trim_end :] = True
    return sig.valid & rows_clear_of(sig.keep, uncertain, filter_reach(st, LEAK_LEVEL))


def window_checks(design, residual: np.ndarray, floor: float, tau: float, alpha: float,
                  usable: np.ndarray | None = None) -> list:  # fmt: skip
    """The ``windows`` check's windows (:data:`N_WINDOWS` over all rows): each
    ``{t0, t1, rows, ratio, bound, test_part, flagged}``, ``ratio`` the RMS of the
    ``rows`` ``usable`` rows (m,; default ``sig.valid``) of ``residual`` in it over
    ``floor``, flagged beyond ``bound`` (module doc).  A window with fewer than 5 usable
    rows is left out (the check's ``skipped`` counts them)."""
    sig = design.sig
    usable = sig.valid if usable is None else usable
    fl = max(floor, 1e-300)
    tau = max(float(tau), 1.0)
    edges = np.linspace(0, residual.size, N_WINDOWS + 1).astype(int)
    wins = []
    for a, b in zip(edges[:-1], edges[1:]):
        m = usable[a:b]
        n = int(m.sum())
        if n < 5:
            continue
        r = float(np.sqrt(np.mean(residual[a:b][m] ** 2))) / fl
        bw = max(WINDOW_MARGIN, _chi2_bound(n / tau, alpha / N_WINDOWS))
        wins.append({"t0": float(sig.t_rows[a]), "t1": float(sig.t_rows[b - 1]), "rows": n, "ratio": r, "bound": bw,
                     "test_part": bool(not design.train_rows[a]), "flagged": bool(r > bw)})  # fmt: skip
    return wins


def estimation_error(design, fit) -> tuple | None:
    """How the training fit's error reaches the test part's held-out residual: ``(E, C)``,
    ``E`` (m, p) the free columns of ``fit.model`` on the test rows (zero elsewhere) and
    ``C`` (p, p) the covariance of the coefficients fitted on the training rows
    (``fit.cov``, :func:`servo.diagnose.fit.fit_model`); None without free columns.  The
    test part is predicted by one fit whose error ``d`` adds ``E @ d`` to its rows: a
    structure against position or distance since reversal where the test part reaches
    further than training did, which the ``state`` check must not read as a misfit
    (module doc)."""
    _, Phi, _ = design.matrix(fit.model)
    if Phi.shape[1] == 0:
        return None
    return np.where((~design.train_rows)[:, None], Phi, 0.0), fit.cov


def assess(design, residual: np.ndarray, J: float, tau: float, variables: dict, alpha: float,
           output_nrmse: float | None, noise_x: float | None = None, estimation: tuple | None = None) -> dict:  # fmt: skip
    """The checks of the module doc on one model's held-out ``residual`` (m,) rows, against
    the floor of a position noise of std ``noise_x`` (m; default the rows' estimate);
    ``estimation``: the training fit's error on the test rows for the ``state`` check
    (:func:`estimation_error`; None: left out)."""
    sig = design.sig
    train = design.train_valid
    test = ~design.train_rows & sig.valid
    usable = sig.valid
    floor = force_floor(sig, J, noise_x)
    fl = max(floor, 1e-300)
    tau = max(float(tau), 1.0)

    def rms(mask):
        return float(np.sqrt(np.mean(residual[mask] ** 2))) if mask.any() else 0.0

    checks: dict = {}
    ratio = rms(usable) / fl
    bound = max(MARGIN, _chi2_bound(usable.sum() / tau, alpha))
    checks["level"] = {"rms": rms(usable), "floor": floor, "position_noise_m": sig.noise_x if noise_x is None else noise_x,
                       "ratio": ratio, "test_ratio": rms(test) / fl,
                       "train_ratio": rms(train) / fl, "bound": bound, "failed": bool(ratio > bound)}  # fmt: skip

    wins = window_checks(design, residual, floor, tau, alpha, window_rows(sig))
    flagged = [w for w in wins if w["flagged"]]
    checks["windows"] = {"windows": wins, "skipped": N_WINDOWS - len(wins), "flagged": [[w["t0"], w["t1"]] for w in flagged],
                         "failed": bool(flagged)}  # fmt: skip

    n_tr, n_te = train.sum() / tau, test.sum() / tau
    g = (rms(test) / max(rms(train), 1e-300)) if train.any() and test.any() else 1.0
    gb = max(MARGIN, math.sqrt(stats.f.isf(alpha, max(n_te, 1.0), max(n_tr, 1.0))))
    above = checks["level"]["test_ratio"] > MARGIN
    gap = {"ratio": g, "bound": gb, "failed": bool(g > gb and above)}
    if gap["failed"]:
        gap["beyond_training"] = ranges_beyond_training(design, train, test)
    checks["gap"] = gap

    st = state_test(residual, usable, tau, variables, alpha, estimation)
    hot = {k: v for k, v in st["variables"].items() if v["flagged"]}
    checks["state"] = {"flagged": sorted(hot), "p": {k: v["p"] for k, v in st["variables"].items()},
                       "bins": {k: [b for b in v["bins"] if b["flagged"]] for k, v in hot.items()},
                       "level_per_variable": st["level_per_variable"], "failed": bool(hot)}  # fmt: skip

    checks["output"] = {"nrmse": output_nrmse, "bound": 1.0,
                        "failed": bool(output_nrmse is not None and output_nrmse > 1.0)}  # fmt: skip
    checks["failed"] = [k for k in ("level", "windows", "gap", "state", "output") if checks[k]["failed"]]
    return checks


def add_frf(checks: dict, departure: dict | None, result) -> None:
    """The ``frf`` check (module doc) from the test part's departure test of the
    frequency-domain path (:func:`servo.diagnose.frf_modes.departure`, None when it did
    not run); ``checks["failed"]`` gets ``"frf"`` when it fails."""
    ran = bool(result is not None and result.ran and departure is not None)
    d = departure or {}
    failed = bool(ran and d.get("departs"))
    checks["frf"] = {"ran": ran, "band_hz": list(result.band_hz) if result is not None else [],
                     "bins": d.get("bins", 0), "flagged_hz": d.get("flagged_hz", []),
                     "flagged_bins": d.get("flagged_bins", 0), "worst_hz": d.get("worst_hz"),
                     "worst_rel": d.get("worst_rel"), "departures": d.get("departures", []), "failed": failed,
                     "note": "" if ran else (result.note if result is not None else "")}  # fmt: skip
    if failed:
        checks["failed"] = list(checks["failed"]) + ["frf"]


def _fmt_range(r: dict) -> str:
    if r["variable"] == "direction":
        return f"moving {'+' if r['test_range'][0] > 0 else '-'}, never seen in training ({100 * r['share_of_test_rows']:.0f} % of test rows)"
    lo, hi = r["train_range"]
    tlo, thi = r["test_range"]
    return (f"{r['variable']} {tlo:.3g}..{thi:.3g} {r['unit']} against training's {lo:.3g}..{hi:.3g} "
            f"({100 * r['share_of_test_rows']:.0f} % of test rows beyond)")  # fmt: skip


def where_text(checks: dict, force_unit: str = "F") -> str:
    """Where and by how much a model fails, in words (empty when it passes)."""
    parts = []
    lv = checks["level"]
    if checks["gap"]["failed"]:
        g = checks["gap"]
        s = (f"the test part's residual is {g['ratio']:.2g} x the training part's (train/test gap; "
             f"{lv['test_ratio']:.2g} x the noise floor)")  # fmt: skip
        if g.get("beyond_training"):
            s += "; the test part reaches " + "; ".join(_fmt_range(r) for r in g["beyond_training"]).replace(" F ", f" {force_unit} ")
        parts.append(s)
    if lv["failed"]:
        parts.append(f"held-out residual {lv['ratio']:.3g} x the noise floor ({lv['floor']:.3g} {force_unit} RMS)")
    w = checks["windows"]
    if w["failed"] and len(w["flagged"]) < len(w["windows"]):
        hot = [x for x in w["windows"] if x["flagged"]]
        spans = _merge_spans([(x["t0"], x["t1"]) for x in hot])
        worst = max(x["ratio"] for x in hot)
        parts.append(f"in time {', '.join(f'{a:.3g}-{b:.3g} s' for a, b in spans[:4])}"
                     f"{' ...' if len(spans) > 4 else ''} (up to {worst:.3g} x the floor)")  # fmt: skip
    elif w["failed"] and not lv["failed"]:
        parts.append("in every time window")
    st = checks["state"]
    if st["failed"]:
        names = ", ".join(n.replace("_", " ") for n in st["flagged"])
        parts.append(f"structured against {names}")
    uniform = not w["failed"] or len(w["flagged"]) == len(w["windows"])
    if lv["failed"] and uniform and not st["failed"] and not checks["gap"]["failed"]:
        parts.append("spread evenly in time and state (an unmodelled noise source, or physics spread over the "
                     "whole recording)")  # fmt: skip
    if checks["output"]["failed"]:
        parts.append(f"the simulated output is worse than coasting (NRMSE {checks['output']['nrmse']:.3g})")
    fr = checks.get("frf", {})
    if fr.get("failed"):
        parts.append(frf_text(fr))
    return "; ".join(parts)


def frf_text(fr: dict) -> str:
    """The ``frf`` check's departures in words: each band where the held-out frequency
    response departs from the model's where its coherence is high, and by how much."""
    deps = fr.get("departures") or []
    if not deps:
        lo, hi = fr["flagged_hz"][0], fr["flagged_hz"][-1]
        deps = [{"band_hz": [lo, hi], "peak_hz": fr["worst_hz"], "size": fr["worst_rel"], "coherence": None}]
    where = "; ".join(f"{d['band_hz'][0]:.4g}-{d['band_hz'][1]:.4g} Hz by up to {100 * d['size']:.0f} % at "
                      f"{d['peak_hz']:.4g} Hz" + (f" (coherence >= {d['coherence']:.2f})" if d.get("coherence") else "")
                      for d in deps[:6])  # fmt: skip
    more = f" and {len(deps) - 6} more" if len(deps) > 6 else ""
    return (f"the held-out frequency response departs from the model's where its coherence is high, in "
            f"{fr['flagged_bins']} of {fr['bins']} bins: {where}{more}")  # fmt: skip


def _merge_spans(spans):
    """Adjacent (equal-length) windows joined into one span."""
    out = []
    for a, b in spans:
        if out and a - out[-1][1] < 0.1 * (b - a):
            out[-1][1] = b
        else:
            out.append([a, b])
    return out


def out_of_scope(J: float | None, J_std: float | None, train_force_pct: float | None) -> str:
    """Why the force balance does not describe the recording ("" when it does): the
    fitted inertia is not positive beyond :data:`J_SIGMAS` standard deviations, or the
    fitted balance explains almost none of the force on the rows it was fitted on (a
    model that fits the training part and fails the test part is a located mismatch,
    not this)."""
    if J is None or not J > J_SIGMAS * (J_std or 0.0):
        jt = "none" if J is None else f"{J:.3g} +- {J_std or 0.0:.2g}"
        return (f"the input does not accelerate the position as a mass would: the fitted inertia J is {jt}, not "
                "positive beyond its uncertainty (is u a force or current, x a position of the driven body?)")  # fmt: skip
    if train_force_pct is not None and train_force_pct >= OUT_OF_SCOPE_PCT:
        return (f"the fitted force balance explains almost none of the force even where it was fitted (error "
                f"{train_force_pct:.3g} %): the motion is not driven by the recorded input through a force balance "
                "of this form")  # fmt: skip
    return ""


def decide(base: dict, final: dict, n_findings: int, scope: str, force_unit: str = "F",
           outside_rows: tuple = (), sensor: str = "") -> dict:  # fmt: skip
    """The verdict from the checks on the baseline and on the final model (module doc).
    ``outside_rows``: findings proven on evidence the rows do not hold (a breakaway from
    the intervals at rest): named in an ``unexplained`` text, which is about the rows.
    ``sensor``: what a sensor finding that left the rows as they were (a quantum named on
    the default rows) makes of their floor, said when the rows were at it."""
    if scope:
        return {"verdict": "out_of_scope", "text": scope}
    lv = final["level"]
    if not final["failed"]:
        if n_findings == 0 and not base["failed"]:
            return {"verdict": "consistent",
                    "text": f"the model explains the recording to its noise: held-out residual {lv['ratio']:.3g} x the "
                            "noise floor the position noise implies, no structure, no train/test gap"}  # fmt: skip
        b = base["level"]
        if sensor and not outside_rows and not base["failed"]:  # the rows' floor is partly the sensor's
            return {"verdict": "explained",
                    "text": f"the rows were at their noise with the baseline ({b['ratio']:.3g} x the floor), {sensor}"}
        if outside_rows and not base["failed"]:  # the rows had nothing to explain
            return {"verdict": "explained",
                    "text": f"the rows were at their noise with the baseline ({b['ratio']:.3g} x the floor); what it "
                            f"left out shows at rest: the {', '.join(outside_rows)} named from the intervals at rest "
                            "and confirmed on intervals its fit did not use"}  # fmt: skip
        above = (" and the held-out frequency response within its interval"
                 if base.get("frf", {}).get("failed") else "")  # fmt: skip
        return {"verdict": "explained",
                "text": f"the findings bring the held-out residual from {b['ratio']:.3g} to {lv['ratio']:.3g} x the noise "
                        f"floor{above}, with no structure left and no train/test gap"}  # fmt: skip
    besides = (f"; the {', '.join(outside_rows)} named from evidence the rows do not hold (the intervals at rest) "
               "cannot lower it, and no other term of the vocabulary accounts for it" if outside_rows
               else "; no term of the vocabulary accounts for it")  # fmt: skip
    return {"verdict": "unexplained", "text": f"the model still fails: {where_text(final, force_unit)}{besides}"}


__all__ = ["MARGIN", "PAGE_STATUS", "VERDICTS", "acceleration_noise_gain", "add_frf", "assess", "decide", "estimation_error",
           "force_floor", "out_of_scope", "ranges_beyond_training", "where_text", "window_checks", "window_rows"]
