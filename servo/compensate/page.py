"""``servo compensate``'s report page (:mod:`servo.io.page`): the proposal and the
check's verdict first (refused, a warning, or no worse than none), then the check's
step figures per compensator as a plot and a table, the section's fields with their
units, what was left out or cannot be cancelled, the authority and the provenance, from
``summary.json``."""
from __future__ import annotations

from servo.io.page import Image, Page, Section, Table, Text


def _fmt(v) -> str:
    return "[" + ", ".join(f"{x:.4g}" for x in v) + "]" if isinstance(v, list) else f"{v:.4g}" if isinstance(v, float) else str(v)


def step_plot(figures: dict):
    """Overshoot and settling of every step of the check, per compensator (bars)."""
    import numpy as np

    from servo.io.plotting import subplots

    names = list(figures)
    steps = figures[names[0]]["run"]["steps"]
    fig, (a, b) = subplots(1, 2, figsize=(10, 3.4))
    x, w = np.arange(len(steps)), 0.8 / len(names)
    for i, name in enumerate(names):
        got = figures[name]["run"]["steps"]
        a.bar(x + i * w, [s["overshoot_pct"] for s in got], w, label=name)
        b.bar(x + i * w, [np.nan if s["settling_ms"] is None else s["settling_ms"] for s in got], w, label=name)
        for j, s in enumerate(got):  # a step that never settles has no bar: say so where it would be
            if s["settling_ms"] is None:
                b.text(x[j] + i * w, 0, "never", rotation=90, ha="center", va="bottom", fontsize=7)
    labels = [f"{s['size_m'] * 1e6:+.3g} um" for s in steps]
    for ax, what in ((a, "overshoot (%)"), (b, "settling (ms)")):
        ax.set_xticks(x + w * (len(names) - 1) / 2, labels)
        ax.set_ylabel(what)
        ax.grid(axis="y", alpha=0.3)
    a.legend(fontsize=8)
    fig.suptitle("The check on the model: steps with each compensator")
    return fig


def page(summary: dict) -> Page:
    """The page of ``servo compensate``'s ``summary`` (:func:`servo.compensate.job.summary`)."""
    u, c = summary["unit"], summary.get("check")
    cancelled = ", ".join(t["name"] for t in summary["cancelled"]) or "nothing"
    lines = [f"proposed: the {summary['proposed']} compensator, cancelling {cancelled} (forces in {u}, positions in "
             f"{summary.get('position_unit', 'm')})"]  # fmt: skip
    status = "ok"
    if summary.get("refused"):
        lines.insert(0, f"REFUSED: {summary['refused']} (written with --allow-worse)")
        status = "bad"
    if c is None:
        lines.append(f"check on the model: {summary.get('check_note') or 'not run'}")
        status = "warn" if status == "ok" else status
    else:
        if c["steps_worse_than_none"]:
            lines.append("WARNING: worse than no compensator: " + "; ".join(c["steps_worse_than_none"]))
            status = "bad"
        if c["others_worse_than_none"]:
            lines.append("warning: worse than no compensator: " + "; ".join(c["others_worse_than_none"]))
            status = "warn" if status == "ok" else status
        if not (c["steps_worse_than_none"] or c["others_worse_than_none"]):
            lines.append(f"check on the model: the {c['chosen']} compensator tracks no worse than none")
    lines.append(f"source: {summary['source']} ({summary['model_kind']})")
    units = summary.get("units", {})
    fields = Table([[k, _fmt(v), units.get(k, "-")] for k, v in summary["section"].items()], ["field", "value", "unit"],
                   "[compensator]")  # fmt: skip
    terms = [Table([[t["name"], ", ".join(t["keys"])] for t in summary["cancelled"]], ["cancelled", "fields"])]
    if summary["left_out"]:
        terms.append(Table([[t.get("name"), "; ".join(f"{k} {_fmt(v)}" for k, v in t.items() if k != "name")]
                            for t in summary["left_out"]], ["left out", "why"]))  # fmt: skip
    if summary["not_cancelled"]:
        terms.append(Table([[t["name"], t["advice"]] for t in summary["not_cancelled"]], ["cannot cancel", "instead"]))
    a = summary["authority"]
    pu = summary.get("position_unit", "m")
    authority = Table([[k, v] for k, v in a.items() if not isinstance(v, (list, dict))],
                      ["authority", f"value ({u}, {pu}/s, dB)"])  # fmt: skip
    sections = []
    if c is not None and c.get("figures"):
        figs = c["figures"]
        rows = [[name, f"{s['size_m'] * 1e6:+.3g} um", s["overshoot_pct"], "never" if s["settling_ms"] is None else s["settling_ms"],
                 f["run"]["error_rms_by_segment_m"].get("disturbance")]
                for name, f in figs.items() for s in f["run"]["steps"]]  # fmt: skip
        sections.append(Section("The check on the model", [
            Image.of_figure(step_plot(figs), "steps.png"),
            Table(rows, ["compensator", "step", "overshoot (%)", "settling (ms)", "disturbance error RMS (m)"])]))
    sections += [Section("The section proposed", [fields] + terms), Section("Authority", [authority])]
    if summary.get("residual_pct"):
        r = summary["residual_pct"]
        sections.append(Section("On the recording", [Table([[k, v] for k, v in r.items()],
                                                           ["held-out force residual (% of the force)", "value"])]))
    if summary.get("files"):
        sections.append(Section("Files", [Text(", ".join(summary["files"]))]))
    return Page("servo compensate", lines, status, sections, summary.get("provenance"))


__all__ = ["page", "step_plot"]
