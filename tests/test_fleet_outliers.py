"""Fleet outliers that mean something: continuous figures only, one MAD per side of the
median, and at most 1 drive in 100 flagged on fleets with no defect at the default
threshold (the rate docs/fleet.md states)."""
import numpy as np
import pyarrow.parquet as pq
import pytest

from servo.cli import main
from servo.fleet import simulate as fleet_simulate
from servo.fleet.outliers import THRESHOLD, outliers, robust_z, unscored
from servo.fleet.table import columns_of

N_DRIVES, N_COLUMNS = 1000, 10


def _fleet(draw, seed: int) -> tuple[list[dict], list[str]]:
    """Rows of N_DRIVES defect-free drives, N_COLUMNS figures each drawn by ``draw(rng, n)``."""
    rng = np.random.default_rng(seed)
    cols = [f"c{j}" for j in range(N_COLUMNS)]
    x = np.column_stack([draw(rng, N_DRIVES) for _ in cols])
    return [{"drive": f"d{i}", "status": "ok", **dict(zip(cols, map(float, x[i])))} for i in range(N_DRIVES)], cols


POPULATIONS = {
    "normal": lambda rng, n: rng.normal(10.0, 1.0, n),
    "lognormal 30 %": lambda rng, n: rng.lognormal(np.log(2e-3), 0.3, n),
    "gamma k=4 (an RMS error's skew)": lambda rng, n: rng.gamma(4.0, 1e-7, n),
    "normal 20 % near 0 (an offset)": lambda rng, n: rng.normal(2e-3, 4e-4, n),
}


@pytest.mark.parametrize("name", POPULATIONS)
def test_fleets_with_no_defect_flag_at_most_one_drive_in_a_hundred(name):
    for seed in range(3):
        rows, cols = _fleet(POPULATIONS[name], seed)
        flagged = {o.drive for o in outliers(rows, cols)}
        assert len(flagged) <= N_DRIVES / 100, (name, seed, len(flagged))


def test_a_planted_defect_is_still_found_on_either_side_of_a_skewed_population():
    rows, cols = _fleet(POPULATIONS["gamma k=4 (an RMS error's skew)"], 7)
    rows[17]["c3"] = 3e-6  # far above the long side (the median is ~3.7e-7)
    rows[99]["c5"] = -8e-7  # below the short side: a negative RMS from a broken fit
    found = {(o.drive, o.column) for o in outliers(rows, cols)}
    assert {("d17", "c3"), ("d99", "c5")} <= found


def test_quantised_and_pinned_columns_are_not_scored():
    rng = np.random.default_rng(0)
    overshoot = np.round(rng.gamma(2.0, 0.5, 200) * 3) / 3  # in quanta of 1/3 %, like a step's overshoot
    overshoot[5] = 53.3
    pinned = np.full(200, 2.0002e-5)  # a maximum error pinned at the step size
    pinned[:3] = 2.0001e-5
    rows = [{"drive": f"d{i}", "status": "ok", "os": float(overshoot[i]), "max": float(pinned[i])} for i in range(200)]
    assert outliers(rows, ["os", "max"]) == []
    assert unscored(rows, ["os", "max"]) == ["os", "max"]
    assert np.isnan(robust_z(overshoot)[0]).all()


def test_simulate_scores_its_continuous_figures_only():
    cols = ["drive.Ha", "comp_error_rms_m", "uncomp_error_max_m", "comp_rms_disturbance_m", "comp_step1_overshoot_pct",
            "comp_step1_settling_ms", "uncomp_rms_step2_m"]  # fmt: skip
    assert fleet_simulate.scored(cols) == ["comp_error_rms_m", "comp_rms_disturbance_m"]
    assert "comp_step1_settling_ms" in fleet_simulate.figures(cols)  # still shown, not scored


@pytest.mark.slow
def test_a_monte_carlo_fleet_with_20_percent_spreads_flags_at_most_one_drive_in_a_hundred(tmp_path, capsys):
    """The fleet of issue 26 (200 drives, 20 % spreads, no defect): 142 outliers with
    the earlier scoring; at most 2 flagged drives now."""
    out = tmp_path / "mc"
    argv = ["fleet", "simulate", "--drives", "200", "--duration", "0.12", "--workers", "0", "--no-plots", "--quiet",
            "--vary", "drive.Ha=lognormal(1e-3, 20%)", "--vary", "drive.sigma=normal(320, 20%)",
            "--vary", "drive.B=normal(2e-3, 20%)", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    rows = pq.read_table(out / "fleet.parquet").to_pylist()
    assert sum(r["status"] == "ok" for r in rows) == 200
    scored = fleet_simulate.scored(columns_of(rows))
    assert scored and not any(c.endswith(("_overshoot_pct", "_settling_ms")) for c in scored)
    flagged = {o.drive for o in outliers(rows, scored)}
    assert len(flagged) <= 2, flagged
    assert f"(|z| > {THRESHOLD:g}): {len(outliers(rows, scored))}" in capsys.readouterr().out
