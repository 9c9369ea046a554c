"""Safe file I/O: atomic writes and pickle-free ``.npz`` archives."""

from __future__ import annotations

import errno
import io
import math
import os
import secrets
import stat
import struct
import zipfile
import zlib
from collections.abc import Callable, Collection, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ._validation import short

__all__ = [
    "MAX_NPZ_BYTES",
    "NpyHeader",
    "NpzArchive",
    "atomic_write_bytes",
    "check_format",
    "open_npz",
    "save_npz_atomic",
    "write_json",
]

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


def save_npz_atomic(
    path: str | os.PathLike[str],
    arrays: Mapping[str, NDArray[Any]],
    *,
    what: str = "arrays",
    max_bytes: int | None = None,
) -> None:
    """Save arrays to an ``.npz`` file atomically; object arrays are refused (no pickle).

    Parameters
    ----------
    path : str or path-like
    arrays : mapping str -> array-like
    what : str
        What the arrays are, for the message (``"demos"``).
    max_bytes : int, optional
        The most bytes the arrays may take once loaded: the bound of the file's reader
        (default :data:`MAX_NPZ_BYTES`, :func:`open_npz`'s). More is refused before anything is
        written: the file could not be read back.

    Raises
    ------
    TypeError
        An object array.
    ValueError
        Arrays of more than ``max_bytes`` in total (the message names ``what``, the size and
        the bound).
    """
    payload: dict[str, Any] = {k: np.asarray(v) for k, v in arrays.items()}
    for key, value in payload.items():
        if value.dtype == object:
            raise TypeError(f"array {short(key)} has dtype object, which would need pickle")
    cap = MAX_NPZ_BYTES if max_bytes is None else int(max_bytes)
    total = sum(int(v.nbytes) for v in payload.values())
    bound = "MAX_NPZ_BYTES" if max_bytes is None else f"the bound of its reader for {what}"
    if total > cap:
        raise ValueError(
            f"{what}: the file would hold {_size(total)} of arrays, more than the {_size(cap)} "
            f"a pbdkit file may hold once loaded ({bound}): it could not be read back; "
            "nothing written"
        )
    buf = io.BytesIO()
    np.savez_compressed(buf, **payload)
    atomic_write_bytes(path, buf.getvalue())


#: The most bytes the arrays of one ``.npz`` file may take once loaded (1 GiB), unless a reader
#: states its own bound. The sizes are read from the archive's headers before any array is: a
#: small file that would decompress into gigabytes (a "zip bomb") is refused at once. pbdkit's
#: files are far smaller (a skill: kilobytes; 10 demonstrations of 10**5 samples of a 7-joint
#: arm: 64 MB).
MAX_NPZ_BYTES = 2**30


@dataclass(frozen=True)
class NpyHeader:
    """What the ``.npy`` header of one member of an ``.npz`` archive declares.

    Attributes
    ----------
    shape : tuple of int
    dtype : numpy.dtype
    nbytes : int
        Bytes of the array once loaded (``prod(shape) * dtype.itemsize``).
    """

    shape: tuple[int, ...]
    dtype: np.dtype[Any]
    nbytes: int


