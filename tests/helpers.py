"""Test helpers: quiet (noise-free) configs, open-loop simulation, shared data paths."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from kernels.plant import plant_measure, plant_step
from servo.config import Config
from servo.runtime.simplant import build_plant

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
EMPS_MAT = SHARED / "data" / "emps" / "DATA_EMPS.mat"

NO_MODES = dict(mode_hz=[], mode_zeta=[], mode_gain=[])
QUIET = dict(position_noise=0.0, velocity_noise=0.0, position_quantum=0.0)


def quiet_config(**drive) -> Config:
    """Default config with noise-free, unquantised sensors and the given drive fields."""
    return Config().replace(drive={**QUIET, **drive})


def simulate_open_loop(cfg: Config, u: np.ndarray, d: np.ndarray | None = None):
    """Step the plant of ``cfg`` open loop under commands ``u`` (A, one per tick).
    Returns arrays (n+1,) of rigid x, v, H and the measured position, from tick 0."""
    p = build_plant(cfg.drive, cfg.dt)
    n = u.shape[0]
    out = np.zeros((4, n + 1))

    def record(k):
        out[0, k], out[1, k], out[2, k] = p.state[0]["x"], p.state[0]["v"], p.state[0]["H"]
        out[3, k] = plant_measure(p.state, p.params, p.q, p.gain, 0.0, 0.0)[0]

    record(0)
    for k in range(n):
        plant_step(p.state, p.params, p.q, p.mab, p.ubuf, u[k], 0.0 if d is None else d[k])
        record(k + 1)
    return out, p


def doc_commands(page: str | Path) -> list[str]:
    """The shell commands a docs page shows (indented lines starting with ``servo``,
    backslash continuations joined), in order: the recipes tests run as written."""
    path = Path(page)
    if not path.is_absolute():
        path = Path(__file__).resolve().parents[1] / path
    out, pending = [], ""
    for line in path.read_text().splitlines():
        text = line.strip()
        if pending:
            pending += " " + text.rstrip("\\").strip()
            if not text.endswith("\\"):
                out.append(pending)
                pending = ""
        elif line.startswith("    ") and text.startswith("servo "):
            if text.endswith("\\"):
                pending = text.rstrip("\\").strip()
            else:
                out.append(text.split("  #")[0].split(" # ")[0].strip())
    return out


def run_doc_command(command: str) -> int:
    """Run one documented ``servo ...`` command line in this process (the shell's
    quoting undone by :func:`shlex.split`); its exit code."""
    import shlex

    from servo.cli import main

    argv = shlex.split(command)
    assert argv[0] == "servo", command
    return main(argv[1:])
