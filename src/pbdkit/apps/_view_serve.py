"""Serving the live view (``pbdkit view``): a viser server on :data:`HOST`, its port checked
first, stopped cleanly on SIGINT or SIGTERM (:func:`serve`), or from a background thread for a
notebook, a test or a benchmark (:func:`served`). The page itself is :class:`ViewApp`
(:mod:`pbdkit.apps._view`).
"""

from __future__ import annotations

import contextlib
import errno
import io
import signal
import socket
import threading
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import viser

    from ._view import ViewApp

__all__ = ["HOST", "check_port", "serve", "served"]

#: The page is served on this interface only.
HOST = "127.0.0.1"


def check_port(port: int) -> None:
    """Refuse a port that is taken on :data:`HOST` (viser would silently take the next one).

    Raises
    ------
    ValueError
        The port is not in 1..65535, or something listens on it.
    """
    if not 1 <= port <= 65535:
        raise ValueError(f"--port must be in 1..65535, got {port}")
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((HOST, port))
        except OSError as exc:
            if exc.errno in (errno.EADDRINUSE, errno.EACCES):
                why = "in use" if exc.errno == errno.EADDRINUSE else "not allowed"
                raise ValueError(
                    f"port {port} on {HOST} is {why}: choose another with --port"
                ) from None
            raise


def serve(
    app_factory: Callable[[viser.ViserServer], ViewApp],
    *,
    port: int,
    open_browser: bool = True,
    say: Callable[[str], None] = print,
    ready: Callable[[ViewApp], None] | None = None,
    stop: threading.Event | None = None,
) -> None:
    """Serve the page until SIGINT or SIGTERM (or ``stop``), then stop cleanly.

    ``app_factory`` builds the :class:`ViewApp` on the server. ``ready`` is called with it once
    the page is served (tests and benchmarks).

    Raises
    ------
    ValueError
        The port is taken (checked first: viser would take the next free one).
    """
    import viser

    check_port(port)
    with contextlib.redirect_stdout(io.StringIO()):  # viser's banner: we print the URL
        server = viser.ViserServer(host=HOST, port=port, verbose=False)
    server.gui.configure_theme(show_share_button=False)  # sharing goes through viser's servers
    done = stop if stop is not None else threading.Event()
    app: ViewApp | None = None
    previous: dict[signal.Signals, Any] = {}
    try:
        if server.get_port() != port:
            raise ValueError(f"port {port} on {HOST} is in use: choose another with --port")
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                previous[sig] = signal.signal(sig, lambda *_: done.set())
        app = app_factory(server)
        url = f"http://{HOST}:{port}"
        say(f"serving {url} (Ctrl+C to stop)")
        if open_browser:
            import webbrowser

            webbrowser.open(url)
        if ready is not None:
            ready(app)
        while not done.wait(timeout=0.5):
            pass
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        if app is not None:
            app.close()
        with contextlib.redirect_stdout(io.StringIO()):
            server.stop()


@contextlib.contextmanager
def served(
    app_factory: Callable[[viser.ViserServer], ViewApp], *, port: int, timeout: float = 120.0
) -> Iterator[ViewApp]:
    """Serve the page from a background thread while the block runs (a notebook, a test, a
    benchmark): yields the app once the page is served, and stops the server at the end.

    Raises
    ------
    ValueError
        As :func:`serve` (a port in use).
    TimeoutError
        The page was not served within ``timeout`` seconds.
    """
    stop = threading.Event()
    started = threading.Event()
    box: dict[str, Any] = {}

    def ready(app: ViewApp) -> None:
        box["app"] = app
        started.set()

    def run() -> None:
        try:
            serve(
                app_factory,
                port=port,
                open_browser=False,
                say=lambda _: None,
                ready=ready,
                stop=stop,
            )
        except BaseException as exc:  # handed to the caller's thread
            box["error"] = exc
            started.set()

    thread = threading.Thread(target=run, name="pbdkit-view-server", daemon=True)
    thread.start()
    if not started.wait(timeout):
        stop.set()
        raise TimeoutError(f"the view was not served within {timeout:g} s")
    if "error" in box:
        raise box["error"]
    try:
        yield box["app"]
    finally:
        stop.set()
        thread.join(timeout=30.0)
