"""MuJoCo for :mod:`pbdkit.sim`, imported once its headless OpenGL backend is chosen.

MuJoCo reads ``MUJOCO_GL`` once, at import time: every module of :mod:`pbdkit.sim` that uses
MuJoCo imports it from here (``from ._gl import mujoco``), so that the choice is made first,
and only when the simulation is used (``import pbdkit.sim`` imports no MuJoCo). A value set by
the user always wins. Otherwise EGL is used when ``libEGL`` can be found
(GPU or Mesa's software EGL, a few ms per 320x240 frame) and OSMesa when only ``libOSMesa`` is
installed (slower, but needs no display either).

If ``mujoco`` was already imported without ``MUJOCO_GL`` (it then picks GLFW, which needs an X
display), and no display exists and PyOpenGL is not loaded yet, the headless context class is
swapped in so that :class:`mujoco.Renderer` still works.
"""

from __future__ import annotations

import ctypes.util
import importlib
import os
import sys
from typing import Any

from .._defaults import install_hint


def _choose_backend() -> str:
    if ctypes.util.find_library("EGL") is not None:
        return "egl"
    if ctypes.util.find_library("OSMesa") is not None:
        return "osmesa"
    # Neither library: keep EGL so that the error raised at the first render names it.
    return "egl"


def _fix_up_late_import(backend: str) -> None:
    gl: Any = sys.modules.get("mujoco.rendering.classic.gl_context")
    if gl is None or "OpenGL" in sys.modules or os.environ.get("DISPLAY"):
        return
    if getattr(gl, "_MUJOCO_GL", "") != "":
        return  # the user chose a backend explicitly
    try:
        module = importlib.import_module("mujoco.osmesa" if backend == "osmesa" else "mujoco.egl")
    except ImportError:
        return
    gl.GLContext = module.GLContext


if "MUJOCO_GL" not in os.environ:
    os.environ["MUJOCO_GL"] = _choose_backend()
    # PyOpenGL needs the same choice to find the matching function pointers.
    os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])
    _fix_up_late_import(os.environ["MUJOCO_GL"])

BACKEND: str = os.environ["MUJOCO_GL"]

try:
    import mujoco
except ImportError as exc:  # pragma: no cover - depends on the environment
    raise ImportError(
        f"pbdkit.sim needs MuJoCo: install the 'sim' extra ({install_hint('sim')})"
    ) from exc

__all__ = ["BACKEND", "mujoco"]
