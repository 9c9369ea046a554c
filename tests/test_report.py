"""The HTML report: self-contained, every section present, images decode to the PNGs given."""

from __future__ import annotations

import base64
import re
from pathlib import Path

from pbdkit.apps.report import Figure, Section, render_report, write_report

PNG_1x1 = base64.b64decode(
    "iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAYAAAAfFcSJAAAADUlEQVR42mNk+M9QDwADhgGAWjR9awAAAABJRU5ErkJggg=="
)


def test_report_is_self_contained_with_sections_tables_and_images(tmp_path: Path) -> None:
    sections = [
        Section(
            "Summary", paragraphs=["a < b & c"], tables={"K": (["space", "K"], [["joint", 4]])}
        ),
        Section("Figures", figures=[Figure(PNG_1x1, "one pixel")], anchor="figs"),
    ]
    path = tmp_path / "report.html"
    write_report(path, "Title", sections, intro="hello")
    text = path.read_text(encoding="utf-8")
    assert text.startswith("<!DOCTYPE html>")
    assert "a &lt; b &amp; c" in text  # paragraphs are escaped
    assert '<td class="num">4</td>' in text
    assert 'href="#figs"' in text and 'id="figs"' in text
    images = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', text)
    assert [base64.b64decode(i) for i in images] == [PNG_1x1]
    # No external resource: nothing is fetched when the report is opened.
    assert not re.search(r'(src|href)="(https?:|//|[^#d])', text)


def test_booleans_render_as_yes_no() -> None:
    text = render_report("T", [Section("S", tables={"t": (["ok"], [[True], [False]])})])
    assert '<span class="ok">yes</span>' in text
    assert '<span class="fail">no</span>' in text
