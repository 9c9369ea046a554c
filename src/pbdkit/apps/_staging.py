"""An output folder written all at once: the commands that write many files (``pbdkit demo``,
``pbdkit study``) write them into a staging folder and move them into place on success."""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from .._validation import short

__all__ = ["staged_output"]


@contextmanager
def staged_output(out: Path, *, last: str | None = None) -> Iterator[Path]:
    """A folder to write into, whose files move into ``out`` when the block ends without error.

    The staging folder is hidden inside ``out`` (``.partial-*``: a move within one file
    system is a rename). If the block raises, it is removed with what it holds, and so are
    ``out`` and its parents if this created them (only while empty: never what someone else
    put there); a folder that existed is left as it was found. A run killed outright may
    leave a ``.partial-*`` folder behind.

    Parameters
    ----------
    out : Path
        The output folder (created, with its missing parents).
    last : str, optional
        The file moved last (the one whose presence says the output is complete).

    Yields
    ------
    stage : Path
        The staging folder.

    Raises
    ------
    ValueError
        If ``out`` or one of its parents exists and is not a directory.
    """
    created = _missing_folders(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        stage = Path(tempfile.mkdtemp(prefix=".partial-", dir=out))
        try:
            yield stage
            for name in sorted(os.listdir(stage), key=lambda n: n == last):
                os.replace(stage / name, out / name)
        finally:
            shutil.rmtree(stage, ignore_errors=True)
    except BaseException:
        for folder in reversed(created):
            try:
                folder.rmdir()
            except OSError:
                break
        raise


def _missing_folders(out: Path) -> list[Path]:
    """The folders that creating ``out`` creates (``out`` and its missing parents), outermost
    first."""
    missing = []
    folder = out
    while not folder.exists() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    if folder.exists() and not folder.is_dir():
        raise ValueError(
            f"out must be a directory, got {short(str(out))}: {short(str(folder))} is a file"
        )
    return missing[::-1]
