"""``prsm-health monitor``: the node's health and diagnostics in a terminal, without rqt.

Subscribes to ``/diagnostics`` and ``<node>/health``. Table mode prints one compact block per
DiagnosticArray that holds prsm_health statuses (the latest estimate on top, then one line per
status); on a terminal each block replaces the previous one. JSON mode prints one object per
message (``{"topic": ..., ...}``). Ends after ``count`` printed records (blocks or JSON lines)
or after ``timeout_s``. A monitor started after the node sees the diagnostics at once (they are
published periodically) but an estimate only when the node makes a new one.
"""

from __future__ import annotations

import json
import sys
import threading
import time
from dataclasses import dataclass
from typing import Any, TextIO

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from prsm_health_msgs.msg import HealthEstimate
from rclpy.exceptions import InvalidTopicNameException
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, QoSReliabilityPolicy
from rclpy.validate_full_topic_name import validate_full_topic_name

from prsm_health.outputs import Level
from prsm_health.ros.messages import stamp_seconds

STATUS_PREFIX = "prsm_health: "
CLEAR = "\x1b[H\x1b[J"
#: The table's first line until an estimate comes (diagnostics may come first: see above).
NO_ESTIMATE = (
    "no estimate received since the monitor started (the node publishes one per new estimate)"
)


@dataclass(frozen=True, kw_only=True)
class MonitorOptions:
    """node: the node's full name (its health topic is ``<node>/health``). json: JSON lines.
    count: stop after this many records (0: no limit). timeout_s: stop after this long
    (0: no limit)."""

    node: str = "/prsm_health"
    json: bool = False
    count: int = 0
    timeout_s: float = 0.0

    def __post_init__(self) -> None:
        """Refuse a node name that cannot name a topic, as a usage error (ValueError), before
        rclpy raises at the subscription."""
        try:
            validate_full_topic_name(self.full_name)
        except InvalidTopicNameException as exc:
            # rclpy's first line, e.g. "Invalid topic name: topic name must not ...:"
            reason = str(exc).splitlines()[0].removeprefix("Invalid topic name: topic name ")
            reason = reason.removesuffix(":")
            raise ValueError(
                f"--node {self.node!r} is not a node name such as /prsm_health: {reason}"
            ) from None

    @property
    def full_name(self) -> str:
        """``node``, absolute (the monitor's own node is in the root namespace, where a
        relative name resolves the same), without a trailing slash."""
        return "/" + self.node.strip("/")

    @property
    def health_topic(self) -> str:
        """The node's ``~/health``."""
        return self.full_name + "/health"


def health_record(msg: Any) -> dict[str, Any]:
    """A HealthEstimate as a JSON-able dict (header stamp in seconds)."""
    record: dict[str, Any] = {"stamp": stamp_seconds(msg.header.stamp)}
    for name in msg.get_fields_and_field_types():
        if name != "header":
            value = getattr(msg, name)
            record[name] = [float(v) for v in value] if name.endswith("probability") else value
    return record


def diagnostics_record(msg: Any) -> dict[str, Any]:
    """The prsm_health statuses of a DiagnosticArray as a JSON-able dict."""
    return {
        "stamp": stamp_seconds(msg.header.stamp),
        "status": [
            {
                "name": s.name,
                "level": Level(s.level[0]).name,
                "message": s.message,
                "hardware_id": s.hardware_id,
                "values": {kv.key: kv.value for kv in s.values},
            }
            for s in msg.status
            if s.name.startswith(STATUS_PREFIX)
        ],
    }


def health_line(record: dict[str, Any]) -> str:
    """One line of the latest estimate."""
    probabilities = record["jammed_rollers_probability"]
    jammed = record["jammed_rollers_most_likely"]
    return (
        f"t {record['stamp']:.2f} s  load {record['axial_load_n'] / 1e3:.2f}"
        f" +- {record['axial_load_std_n'] / 1e3:.2f} kN  jammed {jammed}"
        f" (p {probabilities[jammed]:.2f})  loss {record['precision_loss_um']:.4g} um"
        f" ({record['precision_loss_rate_um_per_h']:.3g} um/h)"
        f"  fatigue {record['fatigue_damage']:.3g}"
    )


def table(health: dict[str, Any] | None, diagnostics: dict[str, Any]) -> str:
    """The compact block: the estimate, then level, short name and message of each status."""
    lines = [health_line(health) if health else NO_ESTIMATE]
    for status in diagnostics["status"]:
        name = status["name"].removeprefix(STATUS_PREFIX)
        lines.append(f"  {status['level']:<5} {name:<18} {status['message']}")
    return "\n".join(lines)


class Monitor:
    """Receives and prints (see the module docstring); :meth:`run` until done."""

    def __init__(self, options: MonitorOptions, out: TextIO = sys.stdout) -> None:
        self.options = options
        self.out = out
        self.latest_health: dict[str, Any] | None = None
        self.latest_diagnostics: dict[str, Any] | None = None
        self.records = 0
        self.health_received = 0
        self.timed_out = False
        self._live = out.isatty() and not options.json
        self._node = rclpy.create_node("prsm_health_monitor")
        reliable = QoSProfile(depth=50, reliability=QoSReliabilityPolicy.RELIABLE)
        self._node.create_subscription(
            HealthEstimate, options.health_topic, self._on_health, reliable
        )
        self._node.create_subscription(
            DiagnosticArray, "/diagnostics", self._on_diagnostics, reliable
        )
        self._executor = SingleThreadedExecutor()
        self._executor.add_node(self._node)

    def _emit(self, text: str) -> None:
        self.out.write((CLEAR if self._live else "") + text + "\n")
        self.out.flush()
        self.records += 1

    def _on_health(self, msg: Any) -> None:
        self.latest_health = health_record(msg)
        self.health_received += 1
        if self.options.json:
            self._emit(json.dumps({"topic": "health", **self.latest_health}))

    def _on_diagnostics(self, msg: Any) -> None:
        record = diagnostics_record(msg)
        if not record["status"]:
            return
        self.latest_diagnostics = record
        if self.options.json:
            self._emit(json.dumps({"topic": "/diagnostics", **record}))
        else:
            self._emit(table(self.latest_health, record))

    def spin_once(self, timeout_s: float = 0.05) -> None:
        """Handle what has arrived, waiting at most ``timeout_s`` for something."""
        self._executor.spin_once(timeout_sec=timeout_s)

    def done(self) -> bool:
        """The requested number of records has been printed."""
        return 0 < self.options.count <= self.records

    def run(self, stop: threading.Event) -> bool:
        """Spin until done, timeout or ``stop``; True if ``count`` records were printed (or no
        count was asked and something was received)."""
        deadline = time.monotonic() + self.options.timeout_s if self.options.timeout_s else None
        while not (stop.is_set() or self.done()):
            if deadline is not None and time.monotonic() >= deadline:
                self.timed_out = True
                break
            self.spin_once()
        return self.done() if self.options.count else self.records > 0

    def shortfall(self) -> str:
        """Why :meth:`run` returned False, for the user: first of all whether anything came."""
        within = f" within {self.options.timeout_s:g} s" if self.timed_out else ""
        if not self.health_received and self.latest_diagnostics is None:
            return (
                f"nothing received on {self.options.health_topic} or /diagnostics{within}: is"
                " the node running, under this name, with the same ROS_DOMAIN_ID?"
            )
        if self.options.count:
            return f"{self.records} of {self.options.count} records printed{within}"
        return f"estimates received{within}, but no prsm_health statuses on /diagnostics"

    def close(self) -> None:
        """Destroy the executor and the node."""
        self._executor.shutdown()
        self._node.destroy_node()
