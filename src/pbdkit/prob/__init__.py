"""Probability: the GMM (:class:`GMM`), its choice of K (:class:`ModelSelection`), Gaussian mixture
regression (``GMM.regress``), task-parameterized frames (:class:`FrameModel`) and products of
Gaussians in information form (:mod:`pbdkit.prob.gaussian`).

The bottom layer: numpy, SciPy and scikit-learn only."""

from __future__ import annotations

from . import gaussian
from ._frames import FrameModel
from ._gmm import GMM
from ._selection import ModelSelection, SelectionWarning

__all__ = ["GMM", "FrameModel", "ModelSelection", "SelectionWarning", "gaussian"]
