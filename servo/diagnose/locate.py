"""Where a residual is structured rather than noise: in time, in state, in frequency.

Every test runs on the baseline's *held-out* force residual (each training block
predicted by the fit on the other blocks, the test part by the fit on the training
part), on usable rows only.  The rows are filtered, so neighbouring rows are not
independent: every count is divided by the residual's integrated autocorrelation time
``tau`` (``n_eff = n/tau``).  Each test states its false-alarm level: the probability
that it flags anything on a residual that is stationary Gaussian noise.

* **Time windows** (:func:`window_test`): the rows cut into ``W`` windows; the log of
  each window's mean square against the mean and standard deviation of the other
  windows' logs: for normal logs ``(L_w - mean)/(sd*sqrt(1 + 1/(W-1)))`` is Student's t
  with ``W - 2`` degrees of freedom (a prediction interval), and windows beyond its
  ``alpha/W`` quantile are flagged (family-wise ``alpha``).  A test against an absolute
  noise level (a chi-square with ``n_eff`` degrees of freedom) flagged 68 % of null
  recordings: even with nothing missing, a closed loop's residual power varies by
  +-20 % from window to window, several times what ``n_eff`` predicts, so the windows
  are compared with each other instead.
* **State** (:func:`state_test`): the residual binned by position, velocity, direction
  of motion and distance since the latest velocity reversal (for the last, the residual
  times the direction, so that a friction-like force does not cancel between
  directions); ``sum z_j^2`` over the bin means is ``chi2(bins)`` under the null, each
  variable tested at ``alpha/4``; bins with ``|z_j|`` beyond the Bonferroni normal
  quantile are flagged.  Given the error of a fit that predicts part of the rows (the
  verdict's test part, :func:`servo.diagnose.verdict.estimation_error`), the bin means'
  covariance holds it too and their Mahalanobis form is the ``chi2(bins)`` statistic.
* **Spectrum** (:func:`spectrum_test`): Welch's estimate over a running median floor;
  the ratio is ``chi2(2L)/2L`` for ``L`` segments, bins beyond the ``alpha/N_f``
  quantile are flagged.
* **Coherence and cross-correlation with the input** (:func:`coherence_test`,
  :func:`xcorr_test`): under independence the Welch coherence exceeds
  ``1 - (alpha/N_f)^(1/(L-1))`` with probability ``alpha/N_f`` per bin; a
  cross-correlation coefficient has Bartlett's variance ``sum rho_rr*rho_uu / n``.
  Both assume the residual is independent of the input, which **closed-loop data
  violate**: the sensor noise reaches the input through the controller, and the
  acceleration noise in the residual is the same noise differentiated twice.  On
  closed-loop recordings these two flag the band where the sensor noise dominates even
  when nothing is missing (measured on null recordings: ``docs/diagnosis.md``); they
  locate, they do not decide: findings come from :mod:`servo.diagnose.select`.
"""
from __future__ import annotations

import numpy as np
from scipy import signal, stats

from servo.diagnose.select import fft_len
from servo.frf.estimate import coherence, psd

N_WINDOWS = 20
N_BINS = 10


