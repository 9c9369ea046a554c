"""SRDF files: reading the link pairs a robot never checks for self-collision, and writing them.

Of the SRDF (MoveIt's Semantic Robot Description Format) only the ``<disable_collisions
link1="..." link2="..." reason="..."/>`` elements are read; groups, group states, end effectors
and everything else are ignored. A pair is returned with its two names sorted alphabetically,
so that ``(a, b)`` and ``(b, a)`` are the same pair.

The text is parsed without a document type: an SRDF with a ``<!DOCTYPE>`` (which could declare
entities, the "billion laughs") is refused before any entity is expanded, and a file over
:data:`MAX_SRDF_BYTES` is refused before it is read.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from collections.abc import Collection, Iterable, Mapping
from pathlib import Path
from xml.parsers import expat
from xml.sax.saxutils import quoteattr

from .._io import atomic_write_bytes
from .._validation import short

__all__ = ["MAX_SRDF_BYTES", "write_srdf"]

#: The largest SRDF read (bytes): the disabled pairs of a 100-link robot take about 500 KB.
MAX_SRDF_BYTES = 4 * 1024 * 1024

LinkPair = tuple[str, str]


def _pair(a: str, b: str) -> LinkPair:
    """A link pair with its names in alphabetical order."""
    return (a, b) if a <= b else (b, a)


def _read_srdf_text(srdf: str | os.PathLike[str]) -> tuple[str, str]:
    """The SRDF text from a path or from the text itself, and how to name it in messages."""
    if isinstance(srdf, str) and srdf.lstrip("\ufeff \t\r\n").startswith("<"):
        text, label = srdf, "the SRDF text"
    elif isinstance(srdf, (str, os.PathLike)):
        path = Path(srdf)
        label = f"SRDF file {short(str(path))}"
        if not path.is_file():
            state = "is a directory" if path.is_dir() else "does not exist"
            raise ValueError(
                f"srdf: {label} {state}; pass an existing .srdf path or the SRDF XML text "
                "(starting with '<')"
            )
        size = path.stat().st_size
        data = b""
        if size <= MAX_SRDF_BYTES:
            with path.open("rb") as file:
                data = file.read(MAX_SRDF_BYTES + 1)  # it may have grown since
            size = max(size, len(data))
        if size > MAX_SRDF_BYTES:
            raise ValueError(
                f"srdf: {label} has {size} bytes, over the cap of {MAX_SRDF_BYTES} (MAX_SRDF_BYTES)"
            )
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise ValueError(
                f"srdf: {label} is not UTF-8 text (byte {exc.start}: {exc.reason}); "
                "expected SRDF XML"
            ) from exc
    else:
        raise ValueError(
            f"srdf must be a path to an SRDF file or the SRDF XML text, got {type(srdf).__name__}"
        )
    size = len(text.encode("utf-8", "surrogatepass"))
    if size > MAX_SRDF_BYTES:
        raise ValueError(
            f"srdf: {label} has {size} bytes, over the cap of {MAX_SRDF_BYTES} (MAX_SRDF_BYTES)"
        )
    return text, label


def _refuse_doctype(text: str, label: str) -> None:
    """Scan ``text`` with expat and refuse a document type declaration (entities included)
    before any entity could be expanded; a syntax error is reported here too."""

    def refuse(*_: object) -> None:
        raise ValueError(
            f"srdf: {label} has a <!DOCTYPE> declaration, which could declare entities; an SRDF "
            "needs none: remove it"
        )

    scanner = expat.ParserCreate()
    scanner.StartDoctypeDeclHandler = refuse
    scanner.EntityDeclHandler = refuse
    try:
        scanner.Parse(text, True)
    except expat.ExpatError as exc:
        raise ValueError(
            f"srdf: {label} is not valid XML ({exc}); expected an SRDF <robot>"
        ) from None


def read_srdf(
    srdf: str | os.PathLike[str], links: Collection[str], robot: str
) -> tuple[str, frozenset[LinkPair]]:
    """Read an SRDF's disabled collision pairs and check them against the URDF's links.

    Parameters
    ----------
    srdf : str or path-like
        A path to an SRDF file, or its XML text (a string starting with ``<``).
    links : collection of str
        The URDF's link names.
    robot : str
        The URDF's robot name, for messages.

    Returns
    -------
    text : str
        The SRDF text (read from the file if a path was given).
    pairs : frozenset of (str, str)
        The disabled pairs, each sorted alphabetically; a pair of a link with itself is dropped.

    Raises
    ------
    ValueError
        A missing file, one over :data:`MAX_SRDF_BYTES`, not UTF-8 or not XML, a
        ``<!DOCTYPE>``, a root that is not ``<robot>``, a ``<disable_collisions>`` without
        ``link1`` or ``link2``, or a link the URDF does not have (naming it and the file).
    """
    text, label = _read_srdf_text(srdf)
    _refuse_doctype(text, label)
    root = ET.fromstring(text)
    if root.tag != "robot":
        raise ValueError(f"srdf: {label} must have a <robot> root element, got <{root.tag}>")
    known = set(links)
    pairs: set[LinkPair] = set()
    for elem in root.iter("disable_collisions"):
        names = [elem.get("link1"), elem.get("link2")]
        for key, name in zip(("link1", "link2"), names, strict=True):
            if not name:
                raise ValueError(
                    f"srdf: a <disable_collisions> of {label} has no {key}; give both link1= "
                    "and link2="
                )
            if name not in known:
                raise ValueError(
                    f"srdf: {label} disables link {short(name)}, which the URDF "
                    f"{short(robot)} does not have; its links are {sorted(known)}"
                )
        a, b = str(names[0]), str(names[1])
        if a != b:
            pairs.add(_pair(a, b))
    return text, frozenset(pairs)


def write_srdf(
    pairs: Iterable[tuple[str, str]],
    path: str | os.PathLike[str],
    *,
    robot_name: str = "robot",
    reasons: Mapping[tuple[str, str], str] | None = None,
    comment: str | None = None,
) -> None:
    """Write link pairs as an SRDF of ``<disable_collisions>`` elements, atomically.

    The file reads back with ``Robot.from_urdf(urdf, srdf=path)`` (and in MoveIt): its
    :attr:`~pbdkit.robots.CollisionModel.disabled` then holds these pairs.

    Parameters
    ----------
    pairs : iterable of (str, str)
        Link names; each pair is written once, its names in alphabetical order, the pairs
        sorted (so that the file does not depend on the order given).
    path : str or path-like
        Written atomically (readers see the old file or the new one), with the mode the umask
        gives a new file.
    robot_name : str
        The ``name`` of the SRDF's ``<robot>`` (MoveIt expects the URDF's).
    reasons : mapping (str, str) -> str, optional
        A ``reason`` attribute per pair (MoveIt's "Adjacent", "Default", "Always", "Never",
        "User"), in either name order; pairs it does not name get none.
    comment : str, optional
        Written as an XML comment after the declaration (how the pairs were found).

    Raises
    ------
    ValueError
        A pair that is not two different non-empty strings, a reason or robot name that is not
        a string, or a comment with ``--`` (which ends an XML comment).
    """
    if not isinstance(robot_name, str):
        raise ValueError(f"robot_name must be a string, got {type(robot_name).__name__}")
    if comment is not None and (not isinstance(comment, str) or "--" in comment):
        raise ValueError("comment must be a string without '--' (which ends an XML comment)")
    why: dict[LinkPair, str] = {}
    for key, reason in (reasons or {}).items():
        if not isinstance(reason, str):
            raise ValueError(f"reasons[{short(key)}] must be a string, got {short(reason)}")
        why[_checked_pair(key, "reasons key")] = reason
    checked = sorted({_checked_pair(p, "pairs item") for p in pairs})
    q = quoteattr
    lines = ['<?xml version="1.0" encoding="UTF-8"?>']
    if comment is not None:
        body = comment.strip("\n")
        lines.append(f"<!--\n{body}\n-->" if "\n" in body else f"<!-- {body} -->")
    lines.append(f"<robot name={q(robot_name)}>")
    for a, b in checked:
        reason = f" reason={q(why[(a, b)])}" if (a, b) in why else ""
        lines.append(f"  <disable_collisions link1={q(a)} link2={q(b)}{reason}/>")
    lines.append("</robot>\n")
    atomic_write_bytes(path, "\n".join(lines).encode("utf-8"))


def _checked_pair(pair: object, what: str) -> LinkPair:
    if (
        not isinstance(pair, (tuple, list))
        or len(pair) != 2
        or not all(isinstance(s, str) and s for s in pair)
    ):
        raise ValueError(f"{what} must be a pair of non-empty link names, got {short(pair)}")
    if pair[0] == pair[1]:
        raise ValueError(f"{what} must name two different links, got {short(pair)}")
    return _pair(str(pair[0]), str(pair[1]))
