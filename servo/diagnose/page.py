"""``servo diagnose``'s report page (:mod:`servo.io.page`): the verdict first, then the
findings with their held-out proof, the figures, the final model, what was dropped or
not named, the recording and its rows, and the provenance, from ``report.json``."""
from __future__ import annotations

from pathlib import Path

from servo.diagnose.report import _change, _fmt_params
from servo.diagnose.verdict import PAGE_STATUS
from servo.io.page import Page, Section, Table, Text, images

#: the plots of :func:`servo.diagnose.plots.write_plots`, in the order the page shows them
PLOTS = ("fits.png", "residual_time.png", "residual_state.png", "residual_spectrum.png", "frf.png")


def page(report: dict, folder: str | Path | None = None) -> Page:
    """The page of a diagnosis's ``report`` (:func:`servo.diagnose.report.build_report`);
    the plots are read from ``folder`` when given."""
    rc, rows, b, fm = report["recording"], report["rows"], report["baseline"], report["final_model"]
    if rows is None:  # out of scope before any row was made (:mod:`servo.diagnose.scope`)
        rec = Table([["source", rc["source"]], ["samples", rc["samples"]], ["sample rate (Hz)", rc["sample_rate_hz"]],
                     ["duration (s)", rc["duration_s"]], ["position span", rc.get("position_span_m")],
                     ["input span", rc.get("input_span")]])  # fmt: skip
        return Page("servo diagnose", [f"verdict: {report['verdict']}: {report['verdict_text']}",
                                       "no rows and no model: nothing was fitted or named"],
                    PAGE_STATUS.get(report["verdict"], "info"), [Section("Recording", [rec])], report.get("provenance"))
    be, fe = b["error"], fm["error"]
    lines = [f"verdict: {report['verdict']}: {report['verdict_text']}",
             f"held-out force error {be['test_force_rel_pct']:.3g} % -> {fe['test_force_rel_pct']:.3g} %"
             + (f", output NRMSE {be['test_output_nrmse']:.3g} -> {fe['test_output_nrmse']:.3g}"
                if be["test_output_nrmse"] is not None and fe["test_output_nrmse"] is not None else ""),
             f"{rc['source']}: {rc['samples']} samples at {rc['sample_rate_hz']:.6g} Hz, {rc['duration_s']:.3g} s, "
             f"forces in {rc['force_unit']}, positions in {rc.get('position_unit', 'm')}"]  # fmt: skip
    found = Table([[i, f["physics"], _fmt_params(f["params"], f["units"], f["std"]), f["where"].get("text", ""), _change(f)]
                   for i, f in enumerate(report["findings"], 1)],
                  ["#", "physics", "parameters", "where", "held-out error before -> after"])  # fmt: skip
    findings = [found] if report["findings"] else [Text("no finding beyond the baseline")]
    model = Table([[t["physics"], _fmt_params(t["params"], t["units"], t["std"], digits=6)
                    + (" (fixed)" if t.get("fixed") else "")] for t in fm["terms"]], ["term", "parameters"])  # fmt: skip
    final = [model, Text(fm["drive_note"] or "" if fm["drive"] is None else "written to final_model.toml as a [drive] section"),
             Text(fm.get("partial") or "")]  # fmt: skip
    dropped = [[u["physics"], _fmt_params(u["params"], u["units"], u["std"]), u["reason"]] for u in report["unconfirmed"]]
    dropped += [[name, "", f"not named: {why}"] for name, why in report["implausible"].items()]
    rec = Table([["source", rc["source"]], ["samples", rc["samples"]], ["sample rate (Hz)", rc["sample_rate_hz"]],
                 ["duration (s)", rc["duration_s"]], ["force unit", rc["force_unit"]],
                 ["position unit", rc.get("position_unit", "m")],
                 ["rows (training / held out)", f"{rows['train']} / {rows['test']}"],
                 ["usable fraction", rows["usable_fraction"]], ["band of the rows (Hz)", rows["band_hz"][1]],
                 ["band note", rows["band_note"]]] + _noise_row(rows))  # fmt: skip
    sections = [Section("Findings", findings)]
    if folder is not None:
        figs = images(folder, PLOTS)
        if figs:
            sections.append(Section("Figures", figs))
    sections.append(Section("Final model", final))
    if dropped:
        sections.append(Section("Dropped or not named", [Table(dropped, ["physics", "parameters", "why"])]))
    sections.append(Section("Recording", [rec]))
    if report.get("files"):
        sections.append(Section("Files", [Text(", ".join(report["files"]))]))
    return Page("servo diagnose", lines, PAGE_STATUS.get(report["verdict"], "info"), sections, report.get("provenance"))


def _noise_row(rows: dict) -> list:
    """The sensor noise and how it was read (``rows.noise`` of ``report.json``)."""
    from servo.diagnose.noise import describe_text

    return [["sensor noise", describe_text(rows["noise"])]] if rows.get("noise") else []


__all__ = ["PLOTS", "page"]
