"""Serving the live view (``pbdkit view``): a viser server on :data:`HOST`, its port checked
first, stopped cleanly on SIGINT or SIGTERM (:func:`serve`), or from a background thread for a
notebook, a test or a benchmark (:func:`served`); a Ctrl+C during the view's imports is held
back to their end (:func:`sigint_deferred`). The page itself is :class:`ViewApp`
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

__all__ = ["HOST", "check_port", "serve", "served", "sigint_deferred"]

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
    the page is served (tests and benchmarks). A signal at any moment, from before the server
    starts on, ends it the same way (with ``stop`` set already, nothing is served).

    Raises
    ------
    ValueError
        The port is taken (checked first: viser would take the next free one).
    """
    import viser

    check_port(port)
    done = stop if stop is not None else threading.Event()
    server: viser.ViserServer | None = None
    app: ViewApp | None = None
    previous: dict[signal.Signals, Any] = {}
    try:
        # The handlers first: a signal while the server starts (its thread runs before the
        # constructor returns) must stop it, not leave it serving (issue 36).
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                previous[sig] = signal.signal(sig, lambda *_: done.set())
        if done.is_set():
            return
        with contextlib.redirect_stdout(io.StringIO()):  # viser's banner: we print the URL
            server = viser.ViserServer(host=HOST, port=port, verbose=False)
        # Sharing would go through viser's servers.
        server.gui.configure_theme(show_share_button=False)
        if server.get_port() != port:
            raise ValueError(f"port {port} on {HOST} is in use: choose another with --port")
        if done.is_set():
            return
        app = app_factory(server)
        if done.is_set():
            return
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
        # The handlers go last: a second signal while the server stops changes nothing.
        try:
            if app is not None:
                app.close()
            if server is not None:
                with contextlib.redirect_stdout(io.StringIO()):
                    server.stop()
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)


@contextlib.contextmanager
def sigint_deferred() -> Iterator[None]:
    """Hold SIGINT back while the block runs, and raise :class:`KeyboardInterrupt` at its end
    if one came: for the view's imports, where a KeyboardInterrupt can be lost (trimesh, which
    yourdfpy imports, catches ``BaseException`` around its optional imports: the command went
    on to serve) or stop an extension module half-way through its initialisation.

    Outside the main thread, or where SIGINT is ignored, the block runs as it is.
    """
    if (
        threading.current_thread() is not threading.main_thread()
        or signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    ):
        yield
        return
    came = threading.Event()
    previous = signal.signal(signal.SIGINT, lambda *_: came.set())
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if came.is_set():
        raise KeyboardInterrupt


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
