"""Applications on top of the library: the ``pbdkit`` command (:func:`main`), its
``demo`` and ``study`` jobs, the paper's figures, the HTML report and the live view.

The top layer: nothing below imports it. Its modules are private; what a user runs is the
command (``pbdkit --help``, or ``python -m pbdkit``)."""

from __future__ import annotations

from ._cli import main

__all__ = ["main"]
