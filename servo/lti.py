"""servo's linear models as python-control objects, the lingua franca of a servo engineer.

* :func:`controller` -- the configured controller kind, ``C(z)`` from the position error
  (m) to its output ``u_n`` (A), discrete at the tick period (each kind's
  :meth:`~servo.controllers.ControllerKind.to_control`);
* :func:`drive` -- the simulated drive's linear part (rigid body, stiffness, viscous
  friction, flexible modes) from current (A) to measured position (m): continuous, or
  discrete at the tick period with the zero-order hold and the input delay (and the
  link's command latency) exact;
* :func:`model` -- the linear part of what ``servo identify`` or ``servo diagnose``
  found (their ``summary.json``/``report.json``, read as a drive by
  :func:`servo.compensate.model.read_model`), from force (A or N, as recorded) to m;
* :func:`loop` -- ``C*P`` at the tick period, for :func:`control.stability_margins`;
* frequency responses: :meth:`servo.io.frequency_response.FrequencyResponse.to_control`
  and :meth:`~servo.io.frequency_response.FrequencyResponse.from_control`
  (:class:`control.FrequencyResponseData`).

The discrete objects carry their sample time (``.dt``, s); the delay of a discrete
drive is in its states (a delay line), so its poles and margins include it.  A
continuous drive has no delay: add ``cfg.drive.input_delay_s`` yourself
(``control.pade``) if you need it.  Input and output names carry the units.
"""
from __future__ import annotations

from pathlib import Path

import control
import numpy as np

from servo.config import Config
from servo.errors import ConfigError


def controller(cfg: Config) -> control.StateSpace:
    """The controller of ``cfg`` (``[controller] kind``) as a discrete system at
    ``cfg.dt`` from the position error ``r - x`` (m) to ``u_n`` (A); its frequency
    response is the kind's :meth:`~servo.controllers.ControllerKind.response`."""
    from servo.controllers import get_kind

    kind = get_kind(cfg.controller.kind)
    try:
        sys = kind.to_control(cfg.controller.section, cfg)
    except NotImplementedError:
        raise ConfigError(f"controller kind {kind.name!r} has no linear form (its to_control is not written)") from None
    return control.ss(sys, inputs=["e (m)"], outputs=["u_n (A)"], name=f"controller {kind.name}")


def drive(cfg: Config, discrete: bool = True, compensated: bool = False, stiffness: float = 0.0,
          force_unit: str = "A") -> control.StateSpace:  # fmt: skip
    """The linear part of the drive of ``cfg``: ``J x'' = u - B x' - (K + stiffness) x``
    plus the flexible modes (measured position ``x + sum(g_i q_i)``), from force
    (``force_unit``) to position (m).

    ``compensated``: the plant the compensator leaves (``B`` and the stiffnesses
    cancelled: the double integrator and the modes, eq. 10); ``stiffness`` (force/m): the
    pivot's small-signal stiffness to add (``drive.sigma`` in pre-sliding; 0: the pivot
    left out).  ``discrete``: at ``cfg.dt`` as the simulated drive applies a command
    (zero-order hold, ``drive.input_delay_s`` and the link's latency in the loop,
    :attr:`~servo.config.LinkConfig.loop_latency_ticks`, exact); its frequency response is :func:`servo.loop.design.plant_response`'s."""
    from servo.design.loop import zoh_delay
    from servo.loop.design import _state_space

    a, b, c = _state_space(cfg, "drive", compensated, stiffness)
    names = dict(inputs=[f"u ({force_unit})"], outputs=["x (m)"], name="drive")
    if not discrete:
        return control.ss(a, b.reshape(-1, 1), c.reshape(1, -1), 0.0, **names)
    delay = cfg.drive.input_delay_s + cfg.link.loop_latency_ticks * cfg.dt
    A, B, C, D = zoh_delay(a, b, c.reshape(1, -1), cfg.dt, delay)
    return control.ss(A, B, C, D, cfg.dt, **names)


