"""Headless Chromium for the tests, the view's benchmark and its screenshots: Debian's chromium
(``make system-deps``), driven by playwright with software WebGL (playwright's own browser
download does not work here)."""

from __future__ import annotations

import contextlib
import io
import socket
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from pbdkit.apps._view_serve import HOST

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--enable-unsafe-swiftshader",
    "--use-angle=swiftshader",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]


def launch(playwright: Any) -> Any:
    """Chromium from ``sync_playwright()``'s object, headless, software WebGL."""
    return playwright.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)


def free_port() -> int:
    """A port free on 127.0.0.1 now."""
    with socket.socket() as s:
        s.bind((HOST, 0))
        return int(s.getsockname()[1])


@contextlib.contextmanager
def quiet_viser_server() -> Iterator[Any]:
    """A viser server on 127.0.0.1 and a free port, its start and stop lines silenced (no
    browser: the tests read the scene it holds)."""
    import viser

    with contextlib.redirect_stdout(io.StringIO()):
        srv = viser.ViserServer(host=HOST, port=free_port(), verbose=False)
    try:
        yield srv
    finally:
        with contextlib.redirect_stdout(io.StringIO()):
            srv.stop()
