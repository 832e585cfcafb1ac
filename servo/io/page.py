"""One report page per result: a self-contained HTML page built from a small document model.

A :class:`Page` is a title, a summary (the verdict or the headline figures, first on the
page), sections of :class:`Table`, :class:`Image` and :class:`Text`, and the provenance
(:mod:`servo.io.provenance`).  :meth:`Page.html` is the whole page as a string: the
styles inline, every figure a base64 PNG in a ``data:`` URI, no script, no link to
anything outside it, so ``report.html`` opens from disk with no server and no network.
:meth:`Page.fragment` is the same content without the document around it (a notebook's
``_repr_html_``); :meth:`Page.write` writes ``report.html`` atomically (into a command's
staging folder, :mod:`servo.io.outdir`).  Each command's job builds its page from what it
writes in its JSON, so the page shows what the JSON holds.
"""
from __future__ import annotations

import base64
import io
import math
from dataclasses import dataclass, field
from html import escape
from pathlib import Path

from servo.io.atomic import atomic_write

#: the page's file name in every command's output folder
NAME = "report.html"

#: a summary's status -> its colour (the verdict's band at the top of the page)
STATUS = {"ok": "#2e7d32", "warn": "#b26a00", "bad": "#c62828", "info": "#37474f"}

STYLE = """
body{font:15px/1.45 system-ui,-apple-system,"Segoe UI",Helvetica,Arial,sans-serif;color:#222;margin:0;background:#fafafa}
main{max-width:1100px;margin:0 auto;padding:1.2em 1.5em 3em}
h1{font-size:1.5em;margin:.2em 0 .6em}h2{font-size:1.15em;margin:1.6em 0 .5em;border-bottom:1px solid #ddd}
h3{font-size:1em;margin:1em 0 .3em}
.summary{border-left:6px solid;padding:.6em 1em;background:#fff;margin:0 0 1em}
.summary p{margin:.2em 0}.summary p:first-child{font-weight:600;font-size:1.1em}
table{border-collapse:collapse;margin:.4em 0 1em;background:#fff;font-size:.93em}
th,td{border:1px solid #ddd;padding:.25em .6em;text-align:left;vertical-align:top}
td.n{text-align:right;font-variant-numeric:tabular-nums}th{background:#f0f0f0}
figure{margin:.6em 0 1.2em}figure img{max-width:100%;height:auto;border:1px solid #eee;background:#fff}
figcaption{font-size:.9em;color:#555}
.prov td:first-child{white-space:nowrap;color:#555}.prov td{font-family:ui-monospace,monospace;font-size:.85em}
"""


def number(v, digits: int = 4) -> str:
    """How a page writes a value: a float to ``digits`` significant digits (``inf``,
    ``nan`` as such), None as an em dash, anything else as ``str``."""
    if v is None:
        return "\u2014"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:.{digits}g}" if math.isfinite(v) else str(v)
    return str(v)


@dataclass
class Table:
    """Rows of cells under an optional ``header``; numbers are written by :func:`number`."""

    rows: list
    header: list | None = None
    title: str = ""
    digits: int = 4

    def html(self) -> str:
        def cell(v, tag="td"):
            num = isinstance(v, (int, float)) and not isinstance(v, bool)
            return f"<{tag}{' class=n' if num and tag == 'td' else ''}>{escape(number(v, self.digits))}</{tag}>"

        head = "<tr>" + "".join(cell(h, "th") for h in self.header) + "</tr>" if self.header else ""
        body = "".join("<tr>" + "".join(cell(v) for v in row) + "</tr>" for row in self.rows)
        title = f"<h3>{escape(self.title)}</h3>" if self.title else ""
        return f"{title}<table>{head}{body}</table>"


