"""``servo loop``'s report page (:mod:`servo.io.page`): the measured margins first (and
any warning), then the Bode and sensitivity plots, the margins of every run and design,
the agreement with the design, the settings and the provenance, from ``summary.json``."""
from __future__ import annotations

from pathlib import Path

from servo.io.page import Page, Section, Table, Text, images

MARGIN_KEYS = (("crossover_hz", "crossover (Hz)"), ("phase_margin_deg", "phase margin (deg)"),
               ("gain_margin_db", "gain margin (dB)"), ("gain_margin_side", "side"), ("gain_margin_hz", "at (Hz)"),
               ("max_S_db", "max|S| (dB)"), ("max_S_hz", "at (Hz)"))  # fmt: skip


def _margin_row(name: str, m: dict) -> list:
    if m.get("stable") is False:
        return [name, "unstable"] + [None] * (len(MARGIN_KEYS) - 1)
    return [name] + [m.get(k) for k, _ in MARGIN_KEYS]


def page(summary: dict, folder: str | Path | None = None) -> Page:
    """The page of ``servo loop``'s ``summary`` (:func:`servo.loop.job.run_loop`); the
    plots are read from ``folder`` when given."""
    st, warnings = summary["settings"], summary.get("warnings", [])
    lines = []
    for e in summary["runs"]:
        m = e["margins"]
        if m.get("stable") is False:
            lines.append(f"measured, {e['label']}: unstable")
        else:
            fc, pm = m.get("crossover_hz"), m.get("phase_margin_deg")
            lines.append(f"measured, {e['label']}: crossover " + ("none" if fc is None else f"{fc:.1f} Hz")
                         + ("" if pm is None else f", phase margin {pm:.1f} deg") + f", max|S| {m['max_S_db']:.1f} dB")  # fmt: skip
    lines += [f"warning: {w}" for w in warnings]
    lines.append(f"stepped sine on {summary['where']}, {st['n_freq']} frequencies {st['f_min']:g}-{st['f_max']:g} Hz")
    margins = Table([_margin_row(f"design, {k}", m) for k, m in summary["designs"].items()]
                    + [_margin_row(f"measured, {e['label']}", e["margins"]) for e in summary["runs"]],
                    ["loop"] + [h for _, h in MARGIN_KEYS])  # fmt: skip
    agree = []
    for e in summary["runs"]:
        for key, what in (("vs_nominal", "1/(J s^2) design"), ("vs_drive", "compensated drive model"),
                          ("vs_pivot", "pivot small-signal model")):  # fmt: skip
            a = e.get(key) or {}
            if a.get("points"):
                agree.append([e["label"], what, a.get("L_mag_db_max"), a.get("L_phase_deg_max"), a.get("S_rel_err_max")])
    sections = [Section("Margins", [margins])]
    if agree:
        sections[0].items.append(Table(agree, ["run", "against", "|L| within (dB)", "phase within (deg)",
                                              "S relative error max"], "Agreement with the design"))  # fmt: skip
    if folder is not None:
        sections.append(Section("Figures", images(folder, ["loop.png", "sensitivity.png"])))
    sections.append(Section("Settings", [Table([[k, v if not isinstance(v, (list, dict)) else str(v)]
                                                for k, v in st.items()])]))  # fmt: skip
    if summary.get("files"):
        sections.append(Section("Files", [Text(", ".join(summary["files"]))]))
    status = "warn" if warnings else ("bad" if any(e["margins"].get("stable") is False for e in summary["runs"]) else "ok")
    return Page("servo loop", lines, status, sections, summary.get("provenance"))


__all__ = ["page"]
