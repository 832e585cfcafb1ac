"""Files of ``python -m studies.hdd.evaluate --out DIR``: evaluation.json, the table, plots."""
from __future__ import annotations

from pathlib import Path

from servo.run.pes_plots import pes_plot
from studies.hdd.plots import evaluation_plot
from servo.io.atomic import atomic_write, write_json


def write_report(out, named: dict, args: dict, table: str) -> Path:
    """Write ``evaluation.json`` (every plant's row and the summaries), ``table.md``,
    ``evaluation.png`` and ``pes_<design>.png`` (nominal plant) into ``out`` (created;
    must be new or empty); ``table``: the printed table (:func:`studies.hdd.evaluate.table`).
    Raises ValueError for a folder that holds anything."""
    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise ValueError(f"{out}: exists and is not an empty folder")
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "evaluation.json", dict(args=args, designs={
        n: dict(summary=ev["summary"], plants=[r.row() for r in ev["plants"]]) for n, ev in named.items()}))  # fmt: skip
    atomic_write(out / "table.md", lambda tmp: Path(tmp).write_text(table + "\n", encoding="utf-8"))
    evaluation_plot(named, out / "evaluation.png")
    for n, ev in named.items():
        nominal = ev["plants"][0]
        if nominal.figures is not None:
            pes_plot(nominal.figures, title=f"{n}: nominal plant", path=out / f"pes_{n}.png")
    return out
