"""The URDF text MuJoCo loads for a collision cross-check (shared by tests/test_collision_model.py
and benchmarks/bench_collision_model.py): collision geoms only, one body per link."""

from __future__ import annotations

import xml.etree.ElementTree as ET


def collision_only_urdf(urdf: str) -> str:
    """The URDF with its ``<mujoco>`` block replaced by one that drops the visuals and keeps
    every link a body of its own (``fusestatic="false"``)."""
    root = ET.fromstring(urdf)
    for old in root.findall("mujoco"):
        root.remove(old)
    options = ET.Element("mujoco")
    ET.SubElement(options, "compiler", {"discardvisual": "true", "fusestatic": "false"})
    root.insert(0, options)
    return ET.tostring(root, encoding="unicode")
