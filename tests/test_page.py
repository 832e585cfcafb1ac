"""The report page builder (servo/io/page.py): self-contained, escaped, atomic; and the
notebook's ``_repr_html_`` of a run, a frequency response and a diagnosis built by it.
That each command's page shows what its JSON holds in a real browser is
tests/test_report_browser.py."""
import base64
import re

import numpy as np

from servo.io.frequency_response import FrequencyResponse
from servo.io.page import NAME, Image, Page, Section, Table, Text, number
from servo.io.plotting import subplots


def self_contained(html: str) -> None:
    """No script, no stylesheet link, no frame; every ``src`` a ``data:`` URI; no
    ``url(...)`` or ``http`` address anywhere: the page needs nothing but itself."""
    assert not re.search(r"<(script|link|iframe|object|embed)\b", html, re.I)
    assert all(s.startswith("data:") for s in re.findall(r'\bsrc="([^"]*)"', html)), "an image from outside the page"
    assert "url(" not in html and "http://" not in html and "https://" not in html


def test_a_page_is_self_contained_escaped_and_ordered(tmp_path):
    fig, ax = subplots()
    ax.plot([0, 1], [1, 0])
    img = Image.of_figure(fig, "a.png")
    page = Page("<b>title</b>", ["verdict: <script>alert(1)</script>", "second"], "warn",
                [Section("Figures", [img]), Section("Numbers", [Table([["x", 0.123456789, None, float("inf")]], ["k", "v", "w", "z"]),
                                                                Text("a & b")])],
                {"servo_version": "9.9", "libraries": {"numpy": "2.0"}})  # fmt: skip
    html = page.html()
    self_contained(html)
    assert "<script>" not in html and "&lt;script&gt;alert(1)&lt;/script&gt;" in html and "&lt;b&gt;title" in html
    assert html.index('id="summary"') < html.index("Figures") < html.index("Numbers") < html.index("Provenance")
    assert 'data-status="warn"' in html and "0.1235" in html and "\u2014" in html and ">inf<" in html
    assert "a &amp; b" in html and "numpy 2.0" in html
    data = re.search(r'src="data:image/png;base64,([^"]+)"', html).group(1)
    assert base64.b64decode(data) == img.png and img.png.startswith(b"\x89PNG")
    path = page.write(tmp_path)
    assert path == tmp_path / NAME and path.read_text(encoding="utf-8") == html
    assert sorted(p.name for p in tmp_path.iterdir()) == [NAME]  # no temporary left beside it


def test_number_formats():
    assert [number(None), number(True), number(3), number(2.0 / 3), number(float("nan"))] == ["\u2014", "yes", "3", "0.6667", "nan"]
    assert number(1234567.0, 3) == "1.23e+06"


def test_notebook_summaries_are_built_by_the_page_builder():
    """A frequency response's ``_repr_html_`` is a page fragment (summary band, a table)
    with its figures, self-contained."""
    f = np.geomspace(10, 1000, 50)
    resp = FrequencyResponse(f, 1 / (1j * 2 * np.pi * f) ** 2, coherence=np.full(50, 0.95), unit="m/A", meta={"label": "u -> x"})
    html = resp._repr_html_()
    self_contained(html)
    assert 'class="summary"' in html and "u -&gt; x" in html and "<table>" in html
    assert f"{np.abs(resp.H).max():.4g}" in html and ">50<" in html


def test_a_run_in_memory_shows_its_figures_through_the_builder():
    import servo
    from servo.config import Config

    cfg = Config().replace(run={"duration_s": 0.05})
    run = servo.simulate(cfg)
    html = run._repr_html_()
    self_contained(html)
    assert 'class="summary"' in html
    for label in run.labels:
        rms = run.summary["runs"][label]["error_rms_m"]
        assert label in html and f"tracking error RMS {rms * 1e9:.1f} nm" in html
