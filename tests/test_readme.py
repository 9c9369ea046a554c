"""The front door does not drift (issue 40): every code block of README.md and of the docs'
quickstart runs here, or is marked as needing a robot, and every ``pbdkit`` command they name
still parses.

A fenced block is preceded by a marker, ``<!-- readme-test: KIND -->`` (GitHub and the docs hide
it):

- ``writes FILE ...``: a Python block, run as a script in an empty folder; it must write those
  files, and a skill it saves must load with the K it printed;
- ``make``: ``make TARGET`` lines; each target's recipe is checked by ``make -n`` (``make test``
  is what CI runs, ``.ci/run``; ``make demo``'s ``pbdkit demo`` is run by tests/test_demo.py);
- ``install``: ``pip install`` lines; the extras they name exist in pyproject.toml;
- ``needs a robot``: commands that talk to a live arm; they must still parse (their options
  exist), as every ``pbdkit`` command in the prose must.
"""

from __future__ import annotations

import ast
import re
import shlex
import subprocess
import sys
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest
from trajectory_bag import read_trajectory
from typer.testing import CliRunner

import pbdkit
from pbdkit.apps._cli import app

ROOT = Path(__file__).resolve().parent.parent
PAGES = (ROOT / "README.md", ROOT / "docs" / "quickstart.md")
_MARKER = re.compile(r"^<!-- readme-test: (?P<kind>.+?) -->$")
_FENCE = re.compile(r"^```(?P<lang>\S*)")
_INLINE = re.compile(r"`(pbdkit [^`]+)`")
KINDS = ("writes", "make", "install", "needs a robot")


class Block(NamedTuple):
    page: str
    line: int
    lang: str
    kind: str
    code: str


def code_blocks(text: str, page: str) -> list[Block]:
    """Every fenced block of a Markdown page (not a MyST directive: ```{name}), with the marker
    on the line before its fence ('' without one)."""
    lines = text.splitlines()
    blocks: list[Block] = []
    i = 0
    while i < len(lines):
        m = _FENCE.match(lines[i])
        if m is None:
            i += 1
            continue
        end = next(j for j in range(i + 1, len(lines)) if lines[j].startswith("```"))
        marker = _MARKER.match(lines[i - 1]) if i else None
        kind = marker.group("kind") if marker else ""
        code = "\n".join(lines[i + 1 : end])
        if not m.group("lang").startswith("{"):  # a MyST directive is not code
            blocks.append(Block(page, i + 1, m.group("lang"), kind, code))
        i = end + 1
    return blocks


def commands(code: str) -> list[list[str]]:
    """The shell commands of a block: one per line, comments dropped."""
    return [c for c in (shlex.split(line, comments=True) for line in code.splitlines()) if c]


def prose_commands(text: str) -> list[list[str]]:
    """``pbdkit ...`` in inline code outside the fenced blocks (a command may wrap a line)."""
    text = re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)
    return [shlex.split(m.group(1).replace("\n", " ")) for m in _INLINE.finditer(text)]


BLOCKS = [b for page in PAGES for b in code_blocks(page.read_text(encoding="utf-8"), page.name)]


def _id(block: Block) -> str:
    return f"{block.page}:{block.line}"


def test_the_pages_have_blocks_of_every_kind() -> None:
    # The parser finds what the pages hold (a parser that found nothing would pass everything).
    assert {b.kind.split()[0] for b in BLOCKS if b.kind} == {"writes", "make", "install", "needs"}
    assert any(b.page == "quickstart.md" for b in BLOCKS)


def test_a_block_without_a_marker_is_found() -> None:
    text = "intro\n<!-- readme-test: make -->\n```bash\nmake demo\n```\n\n```python\nx = 1\n```\n"
    blocks = [(b.kind, b.lang, b.code, b.line) for b in code_blocks(text, "probe")]
    assert blocks == [("make", "bash", "make demo", 3), ("", "python", "x = 1", 7)]
    assert prose_commands("run `pbdkit demo\n--task basin`\n```\n`pbdkit view`\n```\n") == [
        ["pbdkit", "demo", "--task", "basin"]
    ]


@pytest.mark.parametrize("block", BLOCKS, ids=_id)
def test_every_block_is_run_here_or_needs_a_robot(block: Block) -> None:
    assert block.kind.startswith(KINDS), (
        f"{block.page}:{block.line}: a {block.lang or 'plain'} block without a readme-test "
        f"marker; precede it with <!-- readme-test: KIND --> (one of {KINDS})"
    )
    if block.kind.startswith("writes"):
        assert block.lang == "python"
        ast.parse(block.code)
    else:
        assert block.lang == "bash" and commands(block.code)


