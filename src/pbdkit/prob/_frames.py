"""Frames (A, b): data seen from a frame, Gaussians mapped back to the world.

A frame is an invertible A (D, D) and an origin b (D,):

    x in the world        ->  A^-1 (x - b) in the frame               (:func:`to_local`)
    N(m, S) in the frame  ->  N(A m + b, A S A^T) in the world       (:func:`to_world`)
    precision L = S^-1    ->  A^-T L A^-1 (A L A^T only for an orthogonal A)

:class:`FrameModel` is a task-parameterized GMM (Calinon, "A tutorial on task-parameterized
movement learning and retrieval", Intelligent Service Robotics 9, 2016): one GMM per frame over
{t, A^-1 (x - b)}; for new frames, GMR in each frame, mapped to the world, and the product
Lambda = sum_p A_p^-T S_p^-1 A_p^-1 (:func:`product_in_world`). Why, and how a frame wins where
the demonstrations agree: ``docs/math.md``, "Frames (TP-GMM)".

File format (:meth:`FrameModel.save` / :meth:`FrameModel.load`): a NumPy ``.npz`` archive, no
pickle, written atomically. Keys: ``format`` = ``"pbdkit-frame-model"``, ``version`` = 1,
``n_frames`` (P >= 1), ``n_dims`` (D >= 1), and for every frame p in 0 .. P-1
``gmm_{p}_weights`` (K,), ``gmm_{p}_means`` (K, 1 + D) and ``gmm_{p}_covariances``
(K, 1 + D, 1 + D). :meth:`FrameModel.load` judges the archive from its headers before it loads
an array: any other key, or arrays of more than :data:`MAX_FILE_BYTES` in all, are refused;
then values that are not finite, means beyond :data:`MAX_MAGNITUDE` and covariances beyond its
square (what :meth:`FrameModel.learn` gives), naming the key.
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
from numpy.typing import NDArray

from .._defaults import MAX_COMPONENTS
from .._io import NpzArchive, check_format, open_npz, save_npz_atomic
from .._validation import check_array, check_int, check_trajectories, short
from ._gmm import GMM
from ._gmr import CovarianceMode
from .gaussian import precision_from_covariance, product_information

__all__ = [
    "FrameModel",
    "covariance_to_world",
    "precision_to_world",
    "product_in_world",
    "to_local",
    "to_world",
]

Float = NDArray[np.float64]
#: A frame (A, b): A (D, D) invertible, b (D,).
Frame = tuple[npt.ArrayLike, npt.ArrayLike]

FORMAT_NAME = "pbdkit-frame-model"
FORMAT_VERSION = 1
#: The most bytes the arrays of a frame-model file may take once loaded (16 MiB), read from the
#: archive's headers before anything is loaded. A model of 10 frames in 10 dimensions with 30
#: components each takes about 0.3 MB.
MAX_FILE_BYTES = 2**24
#: Largest condition number of a frame's A (the ratio of its largest to its smallest singular
#: value) that :meth:`FrameModel.learn` and :meth:`FrameModel.reproduce` accept: beyond it,
#: A^-1 (x - b) loses more than 12 of float64's 16 digits, and A is taken as singular.
MAX_CONDITION = 1e12
#: The range of a frame's scale, the singular values of its A, that :meth:`FrameModel.learn` and
#: :meth:`FrameModel.reproduce` accept: A = 1e-200 I (condition number 1) made A^-1 (x - b)
#: overflow EM's statistics, and A S A^T underflow to 0 (NaN predictions).
FRAME_SCALE_RANGE = (1e-9, 1e9)
#: Largest magnitude of a time, a coordinate, a frame's origin b and a coordinate seen from a
#: frame, A^-1 (x - b), that :meth:`FrameModel.learn` takes (and of a loaded model's means; its
#: covariances up to the square): EM squares and sums them, which overflowed from 1e150 on.
MAX_MAGNITUDE = 1e15


def to_local(a: npt.ArrayLike, b: npt.ArrayLike, x: npt.ArrayLike) -> Float:
    """A^-1 (x - b): world points x (..., D) seen from the frame (A (D, D), b (D,)); batched
    frames (..., D, D) and (..., D) broadcast against x."""
    am = np.asarray(a, dtype=np.float64)
    d = np.asarray(x, dtype=np.float64) - np.asarray(b, dtype=np.float64)
    return np.asarray(np.linalg.solve(am, d[..., None])[..., 0], dtype=np.float64)


def covariance_to_world(a: npt.ArrayLike, cov: npt.ArrayLike) -> Float:
    """A S A^T for covariances S (..., D, D) and frames A (..., D, D)."""
    am = np.asarray(a, dtype=np.float64)
    return np.asarray(am @ np.asarray(cov, dtype=np.float64) @ np.swapaxes(am, -1, -2))


def precision_to_world(a: npt.ArrayLike, prec: npt.ArrayLike) -> Float:
    """A^-T L A^-1 for precisions L (..., D, D) and frames A (..., D, D): the inverse of
    A S A^T. Equal to A L A^T only when A is orthogonal (a rotation or a reflection)."""
    ainv = np.linalg.inv(np.asarray(a, dtype=np.float64))
    return np.asarray(np.swapaxes(ainv, -1, -2) @ np.asarray(prec, dtype=np.float64) @ ainv)


def to_world(
    a: npt.ArrayLike, b: npt.ArrayLike, mean: npt.ArrayLike, cov: npt.ArrayLike
) -> tuple[Float, Float]:
    """A Gaussian of the frame (A, b) in the world: mean A m + b (..., D), covariance
    A S A^T (..., D, D)."""
    am = np.asarray(a, dtype=np.float64)
    m = np.einsum("...ij,...j->...i", am, np.asarray(mean, dtype=np.float64))
    return m + np.asarray(b, dtype=np.float64), covariance_to_world(am, cov)


def product_in_world(
    a: npt.ArrayLike, b: npt.ArrayLike, means: npt.ArrayLike, covariances: npt.ArrayLike
) -> tuple[Float, Float]:
    """The product of P frames' Gaussians, each mapped from its frame to the world.

    Frame p's Gaussian N(m_p, S_p) is N(A_p m_p + b_p, A_p S_p A_p^T) in the world
    (:func:`to_world`), with precision A_p^-T S_p^-1 A_p^-1 (:func:`precision_to_world`); the
    product has precision sum_p A_p^-T S_p^-1 A_p^-1 and mean
    (sum_p Lambda_p)^-1 sum_p Lambda_p (A_p m_p + b_p)
    (:func:`pbdkit.prob.gaussian.product_information`). :class:`FrameModel` predicts with it;
    the position part of :class:`pbdkit.Skill` uses the same mapping.

    Parameters
    ----------
    a : array-like, shape (P, D, D)
        The frames' matrices, invertible.
    b : array-like, shape (P, D)
        The frames' origins.
    means : array-like, shape (T, P, D)
        Each frame's mean at T moments, in the frame's coordinates.
    covariances : array-like, shape (T, P, D, D)
        Each frame's covariance, in the frame's coordinates; symmetric positive definite.

    Returns
    -------
    mean : ndarray, shape (T, D)
    covariance : ndarray, shape (T, D, D)
    """
    am = check_array(a, "a", ndim=3)
    p, d = am.shape[0], am.shape[1]
    bv = check_array(b, "b", shape=(p, d))
    m = check_array(means, "means", shape=(None, p, d))
    cov = check_array(covariances, "covariances", shape=(m.shape[0], p, d, d))
    world_mean, _ = to_world(am, bv, m, cov)
    prec = precision_to_world(am, precision_from_covariance(cov))
    prec = 0.5 * (prec + np.swapaxes(prec, -1, -2))
    return product_information(world_mean, prec, check=False)


def _check_frames(
    frames: object, name: str, n_dims: int, n_frames: int | None = None, why: str = ""
) -> tuple[Float, Float]:
    """The frames (A, b) of one demonstration (or of a reproduction) as arrays A (P, D, D) and
    b (P, D), validated: P pairs (``n_frames`` if given; ``why`` says why, in the message),
    A invertible, everything finite."""
    if isinstance(frames, (str, bytes)):
        raise ValueError(f"{name} must be a list of frames (A, b), got a string")
    try:
        items = list(frames)  # type: ignore[call-overload]
    except TypeError:
        raise ValueError(
            f"{name} must be a list of frames (A, b), got {type(frames).__name__}"
        ) from None
    if not items:
        raise ValueError(f"{name} must hold at least one frame (A, b), got none")
    if n_frames is not None and len(items) != n_frames:
        raise ValueError(f"{name} must hold {n_frames} frames (A, b){why}, got {len(items)}")
    a = np.empty((len(items), n_dims, n_dims))
    b = np.empty((len(items), n_dims))
    for p, item in enumerate(items):
        try:
            a_p, b_p = item
        except (TypeError, ValueError):
            raise ValueError(
                f"{name}[{p}] must be a pair (A, b), A ({n_dims}, {n_dims}) and b ({n_dims},), "
                f"got {type(item).__name__}"
                + (f" of length {len(item)}" if hasattr(item, "__len__") else "")
            ) from None
        a[p] = check_array(a_p, f"{name}[{p}] A", shape=(n_dims, n_dims))
        b[p] = check_array(b_p, f"{name}[{p}] b", shape=(n_dims,))
        with np.errstate(over="ignore", invalid="ignore"):  # entries near 1e308
            scale = np.linalg.svd(a[p], compute_uv=False)
        cond = float(scale[0] / scale[-1]) if scale[-1] > 0 else float("inf")
        if not cond <= MAX_CONDITION:
            raise ValueError(
                f"{name}[{p}] A must be invertible (a rotation, scaling, reflection or a "
                f"product of them), got a singular matrix (condition number {cond:.3g}, "
                f"more than MAX_CONDITION = {MAX_CONDITION:g}): {a[p].tolist()}"
            )
        low, high = FRAME_SCALE_RANGE
        if not (low <= scale[-1] and scale[0] <= high):
            raise ValueError(
                f"{name}[{p}] A must scale by {low:g} to {high:g} (its singular values, "
                f"FRAME_SCALE_RANGE), got singular values from {scale[-1]:.3g} to {scale[0]:.3g}"
            )
        _check_magnitude(b[p], f"{name}[{p}] b")
    return a, b


def _check_magnitude(x: Float, name: str, what: str = "") -> None:
    """Refuse values above :data:`MAX_MAGNITUDE` in magnitude, naming ``name``."""
    top = float(np.max(np.abs(x))) if x.size else 0.0
    if top > MAX_MAGNITUDE:
        raise ValueError(
            f"{name}{what} must be at most MAX_MAGNITUDE = {MAX_MAGNITUDE:g} in magnitude, "
            f"got {top:.3g}"
        )


def _check_random_state(value: object) -> int | np.random.RandomState | None:
    """``random_state`` as scikit-learn takes it: None, an integer in [0, 2**32 - 1] or a
    numpy RandomState."""
    if value is None or isinstance(value, np.random.RandomState):
        return value
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        seed = int(value)
        if 0 <= seed < 2**32:
            return seed
    raise ValueError(
        "random_state must be None, an integer in [0, 2**32 - 1] or a numpy RandomState, "
        f"got {short(value)}"
    )


class FrameModel:
    """A task-parameterized model: one GMM per frame, the product of the frames at reproduction.

    Build it with :meth:`learn` or :meth:`load` (``docs/math.md``, "Frames (TP-GMM)").
    Robot-free: the data are D-dimensional points over time, the frames any invertible affine
    maps.

    Parameters
    ----------
    gmms : sequence of GMM
        One fitted :class:`pbdkit.GMM` per frame, over {t, A^-1 (x - b)}: all with 1 + D
        dimensions, time first.

    Attributes
    ----------
    gmms : list of GMM
        The GMM of each frame, over the time and the D coordinates seen from the frame.
    """

    def __init__(self, gmms: Sequence[GMM]) -> None:
        items = list(gmms)
        if not items:
            raise ValueError("gmms must hold one fitted GMM per frame, got none")
        for p, g in enumerate(items):
            if not isinstance(g, GMM) or not hasattr(g, "covariances_"):
                raise ValueError(f"gmms[{p}] must be a fitted GMM, got {short(g)}")
        dims = [int(g.n_dims_) for g in items]
        if dims[0] < 2 or any(d != dims[0] for d in dims):
            raise ValueError(
                "gmms must all have the same 1 + D dimensions (time, then D >= 1 coordinates), "
                f"got {dims}"
            )
        self.gmms = items

    @property
    def n_frames(self) -> int:
        """Number of frames P."""
        return len(self.gmms)

    @property
    def n_dims(self) -> int:
        """Number of coordinates D (time excluded)."""
        return int(self.gmms[0].n_dims_) - 1

    @property
    def n_components(self) -> list[int]:
        """K of each frame's GMM."""
        return [int(g.n_components_) for g in self.gmms]

    def __repr__(self) -> str:
        return (
            f"FrameModel(n_frames={self.n_frames}, n_dims={self.n_dims}, "
            f"n_components={self.n_components})"
        )

    @classmethod
    def learn(
        cls,
        trajectories: Sequence[npt.ArrayLike],
        frames: Sequence[Sequence[Frame]],
        n_components: int | Literal["auto", "bic"] = "auto",
        max_components: int = MAX_COMPONENTS,
        reg_covar: float | npt.ArrayLike | None = None,
        random_state: int | np.random.RandomState | None = 0,
        fit_samples: int | None = 100,
    ) -> FrameModel:
        """Learn from demonstrations and the frames each was recorded with.

        For every frame p, the data of all demonstrations seen from it, {t, A_p^-1 (x - b_p)},
        get one GMM (:class:`pbdkit.GMM`), fitted with the demonstration as the group of each
        row: ``n_components="auto"`` chooses K by leaving one demonstration out at a time.

        Parameters
        ----------
        trajectories : sequence of array-like, shape (T_i, 1 + D)
            At least 2 demonstrations, time in column 0 (any unit, the same for all: for
            demonstrations of different durations a phase, such as t / duration, aligns their
            moments), then the D coordinates x. T_i >= 2 may differ. Times and coordinates
            (and the coordinates seen from each frame) at most :data:`MAX_MAGNITUDE` (1e15) in
            magnitude.
        frames : sequence of sequence of (A, b)
            Per demonstration, its P frames, the same P for all: A array-like (D, D),
            invertible (a rotation, scaling, reflection or a product of them; a condition
            number up to :data:`MAX_CONDITION`, singular values in
            :data:`FRAME_SCALE_RANGE`), b array-like (D,).
        n_components : int, "auto" or "bic"
            K of every frame's GMM, or how to choose it per frame (:class:`pbdkit.GMM`).
        max_components : int
            Largest K tried when K is chosen.
        reg_covar : float, array-like of shape (1 + D,), or None
            Added to the diagonal of every covariance, in each frame's units squared (time's,
            then the coordinates seen from the frame). None: :class:`pbdkit.GMM`'s
            scale-aware default.
        random_state : int, numpy RandomState or None
            Passed to the GMMs (an integer in [0, 2**32 - 1], as scikit-learn's).
        fit_samples : int or None
            Number of evenly spaced samples per demonstration given to EM (all if None or
            larger than T_i), as in :meth:`pbdkit.Skill.learn`: consecutive samples of a smooth
            motion carry little new information, and EM's cost grows with the samples.

        Returns
        -------
        model : FrameModel

        Raises
        ------
        ValueError
            Fewer than 2 demonstrations, shapes that do not match, NaN or infinite values, a
            singular A, frames of different P, or a GMM that cannot be fitted (the message names
            the frame).
        """
        xs = check_trajectories(
            trajectories,
            "trajectories",
            what="demonstration",
            why=" (what varies between them is what the model learns)",
        )
        for i, x in enumerate(xs):
            _check_magnitude(x[:, 0], f"trajectories[{i}][:, 0]", " (time)")
            _check_magnitude(x[:, 1:], f"trajectories[{i}][:, 1:]", " (coordinates)")
        random_state = _check_random_state(random_state)
        d = xs[0].shape[1] - 1
        given: object = frames
        per_demo = None if isinstance(given, (str, bytes, np.ndarray)) else given
        if not isinstance(per_demo, Sequence):
            raise ValueError(
                "frames must be a list, per demonstration, of its frames (A, b), "
                f"got {type(given).__name__}"
            )
        if len(per_demo) != len(xs):
            raise ValueError(
                f"frames must hold one list of frames (A, b) per demonstration, {len(xs)}, "
                f"got {len(per_demo)}"
            )
        checked = [_check_frames(per_demo[0], "frames[0]", d)]
        n_frames = checked[0][0].shape[0]
        same = " as frames[0] does: every demonstration has the same frames"
        checked += [
            _check_frames(per_demo[i], f"frames[{i}]", d, n_frames, same) for i in range(1, len(xs))
        ]
        n_fit = None if fit_samples is None else check_int(fit_samples, "fit_samples", minimum=2)
        rows = []
        for x in xs:
            n = x.shape[0] if n_fit is None else min(n_fit, x.shape[0])
            rows.append(np.unique(np.round(np.linspace(0, x.shape[0] - 1, n)).astype(np.intp)))
        groups = np.concatenate([np.full(r.shape[0], i) for i, r in enumerate(rows)])
        t = np.concatenate([x[r, 0] for x, r in zip(xs, rows, strict=True)])
        gmms = []
        for p in range(n_frames):
            parts = []
            for i, ((a, b), x, r) in enumerate(zip(checked, xs, rows, strict=True)):
                parts.append(to_local(a[p], b[p], x[r, 1:]))
                seen = f" (trajectories[{i}] seen from the frame, A^-1 (x - b))"
                _check_magnitude(parts[-1], f"frames[{i}][{p}]", seen)
            local = np.concatenate(parts)
            gmm = GMM(
                n_components=n_components,
                max_components=max_components,
                reg_covar=reg_covar,
                random_state=random_state,
            )
            try:
                gmms.append(gmm.fit(np.column_stack([t, local]), groups=groups))
            except ValueError as exc:
                raise ValueError(f"frame {p}: {exc}") from exc
        return cls(gmms)

    def reproduce(
        self,
        frames: Sequence[Frame],
        t: npt.ArrayLike,
        covariance: CovarianceMode = "exact",
    ) -> tuple[Float, Float]:
        """The prediction for new frames: the product of the frames' Gaussians, in the world.

        GMR of each frame's GMM at the times t (mean m_p(t), covariance S_p(t), in the frame)
        is mapped to the world with the new frame, mean A_p m_p + b_p and precision
        A_p^-T S_p^-1 A_p^-1, and the P Gaussians are multiplied (:func:`product_in_world`).

        Parameters
        ----------
        frames : sequence of (A, b)
            The P new frames, in the order of learning: A array-like (D, D), invertible, its
            singular values in :data:`FRAME_SCALE_RANGE`; b array-like (D,), at most
            :data:`MAX_MAGNITUDE` in magnitude.
        t : array-like, shape (T,)
            Times, in the unit of the demonstrations' column 0, at most :data:`MAX_MAGNITUDE`
            in magnitude.
        covariance : {"exact", "paper"}
            GMR covariance (:meth:`pbdkit.GMM.regress`).

        Returns
        -------
        mean : ndarray, shape (T, D)
        covariance : ndarray, shape (T, D, D)
        """
        a, b = _check_frames(
            frames, "frames", self.n_dims, self.n_frames, ", one per frame learned"
        )
        tv = check_array(t, "t", ndim=1, min_rows=1)
        _check_magnitude(tv, "t")
        local = [g.regress(tv[:, None], in_dims=[0], covariance=covariance) for g in self.gmms]
        means = np.stack([m for m, _ in local], axis=1)
        covs = np.stack([c for _, c in local], axis=1)
        return product_in_world(a, b, means, covs)

    # ------------------------------------------------------------------ I/O
    def save(self, path: str | os.PathLike[str]) -> None:
        """Save the model to a versioned ``.npz`` file (no pickle, written atomically; module
        docstring). How K was chosen is not stored.

        Parameters
        ----------
        path : str or path-like
        """
        arrays: dict[str, Any] = {
            "format": np.array(FORMAT_NAME),
            "version": np.array(FORMAT_VERSION, dtype=np.int64),
            "n_frames": np.array(self.n_frames, dtype=np.int64),
            "n_dims": np.array(self.n_dims, dtype=np.int64),
        }
        for p, g in enumerate(self.gmms):
            arrays[f"gmm_{p}_weights"] = g.weights_
            arrays[f"gmm_{p}_means"] = g.means_
            arrays[f"gmm_{p}_covariances"] = g.covariances_
        save_npz_atomic(path, arrays, what="FrameModel", max_bytes=MAX_FILE_BYTES)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> FrameModel:
        """Load a model saved by :meth:`save`.

        Parameters
        ----------
        path : str or path-like

        Returns
        -------
        model : FrameModel
            Reproduces bit-identical results to the model that was saved. Its GMMs'
            ``selection_`` is ``"fixed"`` (the file does not record how K was chosen).

        Raises
        ------
        FileNotFoundError
            If ``path`` does not exist.
        ValueError
            A corrupt or foreign file, another format version, a key the format does not have,
            arrays of more than :data:`MAX_FILE_BYTES` in all, or inconsistent content.
        """
        p = Path(path)
        with open_npz(p, what=FORMAT_NAME + " file", max_bytes=MAX_FILE_BYTES) as data:
            return cls._from_archive(data, p)

    @classmethod
    def _from_archive(cls, data: NpzArchive, p: Path) -> FrameModel:
        check_format(data, p, FORMAT_NAME, FORMAT_VERSION)
        data.check_keys(lambda k: k in _BASE_KEYS or _GMM_KEY.fullmatch(k) is not None)
        bad = f"{p} is not a valid {FORMAT_NAME} file"
        try:
            n_frames = _stored_int(data["n_frames"])
            n_dims = _stored_int(data["n_dims"])
            if n_frames is None or n_frames < 1:
                raise ValueError(f"n_frames must be an integer >= 1, got {short(data['n_frames'])}")
            if n_dims is None or n_dims < 1:
                raise ValueError(f"n_dims must be an integer >= 1, got {short(data['n_dims'])}")
            extra = [k for k in data if k.startswith("gmm_") and int(k.split("_")[1]) >= n_frames]
            if extra:
                raise ValueError(f"key {short(extra[0])} for a frame beyond n_frames = {n_frames}")
            gmms = [_stored_gmm(data, i) for i in range(n_frames)]
        except KeyError as exc:
            raise ValueError(f"{bad}: missing key {exc}") from exc
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{bad}: {exc}") from exc
        dims = [int(g.n_dims_) for g in gmms]
        if any(k != 1 + n_dims for k in dims):
            raise ValueError(
                f"{bad}: GMM dimensions {dims}, expected {1 + n_dims} for each frame "
                f"(time and n_dims = {n_dims} coordinates)"
            )
        return cls(gmms)