@dataclass
class Image:
    """A figure as PNG bytes, embedded in the page as a base64 ``data:`` URI."""

    png: bytes
    title: str = ""
    caption: str = ""

    @classmethod
    def of_figure(cls, fig, title: str = "", caption: str = "", dpi: int = 90) -> "Image":
        """A :class:`matplotlib.figure.Figure`, drawn to PNG."""
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
        return cls(buf.getvalue(), title, caption)

    @classmethod
    def of_file(cls, path: str | Path, title: str = "", caption: str = "") -> "Image":
        """A PNG file a job wrote (``title`` defaults to its name)."""
        path = Path(path)
        return cls(path.read_bytes(), title or path.name, caption)

    def html(self) -> str:
        data = base64.b64encode(self.png).decode("ascii")
        cap = " ".join(x for x in (self.title, self.caption) if x)
        return (f'<figure><img alt="{escape(self.title)}" src="data:image/png;base64,{data}">'
                + (f"<figcaption>{escape(cap)}</figcaption>" if cap else "") + "</figure>")  # fmt: skip


@dataclass
class Text:
    """Paragraphs of plain text (escaped), a list of strings or one string."""

    paragraphs: list | str
    title: str = ""

    def html(self) -> str:
        paras = [self.paragraphs] if isinstance(self.paragraphs, str) else self.paragraphs
        title = f"<h3>{escape(self.title)}</h3>" if self.title else ""
        return title + "".join(f"<p>{escape(str(p))}</p>" for p in paras if p)


@dataclass
class Section:
    """A titled part of the page: tables, images and text, in order."""

    title: str
    items: list = field(default_factory=list)

    def html(self) -> str:
        return f"<section><h2>{escape(self.title)}</h2>" + "".join(i.html() for i in self.items if i) + "</section>"


@dataclass
class Page:
    """A result's page: ``summary`` lines (the verdict first) with a ``status`` (a key of
    :data:`STATUS`), then ``sections``, then the ``provenance`` dict."""

    title: str
    summary: list = field(default_factory=list)
    status: str = "info"
    sections: list = field(default_factory=list)
    provenance: dict | None = None

    def _summary(self) -> str:
        colour = STATUS.get(self.status, STATUS["info"])
        lines = "".join(f"<p>{escape(str(s))}</p>" for s in self.summary)
        return f'<div class="summary" id="summary" data-status="{escape(self.status)}" style="border-color:{colour}">{lines}</div>'

    def _provenance(self) -> str:
        if not self.provenance:
            return ""
        rows = []
        for k, v in self.provenance.items():
            if isinstance(v, dict):
                v = ", ".join(f"{a} {b}" for a, b in v.items()) if v else "\u2014"
            elif isinstance(v, list):
                v = " ".join(str(x) for x in v)
            rows.append([k, v])
        return f'<section class="prov"><h2>Provenance</h2>{Table(rows).html()}</section>'

    def fragment(self) -> str:
        """The page's content without the document around it (for a notebook)."""
        return (f"<div class=servo-report><h1>{escape(self.title)}</h1>{self._summary()}"
                + "".join(s.html() for s in self.sections) + self._provenance() + "</div>")  # fmt: skip

    def html(self) -> str:
        """The whole page, self-contained."""
        return ("<!DOCTYPE html>\n<html lang=en><head><meta charset=utf-8>"
                '<meta name=viewport content="width=device-width,initial-scale=1">'
                f"<title>{escape(self.title)}</title><style>{STYLE}</style></head>"
                f"<body><main>{self.fragment()}</main></body></html>\n")  # fmt: skip

    def _repr_html_(self) -> str:
        """:meth:`fragment` (the page's styles would restyle the whole notebook)."""
        return self.fragment()

    def write(self, folder: str | Path, name: str = NAME) -> Path:
        """Write :meth:`html` to ``folder/name`` atomically; returns the path."""
        path = Path(folder) / name
        text = self.html()
        atomic_write(path, lambda p: Path(p).write_text(text, encoding="utf-8"))
        return path


def images(folder: str | Path, names) -> list[Image]:
    """The PNGs ``names`` of ``folder`` that exist, as :class:`Image` (a job's plots,
    which ``--no-plots`` may have left out)."""
    return [Image.of_file(Path(folder) / n) for n in names if (Path(folder) / n).is_file()]


__all__ = ["NAME", "Image", "Page", "Section", "Table", "Text", "images", "number"]