@pytest.mark.slow
@pytest.mark.parametrize("block", [b for b in BLOCKS if b.kind.startswith("writes")], ids=_id)
def test_the_python_blocks_run_and_write_what_they_say(block: Block, tmp_path: Path) -> None:
    run = subprocess.run(
        [sys.executable, "-c", block.code],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stderr[-3000:]
    for name in block.kind.split()[1:]:
        assert (tmp_path / name).exists(), f"{block.page}:{block.line} did not write {name}"
    if (tmp_path / "skill.npz").exists():
        skill = pbdkit.Skill.load(tmp_path / "skill.npz")
        printed = ast.literal_eval(run.stdout.split("}")[0] + "}")
        assert skill.n_components == printed
    if (tmp_path / "trajectory").exists():
        # A joint trajectory for the skill's arm: its joints by name, in time order, in limits.
        traj = read_trajectory(tmp_path / "trajectory")
        robot = skill.robot
        assert traj.names == list(robot.joint_names)
        assert len(traj.t) > 100 and np.all(np.diff(traj.t) > 0)
        assert np.all(traj.q >= robot.lower - 1e-9) and np.all(traj.q <= robot.upper + 1e-9)


@pytest.mark.parametrize("block", [b for b in BLOCKS if b.kind == "make"], ids=_id)
def test_the_make_targets_do_what_the_page_says(block: Block) -> None:
    recipes = {"demo": "pbdkit demo", "test": "pytest"}
    targets = [c[1] for c in commands(block.code) if c[0] == "make"]
    assert "demo" in targets and "test" in targets
    for target in targets:
        # -n: print the recipe without running it; -B: as on a fresh clone (nothing installed).
        dry = subprocess.run(
            ["make", "-n", "-B", target], cwd=ROOT, capture_output=True, text=True, timeout=60
        )
        assert dry.returncode == 0, dry.stderr
        assert recipes[target] in dry.stdout
        assert "pip install" in dry.stdout  # installs what it needs on a fresh machine
    assert "make test" in (ROOT / ".ci" / "run").read_text()  # CI runs the README's command


@pytest.mark.parametrize("block", [b for b in BLOCKS if b.kind == "install"], ids=_id)
def test_the_install_lines_name_extras_that_exist(block: Block) -> None:
    pyproject = (ROOT / "pyproject.toml").read_text()
    section = pyproject.split("[project.optional-dependencies]")[1].split("\n[")[0]
    extras = set(re.findall(r"^([\w-]+) = \[", section, flags=re.M))
    assert {"sim", "view", "ros"} <= extras
    named = set(re.findall(r"\[([\w,]+)\]", block.code)) | set(
        re.findall(r"extras: ([\w ,()-]+)", block.code)
    )
    found = {e for group in named for e in re.findall(r"\b(\w+)\b", group)} & extras
    assert found, block.code
    for line in commands(block.code):
        if line[:2] == ["pip", "install"]:
            target = line[-1]
            spec = re.fullmatch(r"\.(?:\[(?P<extras>[\w,]+)\])?", target)
            if spec is None:
                assert target.startswith("dist/pbdkit-"), target
            elif spec.group("extras"):
                assert set(spec.group("extras").split(",")) <= extras
    assert re.search(r'^name = "pbdkit"$', pyproject, flags=re.M)


def _parse(args: list[str]) -> None:
    assert args[0] == "pbdkit"
    result = CliRunner().invoke(app, [*args[1:], "--help"])
    assert result.exit_code == 0, f"{shlex.join(args)}: {result.output[-800:]}"


@pytest.mark.parametrize("block", [b for b in BLOCKS if b.kind == "needs a robot"], ids=_id)
def test_the_robot_commands_parse(block: Block) -> None:
    for args in commands(block.code):
        _parse(args)


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_every_command_in_the_prose_parses(page: Path) -> None:
    found = prose_commands(page.read_text(encoding="utf-8"))
    assert found, page
    for args in found:
        _parse(args)


def test_a_misspelt_option_is_caught() -> None:
    with pytest.raises(AssertionError, match="No such option"):
        _parse(["pbdkit", "evaluate", "--task", "coaster", "--trails", "50"])