def model(source: str | Path, base: Config | None = None, discrete: bool = False) -> control.StateSpace:
    """The linear part of a model ``servo identify`` (``summary.json``) or ``servo
    diagnose`` (``report.json``) found, or of a config's ``[drive]`` (``.toml``): its
    inertia, viscous friction, stiffness, flexible modes and delay as :func:`drive`
    (the pivot's nonlinear element left out), from force in the recording's unit to m;
    what the model does not hold is absent (no mode, no delay, no stiffness), except
    the inertia, which is ``base``'s when the model has none.
    ``base``: the config whose other fields complete it (default: the default config);
    ``discrete``: at ``base``'s tick period."""
    from servo.compensate.model import read_model

    base = Config() if base is None else base
    src = read_model(source, base)
    bare = {"mode_hz": [], "mode_zeta": [], "mode_gain": [], "input_delay_s": 0.0, "K": 0.0, "B": 0.0}
    cfg = base.replace(drive={**bare, **src.drive})  # what the model holds, nothing of the base drive's
    return drive(cfg, discrete=discrete, force_unit=src.force_unit)


def loop(cfg: Config, compensated: bool = True, stiffness: float = 0.0) -> control.StateSpace:
    """``L = C*P`` at ``cfg.dt``: :func:`controller` after the discrete :func:`drive`
    (negative feedback closes it), the loop ``servo loop`` designs against."""
    return control.series(drive(cfg, True, compensated, stiffness), controller(cfg))


def export(path: str | Path, systems: dict[str, control.LTI]) -> Path:
    """Write ``{name: system}`` (state-space or transfer functions) as MATLAB ``.mat``
    (scipy.io, a struct per system with ``A, B, C, D, Ts``; Ts = 0 continuous, as
    MATLAB's ``ss(A, B, C, D, Ts)`` takes them) or HDF5 (``.h5``: a group per system
    with the same datasets), chosen by the suffix; atomically."""
    from servo.io.atomic import atomic_write

    path = Path(path)
    mats = {}
    for name, sys in systems.items():
        s = control.ss(sys)
        mats[name] = {"A": np.asarray(s.A, float), "B": np.asarray(s.B, float), "C": np.asarray(s.C, float),
                      "D": np.asarray(s.D, float), "Ts": float(s.dt or 0.0)}  # fmt: skip
    if path.suffix == ".mat":
        from scipy.io import savemat

        atomic_write(path, lambda tmp: savemat(tmp, {_mat_name(k): v for k, v in mats.items()}))
    elif path.suffix in (".h5", ".hdf5"):
        import h5py

        def write(tmp):
            with h5py.File(tmp, "w") as f:
                for k, v in mats.items():
                    g = f.create_group(k)
                    for key, val in v.items():
                        g.create_dataset(key, data=val)

        atomic_write(path, write)
    else:
        raise ConfigError(f"{path}: export to .mat or .h5")
    return path


def load(path: str | Path) -> dict[str, control.StateSpace]:
    """What :func:`export` wrote: ``{name: control.StateSpace}`` (``dt`` None when Ts = 0)."""
    path = Path(path)
    out = {}
    if path.suffix == ".mat":
        from scipy.io import loadmat

        for k, v in loadmat(path, squeeze_me=False).items():
            if k.startswith("__"):
                continue
            rec = v[0, 0]
            out[k] = _ss_of({n: rec[n] for n in ("A", "B", "C", "D", "Ts")})
    else:
        import h5py

        with h5py.File(path, "r") as f:
            for k, g in f.items():
                out[k] = _ss_of({n: g[n][()] for n in ("A", "B", "C", "D", "Ts")})
    return out


def _ss_of(m: dict) -> control.StateSpace:
    ts = float(np.asarray(m["Ts"]).ravel()[0])
    A, B, C, D = (np.atleast_2d(np.asarray(m[n], float)) for n in ("A", "B", "C", "D"))
    n = A.shape[0] if A.size else 0
    A = A.reshape(n, n)
    B, C = B.reshape(n, -1), C.reshape(-1, n)
    return control.ss(A, B, C, D, ts if ts > 0 else 0)


def _mat_name(name: str) -> str:
    """A MATLAB variable name for ``name`` (letters, digits, underscores; a letter first)."""
    s = "".join(ch if ch.isalnum() else "_" for ch in name)
    return s if s[:1].isalpha() else f"m_{s}"


__all__ = ["controller", "drive", "export", "load", "loop", "model"]
