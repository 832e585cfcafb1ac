"""``servo.simulate``: the ``servo run`` job in memory, for a notebook.

The same closed loop, scenario and figures as :func:`servo.run.job.run_job` (all
compiled, the fast path: the same bits as the tick path), without an output folder: the
logs stay arrays and the result is the :class:`~servo.io.runfolder.RunFolder`
``servo.load_run`` would give for that folder (``path`` None), summary and provenance
included.
"""
from __future__ import annotations

from servo.config import Config
from servo.io.provenance import provenance
from servo.io.runfolder import RunFolder
from servo.run.reduce import RunFigures
from servo.runtime.controller import compensation_runs


def simulate(cfg: Config | None = None, compensation: str | None = None, **sections: dict) -> RunFolder:
    """Run ``cfg`` (default: the default config; ``sections`` are changes to it, as
    :meth:`Config.replace` takes them: ``simulate(run={"duration_s": 0.2})``) with and/or
    without the compensator (``compensation``: ``on``, ``off``, ``compare``; None: what
    ``[compensator] enabled`` says) and return the runs' logs, config and summary
    (``summary["runs"][label]``: the tracking and step figures ``servo run`` prints)."""
    from servo.runtime.closedloop import run_in_memory
    from servo.scenarios import scenario_inputs

    cfg = (Config() if cfg is None else cfg).replace(**sections) if sections else (cfg or Config())
    logs, metas, runs = {}, {}, {}
    for on in compensation_runs(cfg, compensation):
        label = "compensated" if on else "uncompensated"
        log = run_in_memory(cfg, scenario_inputs(cfg), on)
        data = log.data[: log.rows]
        figures = RunFigures(cfg)
        figures(data)
        runs[label] = figures.result()
        logs[label] = {c: data[:, i].copy() for i, c in enumerate(log.columns)}
        metas[label] = {"label": label, "fast_path": True, "sample_rate_hz": cfg.run.sample_rate_hz, "seed": cfg.run.seed,
                        "controller": cfg.controller.kind}  # fmt: skip
    summary = {"ticks": cfg.n_ticks, "sample_rate_hz": cfg.run.sample_rate_hz, "duration_s": cfg.run.duration_s,
               "seed": cfg.run.seed, "path": "fast (all compiled), in memory", "runs": runs,
               "provenance": provenance(cfg)}  # fmt: skip
    from servo.controllers import get_kind

    kind = get_kind(cfg.controller.kind)
    rf = RunFolder(None, logs, cfg, summary, metas)
    rf.units.update(kind.log_units)
    return rf


__all__ = ["simulate"]
