"""Process-level rclpy setup shared by the node and the tools: init, signals, message types.

:func:`ros_session` initialises rclpy without its own signal handlers and turns SIGINT and
SIGTERM into a stop flag, so that every program ends its loop cleanly (the node saves its
state, the player waits for its messages to be acknowledged) instead of being torn down in the
middle of a callback.
"""

from __future__ import annotations

import importlib
import signal
import threading
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from types import FrameType
from typing import Any

import rclpy
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import try_shutdown


@contextmanager
def ros_session(
    args: Sequence[str] | None = None, *, ignore_signals_after: bool = False
) -> Iterator[threading.Event]:
    """rclpy initialised with ``args`` (ROS arguments); yields the event SIGINT/SIGTERM set.

    The handlers stay until rclpy is shut down, then the previous ones come back, or, with
    ``ignore_signals_after`` (a process that ends with the session: the node), SIGINT and
    SIGTERM are ignored from then on. A second Ctrl-C while such a process ends (rclpy's
    shutdown, then the interpreter's teardown, which puts back the default action of every
    signal that has a Python handler) killed it by the signal (exit code -2), hiding its clean
    exit or the node's 1 after a failed save; SIGKILL still ends a teardown that hangs."""
    stop = threading.Event()

    def request_stop(signum: int, frame: FrameType | None) -> None:
        stop.set()

    rclpy.init(
        args=list(args) if args is not None else None,
        signal_handler_options=SignalHandlerOptions.NO,
    )
    previous = {sig: signal.signal(sig, request_stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stop
    finally:
        try:
            try_shutdown()
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, signal.SIG_IGN if ignore_signals_after else handler)


def message_class(type_name: str) -> Any:
    """The Python class of a ROS message type named ``pkg/msg/Name``.

    Raises LookupError naming the type if its package is not installed.
    """
    parts = type_name.split("/")
    try:
        if len(parts) != 3:
            raise ValueError("expected pkg/msg/Name")
        return getattr(importlib.import_module(f"{parts[0]}.{parts[1]}"), parts[2])
    except (ImportError, AttributeError, ValueError) as exc:
        raise LookupError(f"message type {type_name!r} is not installed ({exc})") from exc


def loopback_env(base: Mapping[str, str], domain_id: int) -> dict[str, str]:
    """``base`` with the DDS rules of this project: discovery on localhost only, Fast DDS's
    built-in transports set to UDPv4 (which the localhost range overrides: docs/ros.md), logs
    in ``ROS_LOG_DIR`` (``build/ros_log`` by default), and a domain id (``ROS_DOMAIN_ID`` if
    ``base`` has one, else ``domain_id``)."""
    env = dict(base)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["FASTDDS_BUILTIN_TRANSPORTS"] = "UDPv4"
    env.setdefault("ROS_LOG_DIR", str(Path("build", "ros_log").resolve()))
    env.setdefault("ROS_DOMAIN_ID", str(domain_id))
    return env