class NpzArchive(Mapping[str, NDArray[Any]]):
    """An open ``.npz`` archive whose members were checked from their headers alone.

    Build it with :func:`open_npz`, which has read the zip directory and each member's ``.npy``
    header (a few hundred bytes each) but no array: :attr:`headers` tells the keys, shapes,
    dtypes and sizes, so that a reader refuses unknown keys or absurd sizes before it loads
    anything. As a mapping, ``archive[key]`` loads one array (:meth:`read`, no pickle) each
    time it is asked for; ``key in archive``, ``len`` and iteration use the headers only. Use
    it as a context manager.
    """

    def __init__(
        self,
        path: Path,
        what: str,
        file: io.BufferedReader,
        archive: zipfile.ZipFile,
        headers: Mapping[str, NpyHeader],
        members: Mapping[str, zipfile.ZipInfo],
    ) -> None:
        self.path = path
        self.what = what
        self.headers: Mapping[str, NpyHeader] = MappingProxyType(dict(headers))
        self._file, self._zip, self._members = file, archive, dict(members)

    def __enter__(self) -> NpzArchive:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Close the archive and its file."""
        self._zip.close()
        self._file.close()

    def __contains__(self, key: object) -> bool:
        return key in self.headers

    def __iter__(self) -> Iterator[str]:
        return iter(self.headers)

    def __len__(self) -> int:
        return len(self.headers)

    def __getitem__(self, key: str) -> NDArray[Any]:
        return self.read(key)

    def read(self, key: str) -> NDArray[Any]:
        """The array stored under ``key`` (as ``np.load(path)[key]`` gives it).

        Raises
        ------
        KeyError
            If the archive has no such key.
        ValueError
            If the member is corrupt or truncated (the message names the file).
        """
        info = self._members[key]
        try:
            with self._zip.open(info) as member:
                return np.lib.format.read_array(member, allow_pickle=False)
        except (zipfile.BadZipFile, zlib.error, OSError, EOFError, ValueError) as exc:
            raise ValueError(
                f"{self.path} is not a valid {self.what} (key {short(key)} does not read): {exc}"
            ) from exc

    def check_keys(self, allowed: Callable[[str], bool] | Collection[str]) -> None:
        """Refuse keys that the reader does not know (before any of them is loaded).

        Parameters
        ----------
        allowed : collection of str, or callable str -> bool
            The keys the format has.

        Raises
        ------
        ValueError
            Naming the file, the first unknown keys and their declared sizes.
        """
        known = allowed if callable(allowed) else frozenset(allowed).__contains__
        unknown = [k for k in self.headers if not known(k)]
        if unknown:
            shown = ", ".join(f"{short(k)} ({_size(self.headers[k].nbytes)})" for k in unknown[:4])
            more = f" and {len(unknown) - 4} more" if len(unknown) > 4 else ""
            raise ValueError(
                f"{self.path} is not a valid {self.what}: unknown key(s) {shown}{more}; "
                "the format has no such key"
            )


def _size(n: int) -> str:
    """A byte count for a message: ``512 B``, ``3.1 MB``, ``2.1 GB``."""
    if n < 1000:
        return f"{n} B"
    for unit, scale in (("kB", 1e3), ("MB", 1e6), ("GB", 1e9), ("TB", 1e12)):
        if n < 1000 * scale or unit == "TB":
            return f"{n / scale:.3g} {unit}"
    raise AssertionError  # pragma: no cover


# The longest .npy header read (bytes): NumPy's own bound (np.load's max_header_size). The
# length is checked before the header is read: a version-2 header may declare 4 GiB.
_MAX_NPY_HEADER = 10_000


def _npy_header(archive: zipfile.ZipFile, info: zipfile.ZipInfo) -> NpyHeader:
    """The header of one ``.npy`` member: reads a few hundred bytes, never the array."""
    with archive.open(info) as member:
        version = np.lib.format.read_magic(member)
        # The versions np.save writes for arrays without object fields (3.0: field names
        # that need UTF-8, which pbdkit never writes).
        if version not in ((1, 0), (2, 0)):
            raise ValueError(f".npy format version {version[0]}.{version[1]} is not supported")
        length_format = "<H" if version == (1, 0) else "<I"
        length_bytes = member.read(struct.calcsize(length_format))
        if len(length_bytes) != struct.calcsize(length_format):
            raise ValueError("the .npy header is truncated")
        (length,) = struct.unpack(length_format, length_bytes)
        if length > _MAX_NPY_HEADER:
            raise ValueError(
                f"the .npy header declares {length} bytes, more than {_MAX_NPY_HEADER}"
            )
        text = member.read(length)
    read_header = (
        np.lib.format.read_array_header_1_0
        if version == (1, 0)
        else np.lib.format.read_array_header_2_0
    )
    shape, _, dtype = read_header(io.BytesIO(length_bytes + text))
    header_end = np.lib.format.MAGIC_LEN + len(length_bytes) + length
    if dtype.hasobject:
        raise ValueError("it holds an object array, which would need pickle to load")
    nbytes = math.prod(int(s) for s in shape) * int(dtype.itemsize)
    if info.file_size < header_end + nbytes:
        raise ValueError(
            f"the array declares {_size(nbytes)} but the member holds "
            f"{_size(max(info.file_size - header_end, 0))} (truncated)"
        )
    return NpyHeader(tuple(int(s) for s in shape), dtype, nbytes)


def open_npz(
    path: str | os.PathLike[str], *, what: str = "file", max_bytes: int | None = None
) -> NpzArchive:
    """Open an ``.npz`` archive and check every member from its headers, loading no array.

    Parameters
    ----------
    path : str or path-like
    what : str
        What the file should be, for the messages ("pbdkit-skill file").
    max_bytes : int, optional
        The most bytes all arrays together may take once loaded (default
        :data:`MAX_NPZ_BYTES`, the bound :func:`save_npz_atomic` writes within).

    Returns
    -------
    archive : NpzArchive
        Open: use it in a ``with`` block.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the file is not a NumPy ``.npz`` archive (foreign content: it is not a zip file), is
        corrupt or truncated, has a member that is not an ``.npy`` array, a key twice, an object
        array (which would need pickle), or arrays of more than ``max_bytes`` in total (sizes
        from the headers: nothing is decompressed beyond them).
    """
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"{what} not found: {p}")
    try:
        # Open the file ourselves: a ZipFile given a path leaks its handle when the archive is
        # truncated.
        f = open(p, "rb")  # noqa: SIM115 (closed by the archive, or below)
    except OSError as exc:
        raise ValueError(f"{p} is not a valid {what} (not a readable .npz archive): {exc}") from exc
    try:
        # np.load takes whatever is neither a zip nor an .npy file for a pickle: look first.
        if f.read(4) not in _ZIP_MAGIC:
            raise ValueError(
                f"{p} is not a NumPy .npz archive (it does not start like a zip file); "
                f"expected a {what}"
            )
        f.seek(0)
        try:
            archive = zipfile.ZipFile(f)
        except (zipfile.BadZipFile, OSError, EOFError) as exc:
            raise ValueError(
                f"{p} is not a valid {what} (not a readable .npz archive): {exc}"
            ) from exc
        cap = MAX_NPZ_BYTES if max_bytes is None else max_bytes
        try:
            headers, members = _check_members(archive, p, what, cap)
        except BaseException:
            archive.close()
            raise
    except BaseException:
        f.close()
        raise
    return NpzArchive(p, what, f, archive, headers, members)


def _check_members(
    archive: zipfile.ZipFile, p: Path, what: str, max_bytes: int
) -> tuple[dict[str, NpyHeader], dict[str, zipfile.ZipInfo]]:
    """The header of every member of an open archive, checked (see :func:`open_npz`)."""
    headers: dict[str, NpyHeader] = {}
    members: dict[str, zipfile.ZipInfo] = {}
    total = 0
    for info in archive.infolist():
        # np.savez stores the array of key k as the member k.npy.
        if not info.filename.endswith(".npy"):
            raise ValueError(
                f"{p} is not a valid {what}: the member {short(info.filename)} is not an .npy array"
            )
        key = info.filename[: -len(".npy")]
        if key in members:
            raise ValueError(f"{p} is not a valid {what}: the key {short(key)} is stored twice")
        try:
            header = _npy_header(archive, info)
        except (zipfile.BadZipFile, zlib.error, OSError, EOFError, ValueError) as exc:
            raise ValueError(f"{p} is not a valid {what}: key {short(key)}: {exc}") from exc
        headers[key], members[key] = header, info
        total += header.nbytes
        if total > max_bytes:
            biggest = max(headers, key=lambda k: headers[k].nbytes)
            raise ValueError(
                f"{p} is not a valid {what}: its arrays would take more than {_size(max_bytes)} "
                f"once loaded (at least {_size(total)}; key {short(biggest)}: "
                f"{_size(headers[biggest].nbytes)})"
            )
    return headers, members


def check_format(
    data: Mapping[str, NDArray[Any]],
    path: str | os.PathLike[str],
    what: str,
    version: int | tuple[int, ...],
) -> int:
    """Check the ``format`` and ``version`` keys of a pbdkit ``.npz`` file: ``format`` is
    ``what``, ``version`` is ``version`` (or one of them); ValueError naming ``path``
    otherwise. Returns the file's version."""
    fmt = data.get("format")
    if fmt is None or fmt.shape != () or fmt.dtype.kind != "U" or str(fmt) != what:
        raise ValueError(f"{path} is not a {what} file (its 'format' key is missing or differs)")
    ver = data.get("version")
    if ver is None or ver.shape != () or ver.dtype.kind not in "iu":
        raise ValueError(f"{path} is not a valid {what} file: missing 'version'")
    versions = (version,) if isinstance(version, int) else version
    if int(ver) not in versions:
        shown = " or ".join(str(v) for v in versions)
        raise ValueError(
            f"{path} is a {what} file of version {int(ver)}; this pbdkit reads version {shown}"
        )
    return int(ver)


