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


def _small_diagnosis():
    rng = np.random.default_rng(4)
    t = np.arange(6000) * 1e-3
    x = 1e-3 * np.sin(2 * np.pi * 1.3 * t) + 3e-4 * np.sin(2 * np.pi * 4.1 * t)
    v, a = np.gradient(x, t), np.gradient(np.gradient(x, t), t)
    u = 0.5 * a + 2.0 * v + 0.3 * np.sign(v) + 1e-3 * rng.standard_normal(t.size)
    return diagnose(Recording(t, u, x, source="synthetic"), Options(baseline="J,B"))


def test_plots_are_drawn_by_two_processes_and_all_written(tmp_path):
    """:class:`PlotWriter` forks a process that draws a share of the figures while the
    caller goes on; after :meth:`finish` every figure is a complete PNG, the same files
    as a serial run, and the other process has exited."""
    from servo.diagnose.plots import PlotWriter, figure_files, write_plots

    D = _small_diagnosis()
    names = figure_files(D)
    (tmp_path / "serial").mkdir()
    (tmp_path / "par").mkdir()
    serial = write_plots(D, tmp_path / "serial", parallel=False)
    w = PlotWriter(D, tmp_path / "par")
    proc = w.proc
    assert proc is not None and proc.pid is not None  # Linux: a forked process draws its share
    assert set(w.mine) < set(names)
    assert w.finish() == names == serial
    assert proc.exitcode == 0 and w.proc is None
    for n in names:
        for d in ("serial", "par"):
            assert (tmp_path / d / n).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(p.name for p in (tmp_path / "par").iterdir()) == sorted(names)  # no staging file left


def test_a_figure_the_other_process_did_not_write_is_drawn_here(tmp_path, monkeypatch):
    """If the forked process fails (here: it exits at once), the caller draws its
    figures: the folder is complete either way."""
    import os

    from servo.diagnose import plots

    D = _small_diagnosis()
    monkeypatch.setattr(plots, "_child", lambda D, out, names: os._exit(1))
    w = plots.PlotWriter(D, tmp_path)
    proc = w.proc
    assert w.finish() == plots.figure_files(D)
    assert proc.exitcode == 1
    assert all((tmp_path / n).stat().st_size > 0 for n in plots.figure_files(D))


def test_the_share_balances_the_cost():
    from servo.diagnose.plots import FIGURES, _share

    names = [n for n, _, _ in FIGURES]
    theirs, mine = _share(names)
    cost = {n: c for n, _, c in FIGURES}
    assert sorted(theirs + mine) == sorted(names) and theirs and mine
    total = sum(cost.values())
    assert abs(sum(cost[n] for n in theirs) - sum(cost[n] for n in mine)) <= max(cost.values()) < total / 2