def window_test(t: np.ndarray, r: np.ndarray, valid: np.ndarray, tau: float, alpha: float, W: int = N_WINDOWS) -> dict:
    """Windows whose residual power stands out from the other windows (module doc)."""
    edges = np.linspace(0, r.size, W + 1).astype(int)
    ms, spans = [], []
    for a, b in zip(edges[:-1], edges[1:]):
        rr = r[a:b][valid[a:b]]
        ms.append(float(np.mean(rr**2)) if rr.size >= 5 else np.nan)
        spans.append((float(t[a]), float(t[b - 1])))
    ms = np.array(ms)
    ok = np.isfinite(ms) & (ms > 0)
    L = np.log(np.where(ok, ms, 1.0))
    n_ok = int(ok.sum())
    z = np.full(W, -np.inf)
    for i in np.flatnonzero(ok):  # each window against the others: a prediction interval
        o = ok.copy()
        o[i] = False
        sd = float(np.std(L[o], ddof=1)) or 1e-12
        z[i] = (L[i] - L[o].mean()) / (sd * np.sqrt(1 + 1 / max(n_ok - 1, 1)))
    level = alpha / W
    dof = max(n_ok - 2, 1)
    zc = float(stats.t.isf(level, dof))
    p = np.where(ok, stats.t.sf(z, dof), 1.0)
    center = float(np.median(L[ok]))
    wins = [{"t0": s[0], "t1": s[1], "rms": float(np.sqrt(m)) if np.isfinite(m) else None, "z": float(zz) if ok[i] else None,
             "p": float(q), "flagged": bool(zz > zc)} for i, (s, m, zz, q) in enumerate(zip(spans, ms, z, p))]  # fmt: skip
    return {"false_alarm": alpha, "level_per_window": level, "noise_rms": float(np.sqrt(np.exp(center))), "windows": wins,
            "flagged": [[w["t0"], w["t1"]] for w in wins if w["flagged"]]}  # fmt: skip


def _bins(values: np.ndarray, n: int) -> np.ndarray:
    qs = np.unique(np.quantile(values, np.linspace(0, 1, n + 1)))
    if qs.size < 2:
        return np.array([values.min(), values.max() + 1e-300])
    return qs


def state_test(r: np.ndarray, valid: np.ndarray, tau: float, variables: dict, alpha: float,
               estimation: tuple | None = None) -> dict:  # fmt: skip
    """Residual bin means against state variables (see module doc).

    ``variables``: name -> ``(values (m,), sign (m,) or None, unit)``; with a sign the
    residual is multiplied by it before binning.  ``estimation``: ``(E, C)``, the rows
    (m, p) through which a fitted coefficient vector's error reaches the residual and
    that error's covariance (p, p): the bin means then have the covariance
    ``diag(sigma^2 tau/n_j) + A C A'`` (``A`` the bin means of ``E``'s rows) and are
    tested by their Mahalanobis form, ``chi2(bins)`` under the null (None: the diagonal
    alone, the module doc's test)."""
    out = {}
    sigma = float(np.std(r[valid])) or 1e-300
    level = alpha / max(len(variables), 1)
    for name, (vals, sign, unit) in variables.items():
        rr = (r * sign if sign is not None else r)[valid]
        Ev = None
        if estimation is not None:
            Ev = (estimation[0] * sign[:, None] if sign is not None else estimation[0])[valid]
        vv = vals[valid]
        if name == "direction":
            edges = np.array([-1.5, 0.0, 1.5])
        else:
            edges = _bins(vv, N_BINS)
        idx = np.clip(np.searchsorted(edges, vv, side="right") - 1, 0, edges.size - 2)
        nb = edges.size - 1
        means, var, A, bins = [], [], [], []
        for j in range(nb):
            sel = idx == j
            n = int(sel.sum())
            if n == 0:
                continue
            means.append(float(rr[sel].mean()))
            var.append(max(sigma**2 * tau / n, np.finfo(float).tiny))  # a zero residual: no structure, p = 1
            if Ev is not None:
                A.append(Ev[sel].mean(axis=0))
            bins.append({"lo": float(edges[j]), "hi": float(edges[j + 1]), "n": n, "mean": means[-1]})
        means, S = np.array(means), np.diag(var)
        if Ev is not None and len(A):
            A = np.array(A)
            S = S + A @ estimation[1] @ A.T
        z = means / np.sqrt(np.diag(S))
        for b, zj in zip(bins, z):
            b["z"] = float(zj)
        X = float(means @ np.linalg.solve(S, means)) if means.size else 0.0
        p = float(stats.chi2.sf(X, max(z.size, 1)))
        zc = float(stats.norm.isf(level / (2 * max(z.size, 1))))
        for b in bins:
            b["flagged"] = bool(p < level and abs(b["z"]) > zc)
        out[name] = {"unit": unit, "signed_by_direction": sign is not None, "chi2": X, "p": p, "flagged": p < level,
                     "bins": bins}  # fmt: skip
    return {"false_alarm": alpha, "level_per_variable": level, "variables": out}


