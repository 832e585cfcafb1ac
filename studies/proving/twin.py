"""An effect's size on the held-out error, measured against the same recording without it.

The study's first measure of a recording's *effect on the held-out error* holds the
baseline's held-out residual against the noise floor the recording implies
(``1 - 1/base_ratio``, :mod:`studies.proving.study`).  Two things bend it:

* the floor is estimated from the data (what the Butterworth removes from the
  position), so it holds a sensor quantum's own noise: a quantised recording's baseline
  sits near "its" floor whatever the quantum, and the measure says the quantum changes
  nothing.  It does: on development seeds (offsets 40000 and 45000, 12 per size) the same
  recording without the quantum has a held-out RMS residual 38-46 % lower at a quantum
  of 5 noise std, 61-69 % at 10, 86-90 % at 30 and 94-98 % at 100 (docs/studies/2026-11-24-quantisation-share.md);
* a null recording's own misfit (a few-sample stick at a reversal, docs section 1)
  counts as the effect's: of five recordings of a mode far above the rows' band that
  read ">= 20 %" by it on the fresh seeds, three (multisine loops) change the held-out
  error by 0.1-0.2 % against their twins (docs/studies/2026-11-23-proving-ground-scores.md).

:func:`twin_effect` measures what the effect itself does: the baseline of eq. (3)
fitted on the training part of the default rows (the decimation the diagnosis chooses
for the recording), its held-out residual (each training block predicted by the fit on
the other blocks, the test part by the fit on the training part, usable rows), on the
recording and on its twin (the same case and seed at size 0, the same noise and
excitation, on the same path): ``1 - rms_twin/rms``.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from studies.proving.cases import Case, recording


def heldout_rms(rec, settings=None) -> tuple[float, object]:
    """RMS (force unit) of the paper baseline's held-out residual on the usable rows of
    ``rec`` (on the path of ``settings``, or the one the diagnosis chooses) and the
    settings used."""
    from servo.diagnose import baseline as baseline_mod
    from servo.diagnose.band import choose
    from servo.diagnose.job import Options, heldout_residual, prepare
    from servo.diagnose.select import make_blocks

    opt = Options()
    design = prepare(rec, settings, opt) if settings is not None else choose(rec, opt, prepare)[0]
    base = baseline_mod.from_terms(None)
    baseline_mod.check_baseline(design, base)
    base = baseline_mod.without_idle_inputs(base, design.sig.u)
    valid = design.sig.valid
    r = heldout_residual(design, base, make_blocks(design.train_valid, opt.blocks), ~design.train_rows & valid)
    return float(np.sqrt(np.mean(r[valid] ** 2))), design.sig.settings


def twin_effect(case: Case, seed: int, rec=None) -> float:
    """``1 - rms_twin/rms``: the share of the baseline's held-out RMS residual on the
    recording of ``case`` that the same recording without the effect (size 0) does not
    have (module doc).  ``rec``: that recording if the caller made it already."""
    if rec is None:
        rec, _ = recording(case, seed)
    rms, settings = heldout_rms(rec)
    twin, _ = recording(replace(case, size=0.0), seed)
    rms0, _ = heldout_rms(twin, settings)
    return float(1.0 - rms0 / max(rms, 1e-300))


__all__ = ["heldout_rms", "twin_effect"]
