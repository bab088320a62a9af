"""``prsm-health play``: publish a rosbag2 bag's messages over DDS with their original timing.

A replacement for ``ros2 bag play`` (not on PyPI for Jazzy). Messages are read raw with
rosbags (MCAP or SQLite rosbag2 directories) and published as the serialized CDR bytes they
are, through rclpy publishers of their types, in log-time order, at ``log time / rate`` after
the start. Optionally ``/clock`` (rosgraph_msgs/Clock) carries the log time, for nodes with
``use_sim_time``. Publishers are reliable (a best-effort subscriber matches them as well) and
keep ``PUBLISHER_DEPTH`` messages.

``wait_for_subscribers_s``: before the first message, wait until every played topic (and
``/clock`` if published) has a subscriber (at most that long; otherwise an error naming the
topics with and without one: a topic nothing reads, e.g. ``/truth/state``, is left out with
``topics``), then
:data:`SETTLE_S` more so that the subscriber side of discovery completes too: a best-effort
subscriber drops what arrives before it has matched the publisher. At the end the player
waits for reliable subscribers to acknowledge everything (at most ``ACK_TIMEOUT_S``), so a
short bag is not cut off, and reports the topics they did not; best-effort subscribers are not
waited for.
"""

from __future__ import annotations

import math
import threading
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import rclpy
from rclpy.duration import Duration
from rclpy.qos import QoSProfile, QoSReliabilityPolicy
from rosbags.rosbag2 import Reader, ReaderError
from rosgraph_msgs.msg import Clock

from prsm_health.ros.messages import time_msg
from prsm_health.ros.runtime import message_class

#: History of each publisher: 10 s at 1 kHz, so a reliable subscriber that falls behind
#: for a while catches up without losses.
PUBLISHER_DEPTH = 10_000
#: After the publishers have matched their subscribers, time for the subscribers to match
#: the publishers [s].
SETTLE_S = 0.3
#: How long the end of the play waits for acknowledgements [s]: Fast DDS repairs a lost
#: message at its heartbeat (every 3 s), later on a starved machine.
ACK_TIMEOUT_S = 10.0
NS_PER_S = 1e9
#: The speed factors played [-]: at the slowest a second of bag lasts 1000 s (17 min), slower
#: is no playback anyone watches (and a far slower one overflowed the wait); at the fastest a
#: 1 kHz bag's messages are due 1 ns apart, already faster than they can be published.
RATE_RANGE = (1e-3, 1e6)
#: The /clock rates [Hz of bag time]: at least one per 100 s, the period of the node's slowest
#: timer (diagnostics_rate_hz 0.01), which a slower clock would leave behind; at most one per
#: nanosecond, the resolution of log time (and the period, 1e9 / rate, stays an integer).
CLOCK_RATE_RANGE = (1e-2, 1e9)
#: The longest single wait for a message [s]: threading's waits refuse more than
#: threading.TIMEOUT_MAX (292 years), which a bag's log times at a slow rate can exceed.
LONGEST_WAIT_S = 3600.0


class PlayError(RuntimeError):
    """The play failed while it ran (no subscriber in time)."""


class PlayInputError(ValueError):
    """The bag cannot be opened, or the options ask for what it does not have: a usage
    error, which the command line reports as every ValueError (one line, exit code 2, as
    ``replay``'s), not a failure while playing (:class:`PlayError`, exit code 1)."""


@dataclass(frozen=True, kw_only=True)
class PlayOptions:
    """rate: speed factor of the log time (within :data:`RATE_RANGE`). clock: publish /clock
    at clock_rate_hz of bag time (within :data:`CLOCK_RATE_RANGE`). topics: only these (all if
    empty). loop: start again at the end until stopped. wait_for_subscribers_s: see the module
    docstring (0: do not wait)."""

    rate: float = 1.0
    clock: bool = False
    clock_rate_hz: float = 100.0
    topics: tuple[str, ...] = ()
    loop: bool = False
    wait_for_subscribers_s: float = 0.0

    def __post_init__(self) -> None:
        """Refuse, as a usage error, a rate or clock rate outside :data:`RATE_RANGE` and
        :data:`CLOCK_RATE_RANGE` (named by the command line's options) and a negative or
        non-finite wait."""
        _require_within("--rate", self.rate, RATE_RANGE)
        _require_within("--clock-rate", self.clock_rate_hz, CLOCK_RATE_RANGE)
        if not 0.0 <= self.wait_for_subscribers_s < math.inf:
            raise PlayInputError("the wait for subscribers must be a finite number >= 0 s")


def _require_within(option: str, value: float, bounds: tuple[float, float]) -> None:
    """PlayInputError unless ``bounds[0] <= value <= bounds[1]`` (NaN is outside)."""
    low, high = bounds
    if not low <= value <= high:
        raise PlayInputError(f"{option} must be within {low:g} .. {high:g}, got {value:g}")


@dataclass
class PlayReport:
    """Messages published per topic, passes through the bag, the largest lateness [s], and
    the topics whose reliable subscribers had not acknowledged everything at the end."""

    published: Counter[str] = field(default_factory=Counter)
    passes: int = 0
    max_late_s: float = 0.0
    interrupted: bool = False
    unacknowledged: list[str] = field(default_factory=list)


