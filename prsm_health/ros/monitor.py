"""``prsm-health monitor``: the node's health and diagnostics in a terminal, without rqt.

Subscribes to ``/diagnostics`` and ``<node>/health``. Table mode prints one compact block per
DiagnosticArray that holds prsm_health statuses (the latest estimate on top, then one line per
status); on a terminal each block replaces the previous one. JSON mode prints one object per
message (``{"topic": ..., ...}``). Ends after ``count`` printed records (blocks or JSON lines)
or after ``timeout_s``. A monitor started after the node sees the diagnostics at once (they are
published periodically) but an estimate only when the node makes a new one.

``/diagnostics`` is shared by every node, and a prsm_health status says which node it is from
only by its ``hardware_id`` (every node names its statuses ``prsm_health: ...``; the message
does not carry its publisher here): the monitor shows the statuses whose ``hardware_id`` is
the node's. It asks the node for its ``hardware_id`` parameter through its parameter service
until it answers, unless ``MonitorOptions.hardware_id`` names it (once: the node applies it at
configure and refuses a change while configured); statuses that come before the answer are
kept, the latest of each hardware id, and the node's shown once it is known.

A node whose configure failed publishes only its configuration status (ERROR, with the
reason): the table's first line then says the node is not configured, instead of waiting for an
estimate that will not come.

Messages from other publishers (``ros2 topic pub``, other tools) are shown as they are, never
refused: a level that is none of the four is ``level 7 (unknown)``, an estimate without the
probability of its jam count says so.
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
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import GetParameters
from rclpy.exceptions import InvalidTopicNameException
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, QoSReliabilityPolicy
from rclpy.validate_full_topic_name import validate_full_topic_name

from prsm_health.jsonvalues import json_safe
from prsm_health.outputs import CONFIGURATION, Level
from prsm_health.ros.messages import stamp_seconds

STATUS_PREFIX = "prsm_health: "
CLEAR = "\x1b[H\x1b[J"
#: The table's first line until an estimate comes (diagnostics may come first: see above).
NO_ESTIMATE = (
    "no estimate received since the monitor started (the node publishes one per new estimate)"
)
#: The first line instead while the node reports a failed configure (an older estimate is no
#: longer the node's).
NOT_CONFIGURED = "the node is not configured: it makes no estimate until a configure succeeds"
#: How often the node is asked for its hardware_id until it answers [s]: a request sent as its
#: service appears may be lost.
ASK_PERIOD_S = 1.0


@dataclass(frozen=True, kw_only=True)
class MonitorOptions:
    """node: the node's full name (its health topic is ``<node>/health``). json: JSON lines.
    count: stop after this many records (0: no limit). timeout_s: stop after this long
    (0: no limit). hardware_id: show the statuses of this hardware id (None: the node's, asked
    from it; see the module docstring)."""

    node: str = "/prsm_health"
    json: bool = False
    count: int = 0
    timeout_s: float = 0.0
    hardware_id: str | None = None

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


def level_name(level: bytes) -> str:
    """A DiagnosticStatus level (a one-byte ``bytes``) by name, or ``level 7 (unknown)`` for
    one that is none of the four (another publisher's: shown, not refused)."""
    try:
        return Level(level[0]).name
    except ValueError:
        return f"level {level[0]} (unknown)"


def diagnostics_record(msg: Any) -> dict[str, Any]:
    """The prsm_health statuses of a DiagnosticArray (of every hardware id) as a JSON-able
    dict."""
    return {
        "stamp": stamp_seconds(msg.header.stamp),
        "status": [
            {
                "name": s.name,
                "level": level_name(s.level),
                "message": s.message,
                "hardware_id": s.hardware_id,
                "values": {kv.key: kv.value for kv in s.values},
            }
            for s in msg.status
            if s.name.startswith(STATUS_PREFIX)
        ],
    }


def statuses_of(record: dict[str, Any], hardware_id: str) -> dict[str, Any]:
    """A :func:`diagnostics_record` with only the statuses of ``hardware_id``."""
    return {**record, "status": [s for s in record["status"] if s["hardware_id"] == hardware_id]}


def jam_probability(record: dict[str, Any]) -> str:
    """The probability of the most likely jam count, or what is missing (an estimate from
    another publisher, e.g. a default message, may have fewer probabilities)."""
    probabilities = record["jammed_rollers_probability"]
    jammed = record["jammed_rollers_most_likely"]
    if jammed < len(probabilities):
        return f"p {probabilities[jammed]:.2f}"
    return f"no probability of {jammed}" if probabilities else "no probabilities"


def health_line(record: dict[str, Any]) -> str:
    """One line of the latest estimate."""
    return (
        f"t {record['stamp']:.2f} s  load {record['axial_load_n'] / 1e3:.2f}"
        f" ± {record['axial_load_std_n'] / 1e3:.2f} kN"
        f"  jammed {record['jammed_rollers_most_likely']} ({jam_probability(record)})"
        f"  loss {record['precision_loss_um']:.4g} um"
        f" ({record['precision_loss_rate_um_per_h']:.3g} um/h)"
        f"  fatigue {record['fatigue_damage']:.3g}"
    )


def table(health: dict[str, Any] | None, diagnostics: dict[str, Any]) -> str:
    """The compact block: the estimate (or that the node is not configured), then level,
    short name and message of each status."""
    if any(s["name"] == CONFIGURATION for s in diagnostics["status"]):
        lines = [NOT_CONFIGURED]
    else:
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
        #: Whose statuses are shown (None until the node has told it).
        self.hardware_id = options.hardware_id
        #: Until then: the latest statuses of each hardware id.
        self._unclaimed: dict[str, dict[str, Any]] = {}
        self._seen_ids: set[str] = set()  # of the statuses met once the hardware_id is known
        #: Why the node's answer gave no hardware id ("" if it did not answer).
        self._no_hardware_id = ""
        self._next_ask_s = 0.0
        self._live = out.isatty() and not options.json
        self._node = rclpy.create_node("prsm_health_monitor")
        reliable = QoSProfile(depth=50, reliability=QoSReliabilityPolicy.RELIABLE)
        self._node.create_subscription(
            HealthEstimate, options.health_topic, self._on_health, reliable
        )
        self._node.create_subscription(
            DiagnosticArray, "/diagnostics", self._on_diagnostics, reliable
        )
        self._parameters = self._node.create_client(
            GetParameters, options.full_name + "/get_parameters"
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
            self._emit(json.dumps(json_safe({"topic": "health", **self.latest_health})))

    def _on_diagnostics(self, msg: Any) -> None:
        record = diagnostics_record(msg)
        if self.hardware_id is not None:
            self._seen_ids.update(s["hardware_id"] for s in record["status"])
            self._show(statuses_of(record, self.hardware_id))
            return
        for hardware_id in {s["hardware_id"] for s in record["status"]}:
            self._unclaimed[hardware_id] = statuses_of(record, hardware_id)

    def _show(self, record: dict[str, Any]) -> None:
        """Print the node's statuses (if there are any) as the latest diagnostics."""
        if not record["status"]:
            return
        self.latest_diagnostics = record
        if self.options.json:
            self._emit(json.dumps(json_safe({"topic": "/diagnostics", **record})))
        else:
            self._emit(table(self.latest_health, record))

    def _ask_hardware_id(self) -> None:
        """Ask the node for its hardware_id parameter, once its parameter service is up and
        again every :data:`ASK_PERIOD_S` until it has told it."""
        now = time.monotonic()
        if self.hardware_id is not None or now < self._next_ask_s:
            return
        if self._parameters.service_is_ready():
            self._next_ask_s = now + ASK_PERIOD_S
            request = GetParameters.Request(names=["hardware_id"])
            self._parameters.call_async(request).add_done_callback(self._on_hardware_id)

    def _on_hardware_id(self, future: Any) -> None:
        """The node's answer: show its statuses from now on, and those that came before."""
        response = future.result()
        if self.hardware_id is not None or response is None:
            return
        values = response.values
        if not values or values[0].type != ParameterType.PARAMETER_STRING:
            self._no_hardware_id = f"{self.options.full_name} has no hardware_id parameter"
            return
        self.hardware_id = str(values[0].string_value)
        before = self._unclaimed.pop(self.hardware_id, None)
        self._unclaimed.clear()
        if before is not None:
            self._show(before)

    def spin_once(self) -> None:
        """Handle what has arrived, waiting at most 50 ms for something."""
        self._ask_hardware_id()
        self._executor.spin_once(timeout_sec=0.05)

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
        """Why :meth:`run` returned False, for the user: first of all whether anything came,
        then whether the node's statuses could be told from the others'."""
        within = f" within {self.options.timeout_s:g} s" if self.timed_out else ""
        unknown = (
            self._no_hardware_id or f"{self.options.full_name} did not tell its hardware_id"
        ) + " (--hardware-id ID shows the statuses of ID)"
        if not self.health_received and self.latest_diagnostics is None:
            if self._unclaimed and self.hardware_id is None:
                return f"prsm_health statuses on /diagnostics{within}, but {unknown}"
            if others := sorted(self._seen_ids - {str(self.hardware_id)}):
                return (
                    f"no status of hardware_id {self.hardware_id!r} on /diagnostics{within};"
                    f" statuses came for {', '.join(map(repr, others))} (--hardware-id)"
                )
            return (
                f"nothing received on {self.options.health_topic} or /diagnostics{within}: is"
                " the node running, under this name, with the same ROS_DOMAIN_ID?"
            )
        count = self.options.count
        text = f"{self.records} of {count} records printed" if count else "estimates received"
        if self.hardware_id is None:
            return f"{text}{within}, but {unknown}"
        if count:
            return f"{text}{within}"
        return (
            f"{text}{within}, but no prsm_health statuses of hardware_id {self.hardware_id}"
            " on /diagnostics"
        )

    def close(self) -> None:
        """Destroy the executor and the node."""
        self._executor.shutdown()
        self._node.destroy_node()