_BASE_KEYS = frozenset({"format", "version", "n_frames", "n_dims"})
_GMM_KEY = re.compile(r"gmm_(0|[1-9][0-9]{0,5})_(?:weights|means|covariances)")


def _stored_gmm(data: NpzArchive, i: int) -> GMM:
    """Frame ``i``'s GMM of a file, its arrays checked by key: real, finite, and means and
    covariances within what :meth:`FrameModel.learn` gives (:data:`MAX_MAGNITUDE`, squared for
    the covariances): means of 1e308 made every prediction NaN."""
    arrays = {}
    bounds = {"weights": np.inf, "means": MAX_MAGNITUDE, "covariances": MAX_MAGNITUDE**2}
    for kind, bound in bounds.items():
        key = f"gmm_{i}_{kind}"
        arr = check_array(data[key], key)
        top = float(np.max(np.abs(arr))) if arr.size else 0.0
        if top > bound:
            raise ValueError(
                f"{key} must be at most {bound:g} in magnitude (MAX_MAGNITUDE"
                f"{'' if kind == 'means' else ' squared'}, as learn gives), got {top:.3g}"
            )
        arrays[kind] = arr
    return GMM.from_params(arrays["weights"], arrays["means"], arrays["covariances"])


def _stored_int(value: NDArray[Any]) -> int | None:
    """The integer stored in a 0-d integer array of a file, or None if it holds anything else."""
    arr = np.asarray(value)
    return int(arr) if arr.shape == () and arr.dtype.kind in "iu" else None
