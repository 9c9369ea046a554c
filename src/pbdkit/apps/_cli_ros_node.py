"""The node a ``pbdkit ros`` command runs on (:func:`run_node`): its own, with SIGINT and
SIGTERM handled by the command (a run brakes first)."""

from __future__ import annotations

import signal
import sys
from typing import Any

__all__ = ["run_node"]


def run_node(body: Any, name: str = "pbdkit_ros_run") -> Any:
    """``body(node, stop)`` on a node of its own; SIGINT and SIGTERM set ``stop`` (the body
    brakes and returns 130). Returns the body's exit code, or the RunFailed (or TimeoutError)
    it raised."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from ..ros._run import RunFailed

    stopped: list[int] = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stopped.append(1))
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node: Any = rclpy.create_node(name)
    try:
        return body(node, lambda: bool(stopped))
    except (RunFailed, TimeoutError) as err:
        return err
    finally:
        node.destroy_node()
        rclpy.shutdown()
        sys.stdout.flush()
