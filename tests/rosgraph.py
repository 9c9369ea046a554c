"""Shared by the tests that speak ROS 2 (issue 37): a script run on a private graph. As root
(CI) in its own network namespace (``unshare -n``, then the loopback up: no discovery traffic
leaves it); otherwise with discovery on localhost only. Either way with a ROS_DOMAIN_ID drawn
from the test's name."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from pbdkit.ros._graph import private_graph_env, ros_available

CASES = Path(__file__).parent / "ros_cases.py"


def needs_ros() -> None:
    if not ros_available():
        pytest.skip("the ros extra is not installed (pip install -e '.[ros]')")


def run_on_private_graph(
    name: str, *args: str, timeout: float = 60.0, script: Path = CASES
) -> subprocess.CompletedProcess[str]:
    """``python SCRIPT ARGS`` (default ``tests/ros_cases.py``) on a private graph; its output
    captured."""
    needs_ros()
    env = private_graph_env(name)
    cmd = [sys.executable, str(script), *args]
    if os.geteuid() == 0 and shutil.which("unshare") and shutil.which("ip"):
        inner = " ".join(["ip link set lo up &&", "exec", *map(_quote, cmd)])
        cmd = ["unshare", "-n", "sh", "-c", inner]
    return subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=timeout)


def _quote(s: str) -> str:
    return "'" + s.replace("'", "'\"'\"'") + "'"
