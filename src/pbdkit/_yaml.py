"""YAML files read safely (private): a size cap checked before reading, PyYAML's safe loader
only (libyaml's where present, so that no tag can run code), and one-line errors naming the
source. Used by the joint_limits files and the scene files."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

__all__ = ["SAFE_LOADER", "parse_yaml", "read_capped_text"]

# libyaml's safe loader where PyYAML was built with it (no python/* tags either way).
SAFE_LOADER: type[yaml.SafeLoader] = getattr(yaml, "CSafeLoader", yaml.SafeLoader)


def read_capped_text(path: Path, label: str, cap: int, cap_name: str, what: str) -> str:
    """A YAML file's text: an existing file of at most ``cap`` bytes, UTF-8.

    ``label`` names the file in messages ("joint_limits file 'x.yaml'"), ``cap_name`` the
    constant that holds the cap, and ``what`` the kind of file, as in "a joint_limits.yaml is
    a few KB" and "pass an existing joint_limits.yaml path, ...".
    """
    if not path.is_file():
        state = "is a directory" if path.is_dir() else "does not exist"
        raise ValueError(f"{label} {state}; pass an existing {what}")
    size, data = path.stat().st_size, b""
    if size <= cap:
        with path.open("rb") as file:
            data = file.read(cap + 1)  # it may have grown since
        size = max(size, len(data))
    if size > cap:
        raise ValueError(f"{label} has {size} bytes, over the cap of {cap} ({cap_name})")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(
            f"{label} is not UTF-8 text (byte {exc.start}: {exc.reason}); expected YAML"
        ) from exc


def parse_yaml(text: str, label: str) -> Any:
    """The YAML text parsed with the safe loader, or a one-line ValueError naming ``label``."""
    try:
        return yaml.load(text, Loader=SAFE_LOADER)
    except Exception as exc:
        # The loader raises more than YAMLError on hostile text: RecursionError (PyYAML's
        # composer, YAML nested 5000 deep), ValueError (a 13th month, 5000 digits), ...
        detail = " ".join(str(exc).split())
        if isinstance(exc, RecursionError):
            detail = f"nested too deeply: {detail}"
        elif not isinstance(exc, yaml.YAMLError):
            detail = f"{type(exc).__name__}: {detail}"
        if len(detail) > 300:  # an alias or tag name of any length
            detail = f"{detail[:200]}...{detail[-80:]}"
        raise ValueError(f"{label} is not valid YAML ({detail})") from exc