def _json_default(value: object) -> object:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    raise TypeError(f"not JSON serializable: {type(value).__name__}")


def write_json(path: str | os.PathLike[str], data: object, *, sort_keys: bool = False) -> None:
    """Write ``data`` as indented JSON, atomically (:func:`atomic_write_bytes`); NumPy arrays
    and scalars become lists and numbers.

    Raises
    ------
    ValueError
        A NaN or an infinity anywhere in ``data`` (JSON has neither: ``json.dumps`` would write
        ``NaN``, which no JSON reader takes), naming where it is; nothing is written. A value
        that is not known goes in ``data`` as None (``null``).
    """
    import json

    try:
        text = json.dumps(
            data, indent=2, sort_keys=sort_keys, default=_json_default, allow_nan=False
        )
    except ValueError:
        found = _non_finite(data, "")
        if found is None:
            raise
        where, value = found
        raise ValueError(
            f"{path}: {where or 'the value'} is {short(value)}, which JSON cannot hold (a value "
            "that is not known is written null); nothing written"
        ) from None
    atomic_write_bytes(path, (text + "\n").encode())


def _non_finite(value: object, where: str) -> tuple[str, float] | None:
    """Where the first NaN or infinity in JSON-bound ``value`` is (``runs.fused[3].x``), and
    it; None if there is none."""
    if isinstance(value, (float, np.floating)):
        return None if math.isfinite(value) else (where, float(value))
    if isinstance(value, np.ndarray):
        if value.dtype.kind not in "fc":
            return None
        bad = ~np.isfinite(value)
        if not bad.any():
            return None
        at = np.unravel_index(int(np.argmax(bad)), value.shape)
        return where + "".join(f"[{int(i)}]" for i in at), float(np.real(value[at]))
    if isinstance(value, Mapping):
        for key, item in value.items():
            name = str(key) if isinstance(key, str) and key.isidentifier() else short(key)
            found = _non_finite(item, f"{where}.{name}" if where else name)
            if found is not None:
                return found
    elif isinstance(value, (list, tuple)):
        for i, item in enumerate(value):
            found = _non_finite(item, f"{where}[{i}]")
            if found is not None:
                return found
    return None
