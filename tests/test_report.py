"""The HTML report: self-contained, every section present, images decode to the PNGs given."""

from __future__ import annotations

import base64
import re
from pathlib import Path

import numpy as np
import pytest

from pbdkit.apps._report import Figure, Section, render_report, write_report

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


# ----------------------------------------------------------------------------- poses (issue 23)
def test_orientation_section_shows_which_objects_are_oriented_and_the_angles() -> None:
    import pose_teacher

    from pbdkit.apps._report import closest_approach, orientation_section
    from pbdkit.robots import panda
    from pbdkit.skill._skill import Skill

    robot = panda()
    demos = pose_teacher.demonstrations(robot)
    skill = Skill.learn(demos, robot, n_steps=40, n_components=3)
    pose = pose_teacher.mug_pose(0.6, 0.5, 0.05)
    fused, joint = skill.reproduce({"mug": pose}), skill.reproduce({"mug": pose}, use=["joint"])
    # Closest approach: the smallest distance, and the angle at that same sample.
    approach = closest_approach(fused)
    j = int(np.argmin(fused.task_errors["mug"]))
    assert approach == {
        "mug": (
            pytest.approx(1000 * fused.task_errors["mug"][j]),
            pytest.approx(np.degrees(fused.orientation_errors["mug"][j])),
        )
    }
    section = orientation_section(skill, {"fused": fused, "joint": joint})
    assert section is not None
    text = render_report("T", [section])
    assert "Learned with orientation: mug." in text
    assert "<td>position and orientation, in the object&#x27;s frame</td>" in text
    assert "<th>mug (mm)</th>\n<th>mug (deg)</th>" in text
    for name, res in (("fused", fused), ("joint", joint)):
        mm, deg = closest_approach(res)["mug"]
        assert deg is not None and 0.0 < deg < 180.0
        assert (
            f'<td>{name}</td>\n<td class="num">{mm:.4g}</td>\n<td class="num">{deg:.4g}</td>'
            in text
        )
    # The tightest orientation spread, in degrees, from the skill's constraints.
    cov = skill.constraints().task_cov["mug"][:, 3:, 3:]
    tightest = np.degrees(np.sqrt(np.trace(cov, axis1=1, axis2=2))).min()
    assert f'<td class="num">{tightest:.4g}</td>' in text
    # A position-only skill (the paper's tasks) has no such section: its report is unchanged.
    flat = Skill.learn(demos, robot, n_steps=40, n_components=3, orientation=False)
    assert flat.oriented == []
    assert orientation_section(flat, {"fused": flat.reproduce({"mug": pose})}) is None
    assert closest_approach(flat.reproduce({"mug": pose}))["mug"][1] is None
