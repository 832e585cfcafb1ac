"""The diagnosis figures as a library returns them: ``residual_time`` marks only the
held-out part "held out" (the residual lines cover the whole record)."""
import numpy as np
from matplotlib.figure import Figure

from servo.diagnose.job import Options, diagnose
from servo.diagnose.plots import plot_time
from servo.io.recording import Recording


def test_residual_time_labels_only_the_held_out_part(tmp_path):
    rng = np.random.default_rng(3)
    t = np.arange(6000) * 1e-3
    x = 1e-3 * np.sin(2 * np.pi * 1.3 * t) + 3e-4 * np.sin(2 * np.pi * 4.1 * t)
    v, a = np.gradient(x, t), np.gradient(np.gradient(x, t), t)
    u = 0.5 * a + 2.0 * v + 0.3 * np.sign(v) + 1e-3 * rng.standard_normal(t.size)
    D = diagnose(Recording(t, u, x, source="synthetic"), Options(baseline="J,B"))
    fig = plot_time(D)
    assert isinstance(fig, Figure) and not list(tmp_path.iterdir())
    ax = fig.axes[0]
    lines = {ln.get_label(): ln for ln in ax.get_lines() if not ln.get_label().startswith("_")}
    assert set(lines) == {"baseline", "final model"}
    assert all(ln.get_xdata()[0] < t[0] + 0.05 * t[-1] for ln in lines.values())  # the whole record, training part too
    held = [p for p in ax.patches if "held out" in p.get_label()]
    assert len(held) == 1
    x0, x1 = held[0].get_x(), held[0].get_x() + held[0].get_width()
    t_split = D.sig.t_rows[np.flatnonzero(D.design.train_rows)[-1]]
    assert x0 == t_split and x1 > x0 and x0 > t[0] + 0.5 * (t[-1] - t[0])
    assert [tx.get_text().strip() for tx in ax.texts] == ["held out"]


def test_a_long_series_is_drawn_as_its_envelope():
    """Past 2*buckets samples the line is each bucket's minimum and maximum (a gap where
    the whole bucket is NaN), so a figure draws the same number of points at any length."""
    from servo.diagnose.plots import envelope

    rng = np.random.default_rng(1)
    t = np.arange(100_000) * 1e-4
    y = rng.standard_normal(t.size)
    y[5000:5100] = np.nan  # one whole bucket (of 100 samples)
    y[777] = 9.0
    te, ye = envelope(t, y, buckets=1000)
    assert te.size == ye.size == 2000
    lo, hi = ye[0::2], ye[1::2]
    for b in (0, 15, 99, 999):
        seg = y[100 * b : 100 * (b + 1)]
        assert lo[b] == np.nanmin(seg) and hi[b] == np.nanmax(seg) and te[2 * b] == t[100 * b]
    assert hi[7] == 9.0 and np.isnan(lo[50]) and np.isnan(hi[50])
    short_t, short_y = envelope(t[:1500], y[:1500], buckets=1000)
    assert np.array_equal(short_t, t[:1500]) and np.array_equal(short_y, y[:1500])  # short: every sample
