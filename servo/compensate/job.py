"""``servo compensate``: a diagnosis or an identification in, a compensator section out.

:func:`compensate` reads the model (:mod:`servo.compensate.model`) and proposes the
section (:mod:`servo.compensate.propose`); :func:`section_text` is the TOML written
(the ``[compensator]`` section alone, or the whole base config with it);
:func:`format_summary` what is printed: each term and its fields, what cannot be
cancelled and what to do instead, and the authority.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from servo.compensate.model import CompensateError, read_model
from servo.compensate.propose import MARGIN, Proposal, apply, propose
from servo.compensate.residual import BEYOND_EQ9, Residual, at_rate, compensated_residual
from servo.config import Config, to_toml
from servo.io.atomic import atomic_write


def compensate(source: str | Path | dict, base: Config, paper: bool = False, force_constant: float | None = None,
               authority: float | None = None) -> Proposal:  # fmt: skip
    """The compensator for the model of ``source`` (a file, or a report/summary dict:
    :func:`~servo.compensate.model.read_model`) on the config ``base`` (see
    :func:`servo.compensate.propose.propose`)."""
    return propose(read_model(source, base), base, paper, force_constant, authority)


def on_recording(source: str | Path | dict, base: Config, rec, force_constant: float | None = None,
                 authority: float | None = None, test_fraction: float = 0.25) -> Residual:  # fmt: skip
    """The held-out force residual each compensator of ``source`` leaves on ``rec``
    (:mod:`servo.compensate.residual`): the paper's (eq. 9 only), the augmented one, and
    the augmented one without each term beyond eq. 9 it holds (what that term removes)."""
    at = at_rate(base, rec)
    model = read_model(source, at)
    full = apply(at, propose(model, at, False, force_constant, authority))
    paper = apply(at, propose(model, at, True, force_constant, authority))
    configs = {"paper's compensator (eq. 9)": paper, "augmented": full}
    p = full.compensator
    for name, off in BEYOND_EQ9.items():
        if any(getattr(p, k) not in (0.0, []) for k in off):
            configs[f"augmented without the {name}"] = full.replace(compensator=off)
    k = force_constant if model.force_unit != "A" and force_constant else 1.0
    J = float(model.drive.get("J", 0.0)) / k
    if k != 1.0:  # the recorded force in the compensator's unit, A
        rec = dataclasses.replace(rec, u=np.asarray(rec.u, dtype=float) / k)
    if not J > 0:
        raise CompensateError(f"{source}: the model has no positive inertia J: the residual needs it")
    return compensated_residual(rec, configs, J, test_fraction)


def format_residual(r: Residual) -> str:
    lines = [f"  on the recording, held-out force residual beyond J*x'' (% of the force, {r.rows} rows; "
             f"J = {r.J:.4g} A*s^2/m):", f"    no compensator: {r.none_pct:.2f} %"]  # fmt: skip
    lines += [f"    {name}: {pct:.2f} %" for name, pct in r.pct.items()]
    return "\n".join(lines)


def section_text(p: Proposal, base: Config, full: bool = False) -> str:
    """The TOML: the ``[compensator]`` section (``full``: the whole of ``base`` with it)."""
    cfg = apply(base, p)
    head = [f"# servo compensate: from {p.source}" + (" (eq. 9 only, the paper's compensator)" if p.paper else "")]
    head += [f"#   {t.name}" for t in p.cancelled]
    head += [f"#   not cancelled: {t.name}" for t in p.not_cancelled]
    text = to_toml(cfg, comments=False)
    if not full:
        text = text[text.index("[compensator]") :].split("\n\n")[0] + "\n"
    return "\n".join(head) + "\n" + text


def write(p: Proposal, base: Config, out: Path, full: bool = False) -> None:
    """Write :func:`section_text` to ``out`` atomically."""
    text = section_text(p, base, full)
    atomic_write(out, lambda f: Path(f).write_text(text))


def _fmt(v) -> str:
    if isinstance(v, list):
        return "[" + ", ".join(f"{x:.4g}" for x in v) + "]"
    return f"{v:.4g}"


def format_summary(p: Proposal) -> str:
    a = p.authority
    lines = [f"servo compensate: {p.source}" + (" (eq. 9 only)" if p.paper else "")]
    for t in p.cancelled:
        lines.append(f"  cancel {t.name}: " + ", ".join(f"{k} {_fmt(v)}" for k, v in t.keys.items()))
    for t in p.not_cancelled:
        lines.append(f"  cannot cancel {t.name}: {t.advice}")
    how = (f"{MARGIN:g} x the largest force of the model, {a['largest_force_a']:.4g} A at speeds up to "
           f"{a['speed_m_s']:.3g} m/s" if a["largest_force_a"] is not None else
           "half the current limit (the source does not say how fast the arm moved)")  # fmt: skip
    lines.append(f"  authority: |u_c| <= {a['authority_a']:.4g} A ({how}; current limit {a['current_limit_a']:.4g} A)")
    if a["worst_um_per_ma"] is not None:
        whose = ("the designed loop" if a.get("loop_is_source", True) else
                 "the base config's drive and controller, not the recorded axis: its forces were in another unit")  # fmt: skip
        lines.append(f"    a wrong force of 1 mA moves the head by at most {a['worst_um_per_ma']:.3g} um at any one frequency "
                     f"(max |P*S| of {whose})")  # fmt: skip
    if a["kf_authority"] is not None:
        gm = [f"{g:+.1f} dB" for g in (a["gain_up_db"], a["gain_down_db"]) if g is not None]
        lines.append(f"  kf(x) held within 1 +- {a['kf_authority']:.3g} (the model asks for {a['kf_model']:.3g}; "
                     + (f"half of the loop's gain margins, {' and '.join(gm)}, allow" if gm else "the loop has no gain margin")
                     + ")")  # fmt: skip
    return "\n".join(lines)


__all__ = ["compensate", "format_residual", "format_summary", "on_recording", "section_text", "write"]