class _Clock:
    """Publishes the bag time on /clock at most every ``1 / rate_hz`` of bag time."""

    def __init__(self, node: Any, rate_hz: float) -> None:
        qos = QoSProfile(depth=10, reliability=QoSReliabilityPolicy.RELIABLE)
        self.publisher = node.create_publisher(Clock, "/clock", qos)
        self._period_ns = int(NS_PER_S / rate_hz)
        self._last_ns: int | None = None

    def tick(self, log_time_ns: int) -> None:
        if self._last_ns is None or not 0 <= log_time_ns - self._last_ns < self._period_ns:
            self.publisher.publish(Clock(clock=time_msg(log_time_ns / NS_PER_S)))
            self._last_ns = log_time_ns


def _wait_for_subscribers(
    publishers: dict[str, Any], timeout_s: float, stop: threading.Event
) -> None:
    deadline = time.monotonic() + timeout_s
    while missing := [t for t, p in publishers.items() if p.get_subscription_count() == 0]:
        if time.monotonic() > deadline:
            raise PlayError(_no_subscriber(list(publishers), missing, timeout_s))
        if stop.wait(0.02):
            return
    stop.wait(SETTLE_S)


def _no_subscriber(topics: list[str], missing: list[str], timeout_s: float) -> str:
    """The error of a wait that timed out: the topics without a subscriber, those with one,
    and how to play only the latter (``--topics`` names bag topics: ``/clock`` is not one)."""
    text = f"no subscriber after {timeout_s:g} s on {', '.join(missing)}"
    subscribed = [t for t in topics if t not in missing]
    if subscribed:
        text += f"; {', '.join(subscribed)} {'has' if len(subscribed) == 1 else 'have'} one"
    played = [t for t in subscribed if t != "/clock"]
    if played and missing != ["/clock"]:
        text += f": pass --topics {' '.join(played)} to play only the subscribed topics"
    if "/clock" in missing:
        text += "; drop --clock if no node uses sim time"
    return text


def _has_reliable_subscriber(node: Any, topic: str) -> bool:
    """Some subscriber of ``topic`` is reliable (a best-effort one acknowledges nothing)."""
    return any(
        info.qos_profile.reliability == QoSReliabilityPolicy.RELIABLE
        for info in node.get_subscriptions_info_by_topic(topic)
    )


def play(bag: Path, options: PlayOptions, stop: threading.Event) -> PlayReport:
    """Play ``bag`` (rclpy must be initialised) until its end, or until ``stop`` is set."""
    try:
        reader = Reader(bag)
        reader.open()
    except (ReaderError, OSError) as exc:
        raise PlayInputError(
            f"cannot open bag {bag}: {exc} (a damaged bag, e.g. cut short, is read up to the "
            "damage by prsm-health replay)"
        ) from exc
    try:
        return _play(reader, options, stop)
    finally:
        reader.close()


def _play(reader: Reader, options: PlayOptions, stop: threading.Event) -> PlayReport:
    available = {c.topic for c in reader.connections}
    unknown = sorted(set(options.topics) - available)
    if unknown:
        raise PlayInputError(
            f"no topic {', '.join(unknown)} in the bag; it has {', '.join(sorted(available))}"
        )
    connections = [c for c in reader.connections if not options.topics or c.topic in options.topics]
    if options.loop and not any(c.msgcount for c in connections):  # it would spin on nothing
        raise PlayInputError("nothing to loop: the bag has no messages on the topics to play")
    node = rclpy.create_node("prsm_health_player")
    try:
        qos = QoSProfile(depth=PUBLISHER_DEPTH, reliability=QoSReliabilityPolicy.RELIABLE)
        publishers: dict[str, Any] = {}
        for connection in connections:
            if connection.topic not in publishers:
                try:
                    cls = message_class(connection.msgtype)
                except LookupError as exc:
                    raise PlayInputError(f"topic {connection.topic}: {exc}") from exc
                publishers[connection.topic] = node.create_publisher(cls, connection.topic, qos)
        clock = _Clock(node, options.clock_rate_hz) if options.clock else None
        if options.wait_for_subscribers_s > 0.0:
            waited = {**publishers, **({"/clock": clock.publisher} if clock else {})}
            _wait_for_subscribers(waited, options.wait_for_subscribers_s, stop)
        report = PlayReport()
        while not stop.is_set():
            _one_pass(reader, connections, publishers, clock, options.rate, stop, report)
            report.passes += 1
            if not options.loop:
                break
        report.interrupted = stop.is_set()
        for topic, publisher in publishers.items():
            if not _has_reliable_subscriber(node, topic):
                continue
            if not publisher.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT_S)):
                report.unacknowledged.append(topic)
        return report
    finally:
        node.destroy_node()


def _one_pass(
    reader: Reader,
    connections: Sequence[Any],
    publishers: dict[str, Any],
    clock: _Clock | None,
    rate: float,
    stop: threading.Event,
    report: PlayReport,
) -> None:
    start: float | None = None  # at the first message: reading the first chunk takes time
    first_ns = 0
    for connection, log_time_ns, raw in reader.messages(connections=connections):
        if start is None:
            start, first_ns = time.monotonic(), log_time_ns
        target = start + (log_time_ns - first_ns) / NS_PER_S / rate
        delay = target - time.monotonic()
        if delay <= 0.0:
            report.max_late_s = max(report.max_late_s, -delay)
        while delay > 0.0:
            if stop.wait(min(delay, LONGEST_WAIT_S)):
                return
            delay = target - time.monotonic()
        if clock is not None:
            clock.tick(log_time_ns)
        publishers[connection.topic].publish(bytes(raw))
        report.published[connection.topic] += 1
        if stop.is_set():
            return
