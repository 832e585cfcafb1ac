"""The held-out proof's output rule: a finding is dropped for raising the short-horizon
output error only where it raises it consistently over the test part's starts
(``servo.diagnose.job.output_worse``), not where one start's error moves the NRMSE."""
import numpy as np

from servo.diagnose.job import OUTPUT_TOLERANCE, output_worse
from servo.diagnose.simulate import Prediction

H = 20


def _prediction(err_scale: np.ndarray, seed: int = 0) -> Prediction:
    """Starts (S,) whose prediction errors are white with std ``err_scale`` per start;
    the non-coasting motion is the same for every start."""
    rng = np.random.default_rng(seed)
    S = err_scale.size
    meas = np.cumsum(rng.standard_normal((S, H)), axis=1)
    pred = meas + err_scale[:, None] * rng.standard_normal((S, H))
    coast = np.zeros((S, H))
    return Prediction(np.arange(S) * H, pred, meas, coast)


def test_one_start_that_moves_the_nrmse_does_not_drop_a_finding():
    """75 starts (as an open-loop step recording's test part), the same errors before
    and after but for one start whose error grows 25-fold: the NRMSE rises well past
    the tolerance, the rise is not consistent, and the finding stands."""
    scale = np.full(75, 0.05)
    before = _prediction(scale, seed=1)
    worse_one = scale.copy()
    worse_one[40] *= 25.0
    after = _prediction(worse_one, seed=1)
    assert after.nrmse() > before.nrmse() * (1 + OUTPUT_TOLERANCE) * 1.5  # the ratio alone would drop it
    assert not output_worse(before, after)


def test_a_consistent_rise_drops_a_finding():
    """Every start's error 30 % larger (the same draws, scaled): the rise is consistent
    over every block of starts, and it counts."""
    before = _prediction(np.full(75, 0.05), seed=2)
    after = _prediction(np.full(75, 0.065), seed=2)
    assert after.nrmse() > before.nrmse() * (1 + OUTPUT_TOLERANCE)
    assert output_worse(before, after)
    assert not output_worse(after, before)  # and a consistent fall is no rise


def test_too_few_starts_leave_the_ratio_to_judge():
    """Under 16 starts (4 blocks of 4) the test cannot resolve a rise: the NRMSE's rise
    alone counts, as before the test."""
    before = _prediction(np.full(12, 0.05), seed=3)
    after = _prediction(np.full(12, 0.05), seed=4)
    assert output_worse(before, after)


def test_a_run_away_from_many_starts_counts_though_the_blocks_are_mixed():
    """A third of the starts (4 blocks of 12) three times worse, the rest a little
    better: the blocks are mixed, so the sign-flip test does not call the rise
    consistent, but without the block that rises most the NRMSE still rises far past
    the tolerance (a simulated output that runs away from many starts): it counts."""
    from servo.diagnose.select import signflip_test

    S = 72
    scale = np.full(S, 0.05)
    before = _prediction(scale, seed=5)
    up = np.where(np.arange(S) % 18 < 6, 3.0, 0.7) * scale  # 4 of the 12 blocks of 6
    after = _prediction(up, seed=5)
    e0, e1 = before.sse()[0], after.sse()[0]
    parts = np.array_split(np.arange(S), 12)
    S0 = np.array([e0[p].sum() for p in parts])
    S1 = np.array([e1[p].sum() for p in parts])
    assert signflip_test(S1, S0)[1] > 0.05  # not consistent over the blocks
    assert output_worse(before, after)
