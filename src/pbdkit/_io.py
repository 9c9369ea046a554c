"""Safe file I/O: atomic writes and pickle-free ``.npz`` archives."""

from __future__ import annotations

import errno
import io
import os
import secrets
import stat
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

__all__ = ["atomic_write_bytes", "load_npz_safe", "save_npz_atomic", "write_json"]

# Flags of the temporary file: created here, never reused (O_EXCL), never through a link.
_TMP_FLAGS = (
    os.O_WRONLY
    | os.O_CREAT
    | os.O_EXCL
    | getattr(os, "O_NOFOLLOW", 0)
    | getattr(os, "O_CLOEXEC", 0)
    | getattr(os, "O_BINARY", 0)
)
# What a zip archive (an .npz) starts with: a local file header, or the end record of an
# empty archive.
_ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")


def _create_temporary(folder: Path, name: str) -> tuple[int, Path]:
    """Create a new file ``.{name}.<random>.tmp`` in ``folder`` with mode 0o666 & ~umask.

    The kernel applies the process umask (or the directory's default ACL) to the mode given
    to ``open``, exactly as for a file a program creates with ``open(path, "wb")``. So the
    umask is never read: ``os.umask`` can only be read by setting it, which races with other
    threads, and ``/proc/self/status`` exists on Linux only. (``tempfile.mkstemp`` would give
    0o600 whatever the umask.)
    """
    for _ in range(100):
        tmp = folder / f".{name}.{secrets.token_hex(6)}.tmp"
        try:
            return os.open(tmp, _TMP_FLAGS, 0o666), tmp
        except FileExistsError:
            continue
    raise FileExistsError(f"could not create a temporary file in {folder}")  # pragma: no cover


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> None:
    """Write ``data`` to ``path`` so that readers see either the old file or the new one.

    The bytes go to a temporary file in the same directory, are flushed to disk (fsync), and
    the temporary file is renamed over the destination (``os.replace``, atomic on POSIX and
    Windows); on any error the temporary file is removed and the old file is left as it was.

    The result is what a plain ``open(path, "wb")`` would give, except for atomicity:

    - a new file gets the mode the umask gives (0o666 & ~umask: 0o644 under umask 022);
    - an existing file keeps its permission bits;
    - if ``path`` is a symbolic link, the file it points to is replaced (a dangling link
      gets its target created) and the link stays in place.

    Missing parent directories are created. The owner of a replaced file is not kept (the
    new file belongs to the writing user), nor are hard links to it.

    Raises
    ------
    IsADirectoryError
        If ``path`` (or the file a link at ``path`` points to) is a directory.
    OSError
        Any error creating, writing or renaming the file.
    """
    # Resolve links (of the file and of its folders) so that the temporary file is created
    # next to the file that is replaced, and the rename never replaces the link itself.
    target = Path(os.path.realpath(path))
    target.parent.mkdir(parents=True, exist_ok=True)
    try:
        st = os.stat(target)
    except FileNotFoundError:
        existing: int | None = None
    else:
        if stat.S_ISDIR(st.st_mode):
            raise IsADirectoryError(errno.EISDIR, "Is a directory, expected a file", str(path))
        existing = stat.S_IMODE(st.st_mode)
    fd, tmp = _create_temporary(target.parent, target.name)
    try:
        with os.fdopen(fd, "wb") as f:
            if existing is not None:
                os.chmod(tmp, existing)
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def save_npz_atomic(path: str | os.PathLike[str], arrays: Mapping[str, NDArray[Any]]) -> None:
    """Save arrays to an ``.npz`` file atomically; object arrays are refused (no pickle)."""
    for key, value in arrays.items():
        if np.asarray(value).dtype == object:
            raise TypeError(f"array {key!r} has dtype object, which would need pickle")
    buf = io.BytesIO()
    payload: dict[str, Any] = {k: np.asarray(v) for k, v in arrays.items()}
    np.savez_compressed(buf, **payload)
    atomic_write_bytes(path, buf.getvalue())


def load_npz_safe(path: str | os.PathLike[str], *, what: str = "file") -> dict[str, NDArray[Any]]:
    """Load every array of an ``.npz`` file with ``allow_pickle=False``.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the file is not a NumPy ``.npz`` archive (foreign content: it is not a zip file),
        is corrupt or truncated, or holds object arrays that would need pickle to load.
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{what} not found: {p}")
    try:
        # Open the file ourselves: np.load(path) leaks its handle when the archive is truncated.
        with open(p, "rb") as f:
            # np.load takes whatever is neither a zip nor an .npy file for a pickle (which
            # allow_pickle=False then refuses, "contains pickled data"): look at it first.
            if f.read(4) in _ZIP_MAGIC:
                f.seek(0)
                with np.load(f, allow_pickle=False) as data:
                    return {k: data[k] for k in data.files}
    except (zipfile.BadZipFile, OSError, EOFError, KeyError) as exc:
        raise ValueError(f"{p} is not a valid {what} (not a readable .npz archive): {exc}") from exc
    except ValueError as exc:  # e.g. an object array, which would need pickle
        raise ValueError(f"{p} is not a valid {what}: {exc}") from exc
    raise ValueError(
        f"{p} is not a NumPy .npz archive (it does not start like a zip file); expected a {what}"
    )


def _json_default(value: object) -> object:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    raise TypeError(f"not JSON serializable: {type(value).__name__}")


def write_json(path: str | os.PathLike[str], data: object, *, sort_keys: bool = False) -> None:
    """Write ``data`` as indented JSON, atomically (:func:`atomic_write_bytes`); NumPy arrays
    and scalars become lists and numbers."""
    import json

    text = json.dumps(data, indent=2, sort_keys=sort_keys, default=_json_default) + "\n"
    atomic_write_bytes(path, text.encode())