def _welch_len(m: int) -> int:
    return int(min(256, max(16, 2 ** int(np.log2(max(m // 8, 16))))))


def spectrum_test(r0: np.ndarray, fs: float, alpha: float) -> dict:
    """Welch spectrum of the residual rows (unusable rows zeroed) and its peaks over a
    running-median floor (see module doc)."""
    nper = _welch_len(r0.size)
    f, P = psd(r0, fs, nper)
    L = max(r0.size // nper, 2)
    floor = signal.medfilt(P, 17) if P.size >= 17 else np.full_like(P, np.median(P))
    floor = np.maximum(floor, 1e-300)
    ratio = P / floor
    level = alpha / f.size
    thr = float(stats.chi2.isf(level, 2 * L) / (2 * L))
    flagged = ratio > thr
    return {"false_alarm": alpha, "f_hz": f, "psd": P, "floor": floor, "threshold_ratio": thr,
            "flagged_hz": [float(x) for x in f[flagged]]}  # fmt: skip


def coherence_test(r0: np.ndarray, u: np.ndarray, fs: float, alpha: float) -> dict:
    """Welch coherence of the residual with the input, and the level a bin exceeds with
    probability ``alpha/N_f`` when they are independent."""
    nper = _welch_len(r0.size)
    f, C = coherence(r0, u, fs, nper)
    L = max(r0.size // nper, 2)
    thr = float(1 - (alpha / f.size) ** (1 / (L - 1)))
    return {"false_alarm": alpha, "f_hz": f, "coherence": C, "threshold": thr,
            "flagged_hz": [float(x) for x in f[C > thr]], "closed_loop_caveat": True}  # fmt: skip


def xcorr_test(r0: np.ndarray, u: np.ndarray, dt: float, alpha: float, max_lag: int = 20) -> dict:
    """Cross-correlation of residual and input at lags ``-max_lag..max_lag`` rows, with
    Bartlett's standard deviation and a Bonferroni bound over the lags."""
    a = r0 - r0.mean()
    b = u - u.mean()
    n = a.size
    sa, sb = a.std() or 1e-300, b.std() or 1e-300
    lags = np.arange(-max_lag, max_lag + 1)
    N = fft_len(n)
    fa, fb = np.fft.rfft(a, N), np.fft.rfft(b, N)
    cc = np.fft.irfft(np.conj(fa) * fb, N)  # cc[k] = sum a[t]*b[t+k], negative k wrapped at the end
    rho = np.array([cc[k] if k >= 0 else cc[N + k] for k in lags]) / (n * sa * sb)

    def acf(z, M):
        z = z - z.mean()
        N = fft_len(z.size)
        f = np.fft.rfft(z, N)
        return np.fft.irfft(f * np.conj(f), N)[: M + 1] / (z.size * max(z.var(), 1e-300))

    M = min(100, n // 4)
    ra, rb = acf(a, M), acf(b, M)
    var = (ra[0] * rb[0] + 2 * np.sum(ra[1:] * rb[1:])) / n
    sd = float(np.sqrt(max(var, 1e-300)))
    zc = float(stats.norm.isf(alpha / (2 * lags.size)))
    return {"false_alarm": alpha, "lag_s": lags * dt, "rho": rho, "bound": zc * sd,
            "flagged_lag_s": [float(x) for x in (lags * dt)[np.abs(rho) > zc * sd]], "closed_loop_caveat": True}  # fmt: skip


def where(delta: np.ndarray, valid: np.ndarray, t: np.ndarray, variables: dict, fs: float) -> dict:
    """Where a finding acts: ``delta`` (m,) the part of the residual it explains.

    Time: the windows (of :data:`N_WINDOWS`) holding more than twice their share of
    ``sum(delta^2)``.  State: the variable in whose bins ``delta^2`` is most
    concentrated, and the bins holding more than twice their share.  Frequency: the
    peak of ``delta``'s spectrum and the band around it holding half its power."""
    d2 = np.where(valid, delta**2, 0.0)
    tot = d2.sum()
    out: dict = {}
    if tot <= 0:
        return {"text": "nowhere (no effect on the rows)"}
    edges = np.linspace(0, d2.size, N_WINDOWS + 1).astype(int)
    share = np.array([d2[a:b].sum() for a, b in zip(edges[:-1], edges[1:])]) / tot
    out["time"] = [[float(t[a]), float(t[b - 1])] for a, b, s in zip(edges[:-1], edges[1:], share) if s > 2.0 / N_WINDOWS]
    best = None
    for name, (vals, _sign, unit) in variables.items():
        vv, dd = vals[valid], d2[valid]
        e = np.array([-1.5, 0.0, 1.5]) if name == "direction" else _bins(vv, N_BINS)
        idx = np.clip(np.searchsorted(e, vv, side="right") - 1, 0, e.size - 2)
        nb = e.size - 1
        per = np.array([dd[idx == j].sum() for j in range(nb)]) / tot
        cnt = np.array([np.sum(idx == j) for j in range(nb)]) / max(vv.size, 1)
        dens = per / np.maximum(cnt, 1e-300)
        hot = dens > 2.0
        conc = float(per[hot].sum() / max(cnt[hot].sum(), 1e-300)) if hot.any() else 1.0
        if best is None or conc > best[0]:
            ranges = _merge([(float(e[j]), float(e[j + 1])) for j in range(nb) if hot[j]])
            best = (conc, name, unit, ranges, float(per[hot].sum()), float(cnt[hot].sum()))
    conc, name, unit, ranges, sh, frac = best
    out["state"] = {"variable": name, "unit": unit, "ranges": ranges, "share_of_effect": sh, "share_of_rows": frac}
    nper = _welch_len(delta.size)
    f, P = psd(np.where(valid, delta, 0.0), fs, nper)
    k = int(np.argmax(P))
    c = np.cumsum(np.sort(P)[::-1])
    keep = P >= np.sort(P)[::-1][np.searchsorted(c, 0.5 * c[-1])]
    out["frequency"] = {"peak_hz": float(f[k]), "band_hz": [float(f[keep].min()), float(f[keep].max())]}
    out["text"] = _where_text(out)
    return out


def _merge(ranges):
    out = []
    for lo, hi in ranges:
        if out and abs(out[-1][1] - lo) <= 1e-12 * max(abs(lo), 1e-300):
            out[-1][1] = hi
        else:
            out.append([lo, hi])
    return out


_NAMES = {"position": "position", "velocity": "velocity", "direction": "direction",
          "distance_since_reversal": "distance since the last reversal"}  # fmt: skip


def _fmt(v: float, unit: str) -> str:
    return f"{v:.3g} {unit}".strip()


def _where_text(w: dict) -> str:
    s = w["state"]
    if s["ranges"] and s["share_of_rows"] < 0.6:
        if s["variable"] == "direction":
            rng = "moving -" if s["ranges"][0][1] <= 0 else "moving +"
        else:
            rng = ", ".join(f"{_fmt(lo, s['unit'])}..{_fmt(hi, s['unit'])}" for lo, hi in s["ranges"][:3])
        state = (f"{_NAMES[s['variable']]} {rng} ({100 * s['share_of_effect']:.0f} % of the effect in "
                 f"{100 * s['share_of_rows']:.0f} % of the rows)")  # fmt: skip
    else:
        state = "throughout the motion"
    f = w["frequency"]
    return f"{state}; {f['band_hz'][0]:.3g}-{f['band_hz'][1]:.3g} Hz"


__all__ = ["coherence_test", "spectrum_test", "state_test", "where", "window_test", "xcorr_test"]
