"""``servo compensate``: a diagnosis or an identification in, a compensator section out.

:func:`compensate` reads the model (:mod:`servo.compensate.model`) and proposes the
section (:mod:`servo.compensate.propose`); :func:`recommend` proposes both eq. 9's and
the augmented one and checks them on the model (:mod:`servo.compensate.check`), which is
what the command writes; :func:`section_text` is the TOML written (the ``[compensator]``
section alone, or the whole base config with it); :func:`write` the output folder
(``compensator.toml``, ``summary.json`` and ``report.html``, :mod:`servo.compensate.page`); :func:`format_summary` what is printed: each
term and its fields with their units, what was left out and why, what cannot be
cancelled and what to do instead, the authority and the check's figures.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from servo.compensate.model import CompensateError, SourceModel, read_model
from servo.compensate.propose import MARGIN, Proposal, apply, propose
from servo.compensate.residual import BEYOND_EQ9, Residual, at_rate, compensated_residual
from servo.config import CompensatorConfig, Config, documented, to_toml
from servo.io.atomic import atomic_write, write_json


def compensate(source: str | Path | dict, base: Config, paper: bool = False, force_constant: float | None = None,
               authority: float | None = None) -> Proposal:  # fmt: skip
    """The compensator for the model of ``source`` (a file, or a report/summary dict:
    :func:`~servo.compensate.model.read_model`) on the config ``base`` (see
    :func:`servo.compensate.propose.propose`)."""
    return propose(read_model(source, base), base, paper, force_constant, authority)


@dataclasses.dataclass
class Recommendation:
    """What ``servo compensate`` writes: ``proposal`` (the one chosen), ``eq9`` and
    ``augmented`` (both proposals of the model), ``check`` (None: not run, ``note`` says
    why) and the ``model`` (significant terms only)."""

    proposal: Proposal
    eq9: Proposal
    augmented: Proposal
    check: object | None
    model: SourceModel
    note: str = ""

    def refusal(self) -> str | None:
        """Why the proposal must not be written (it tracks worse than no compensator on
        the model's steps), or None."""
        c = self.check
        if c is None or not c.steps_worse:
            return None
        return (f"on the model it came from, the {c.chosen} compensator tracks worse than none: "
                + "; ".join(c.steps_worse))  # fmt: skip


def recommend(source: str | Path | dict, base: Config, paper: bool = False, force_constant: float | None = None,
              authority: float | None = None, check: bool = True) -> Recommendation:  # fmt: skip
    """Both proposals of ``source`` on ``base`` (eq. 9's and the augmented one) and, with
    ``check``, the one the check on the model chooses (``paper``: eq. 9's, checked
    against no compensator).  The check runs only for a model in the command's unit (A):
    for another axis the base config's loop is not the recorded one."""
    model = read_model(source, base)
    eq9 = propose(model, base, True, force_constant, authority)
    aug = propose(model, base, False, force_constant, authority)
    from servo.compensate.check import choose, same
    from servo.compensate.significance import significant

    kept, _ = significant(model)
    chosen = eq9 if paper else aug
    if not check:
        return Recommendation(chosen, eq9, aug, None, kept, "not checked (--no-check)")
    if model.force_unit != "A":
        return Recommendation(chosen, eq9, aug, None, kept, f"not checked: the model's forces are in {model.force_unit}, "
                              "and the base config's loop is not the recorded axis's")  # fmt: skip
    if model.position_unit != "m":
        return Recommendation(chosen, eq9, aug, None, kept, f"not checked: the model's positions are in "
                              f"{model.position_unit} (a rotary axis), and the base config's loop is a linear one in m")  # fmt: skip
    alone = paper or same(aug, eq9)  # one candidate: eq. 9's, or the augmented one holding nothing beyond it
    c = choose(kept, base, eq9, None if alone else aug, label="eq. 9" if paper else "proposed")
    if not paper and c.chosen == "eq. 9" and not same(aug, eq9):
        chosen = eq9
    return Recommendation(chosen, eq9, aug, c, kept)


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


def format_residual(r: Residual, unit: str = "A", position_unit: str = "m") -> str:
    lines = [f"  on the recording, held-out force residual beyond J*x'' (% of the force, {r.rows} rows; "
             f"J = {r.J:.4g} {unit}*s^2/{position_unit}):", f"    no compensator: {r.none_pct:.2f} %"]  # fmt: skip
    lines += [f"    {name}: {pct:.2f} %" for name, pct in r.pct.items()]
    return "\n".join(lines)


def section_text(p: Proposal, base: Config, full: bool = False) -> str:
    """The TOML: the ``[compensator]`` section (``full``: the whole of ``base`` with it)."""
    cfg = apply(base, p)
    head = [f"# servo compensate: from {p.source}" + (" (eq. 9 only, the paper's compensator)" if p.paper else "")]
    if p.unit != "A":
        head += [f"#   forces in {p.unit}: the loop that runs it commands {p.unit}"]
    if p.position_unit != "m":
        head += [f"#   positions in {p.position_unit} (a rotary axis): every m of a field's unit reads {p.position_unit}"]
    head += [f"#   {t.name}" for t in p.cancelled]
    head += [f"#   left out: {t.physics} (not distinguishable from zero)" for t in p.left_out]
    head += [f"#   not cancelled: {t.name}" for t in p.not_cancelled]
    text = to_toml(cfg, comments=False)
    if not full:
        text = text[text.index("[compensator]") :].split("\n\n")[0] + "\n"
    return "\n".join(head) + "\n" + text


#: the file the section (or with ``--full`` the whole config) is written to in the folder
SECTION_FILE = "compensator.toml"


def summary(r: Recommendation, residual: Residual | None = None) -> dict:
    """``summary.json``'s content (schema in docs/compensate.md)."""
    p = r.proposal
    out = {
        "source": p.source, "model_kind": r.model.kind, "unit": p.unit, "position_unit": p.position_unit, "paper": p.paper,
        "proposed": "eq. 9" if p is r.eq9 else "augmented", "section": p.section,
        "units": {k: unit_of(k, p.unit, p.position_unit) for k in p.section},
        "cancelled": [{"name": t.name, "keys": t.keys} for t in p.cancelled],
        "left_out": [dataclasses.asdict(t) for t in p.left_out],
        "not_cancelled": [{"name": t.name, "advice": t.advice} for t in p.not_cancelled],
        "authority": p.authority,
        "check": r.check.as_dict() if r.check is not None else None, "check_note": r.note,
        "refused": r.refusal(),
    }  # fmt: skip
    if residual is not None:
        out["residual_pct"] = {"none": residual.none_pct, **residual.pct, "rows": residual.rows}
    return out


def write(r: Recommendation, base: Config, folder: Path, full: bool = False, extra: dict | None = None,
          residual: Residual | None = None) -> list[str]:  # fmt: skip
    """Write :data:`SECTION_FILE` (:func:`section_text`), ``summary.json``
    (:func:`summary`, with ``extra`` such as the provenance) and its page ``report.html`` into ``folder`` (a staging
    folder: :func:`servo.io.outdir.staged`); returns the names written."""
    from servo.compensate.page import page

    text = section_text(r.proposal, base, full)
    files = [SECTION_FILE, "report.html", "summary.json"]
    atomic_write(folder / SECTION_FILE, lambda f: Path(f).write_text(text))
    content = {**summary(r, residual), "files": files, **(extra or {})}
    write_json(folder / "summary.json", content)
    page(content).write(folder)
    return files


_UNITS = {f.name: f.metadata.get("unit", "-") for f in documented(CompensatorConfig)}


def unit_of(key: str, unit: str, position_unit: str = "m") -> str:
    """The unit of the ``[compensator]`` field ``key`` with its forces in ``unit`` and its
    positions in ``position_unit`` (:func:`servo.io.units.substitute`)."""
    from servo.io.units import substitute

    return substitute(_UNITS.get(key, "-"), unit, position_unit)


def _fmt(k: str, v, unit: str, position_unit: str = "m") -> str:
    u = unit_of(k, unit, position_unit)
    u = "" if u == "-" else " " + u
    if isinstance(v, list):
        return f"{k} [" + ", ".join(f"{x:.4g}" for x in v) + "]" + u
    return f"{k} {v:.4g}{u}"


def _run_line(name: str, f: dict) -> str:
    steps = ", ".join(f"{s['size_m'] * 1e6:+.3g} um {s['overshoot_pct']:.1f} %/"
                      + ("never" if s["settling_ms"] is None else f"{s['settling_ms']:.1f} ms") for s in f["run"]["steps"])
    d = f["run"]["error_rms_by_segment_m"].get("disturbance")
    spread = f"; Fig. 8 spread {f['spread_db']:.1f} dB" if f.get("spread_db") is not None else ""
    dist = f"; disturbance {d * 1e9:.4g} nm RMS" if d is not None else ""
    return f"    {name + ':':<12} steps (overshoot/settling) {steps}{dist}{spread}"  # fmt: skip


def format_check(r: Recommendation) -> list[str]:
    """The check's lines: the figures per compensator, the choice and the warnings."""
    c = r.check
    if c is None:
        return [f"  check on the model: {r.note}"]
    lines = ["  check on the model it came from (servo run's scenario; the closed loop in memory):"]
    lines += [_run_line(name, f) for name, f in c.figures.items()]
    if "augmented" in c.figures:
        if c.chosen == "eq. 9":
            lines.append("  proposed: eq. 9's compensator: the augmented one is worse on the model: " + "; ".join(c.why))
        elif c.why:
            lines.append("  proposed: the augmented compensator, though worse on " + "; ".join(c.why) + ": eq. 9's is "
                         "worse on more steps: " + "; ".join(c.against))  # fmt: skip
        else:
            lines.append("  proposed: the augmented compensator: no worse than eq. 9's on any figure")
    if c.steps_worse:
        lines.append("  WARNING: worse than no compensator: " + "; ".join(c.steps_worse))
    if c.others_worse:
        lines.append("  warning: worse than no compensator: " + "; ".join(c.others_worse) + " (a compensator that "
                     "cancels friction also removes the damping it gave against a force: docs/compensate.md)")  # fmt: skip
    return lines


def format_summary(p: Proposal | Recommendation) -> str:
    r = p if isinstance(p, Recommendation) else None
    p = r.proposal if r is not None else p
    a, u, pu = p.authority, p.unit, p.position_unit
    lines = [f"servo compensate: {p.source}" + (" (eq. 9 only)" if p.paper else "")
             + (f" (forces in {u}: the loop that runs it commands {u})" if u != "A" else "")
             + (f" (positions in {pu}: a rotary axis)" if pu != "m" else "")]  # fmt: skip
    for t in p.cancelled:
        lines.append(f"  cancel {t.name}: " + ", ".join(_fmt(k, v, u, pu) for k, v in t.keys.items()))
    for t in p.left_out:
        lines.append(f"  left out {t.describe()}")
    for t in p.not_cancelled:
        lines.append(f"  cannot cancel {t.name}: {t.advice}")
    how = (f"{MARGIN:g} x the largest force of the model, {a['largest_force_a']:.4g} {u} at speeds up to "
           f"{a['speed_m_s']:.3g} {pu}/s" if a["largest_force_a"] is not None else
           "half the current limit (the source does not say how fast the arm moved)")  # fmt: skip
    lines.append(f"  authority: |u_c| <= {a['authority_a']:.4g} {u} ({how}; current limit {a['current_limit_a']:.4g} {u})")
    if a["worst_um_per_ma"] is not None and a.get("loop_is_source", True):
        lines.append(f"    a wrong force of 1 mA moves the head by at most {a['worst_um_per_ma']:.3g} um at any one frequency "
                     "(max |P*S| of the designed loop)")  # fmt: skip
    if a["kf_authority"] is not None:
        gm = [f"{g:+.1f} dB" for g in (a["gain_up_db"], a["gain_down_db"]) if g is not None]
        why = (f"half of the loop's gain margins, {' and '.join(gm)}, allow" if gm else "the loop has no gain margin"
               if a.get("loop_is_source", True) else "the recorded axis's loop is not known: at most 0.9")  # fmt: skip
        lines.append(f"  kf(x) held within 1 +- {a['kf_authority']:.3g} (the model asks for {a['kf_model']:.3g}; {why})")
    if r is not None:
        lines += format_check(r)
    return "\n".join(lines)


__all__ = ["SECTION_FILE", "Recommendation", "compensate", "format_check", "format_residual", "format_summary", "on_recording",
           "recommend", "section_text", "summary", "unit_of", "write"]
