"""``prsm-health play``: publish a rosbag2 bag's messages over DDS with their original timing.

A replacement for ``ros2 bag play`` (not on PyPI for Jazzy). An MCAP bag (rosbag2 directory
or bare ``.mcap`` file) is read raw with :func:`~prsm_health.bags.raw.read_raw_messages`, as
the replay reads it (into memory, files and chunks merged into log-time order, up to any
damage, which is in the :class:`PlayReport`), a SQLite3 rosbag2 directory with rosbags; the
messages are published as the serialized CDR bytes they are, through rclpy publishers of their
types, in log-time order, at ``log time / rate`` after the start. (Until 2026-11-27 rosbags
read every bag it could open: it played the files of a split bag one after another, called
an unchunked MCAP written out of log-time order damaged, published a second type on a topic
and took the counts of a metadata.yaml that disagreed with the files; found by a review
session.) :class:`BagSource` is what the player needs of either.

Optionally ``/clock`` (rosgraph_msgs/Clock) carries the log time, for nodes with
``use_sim_time``. Publishers are reliable (a best-effort subscriber matches them as well) and
keep all messages until every reliable subscriber has them (KEEP_ALL): a subscriber that
falls behind holds the play back instead of losing messages. With keep-last (10 s at 1 kHz)
a node with reliable input fed at ``--rate 10`` received 25,474 of 60,000 messages, and the
play, which can wait only for what its history still holds, reported none lost. Fast DDS
holds at most 5,000 unacknowledged messages per publisher (its default resource limit; the
QoS depth does not apply to KEEP_ALL): a write beyond blocks 100 ms (its max_blocking_time)
and fails, so the player writes the message again until a subscriber has taken one, at most
``ACK_TIMEOUT_S`` (then :class:`PlayError`: a stopped subscriber ends the play).

``wait_for_subscribers_s``: before the first message, wait until every played topic (and
``/clock`` if published) has a subscriber (at most that long; otherwise an error naming the
topics with and without one: a topic nothing reads, e.g. ``/truth/state``, is left out with
``topics``), then
:data:`SETTLE_S` more so that the subscriber side of discovery completes too: a best-effort
subscriber drops what arrives before it has matched the publisher. At the end the player
waits for reliable subscribers to acknowledge everything (at most ``FINAL_ACK_TIMEOUT_S``), so a
short bag is not cut off, and reports the topics they did not; best-effort subscribers are not
waited for.
"""

from __future__ import annotations

import math
import threading
import time
from collections import Counter
from collections.abc import Callable, Collection, Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import rclpy
from rclpy.duration import Duration
from rclpy.exceptions import InvalidTopicNameException
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.qos import QoSHistoryPolicy, QoSProfile, QoSReliabilityPolicy
from rosbags.rosbag2 import Reader
from rosgraph_msgs.msg import Clock

from prsm_health.bags.bagfiles import is_sqlite_bag
from prsm_health.bags.errors import BagDamagedError, BagError
from prsm_health.bags.raw import read_raw_messages
from prsm_health.ros.messages import time_msg
from prsm_health.ros.runtime import message_class

#: After the publishers have matched their subscribers, time for the subscribers to match
#: the publishers [s].
SETTLE_S = 0.3
#: How long a message held back by a full history waits for a reliable subscriber to take
#: one [s] (module docstring): Fast DDS repairs a lost message at its heartbeat (every 3 s),
#: later on a starved machine.
ACK_TIMEOUT_S = 10.0
#: How long the player waits at the end (after Ctrl-C too) for reliable subscribers to
#: acknowledge everything [s]. Up to the 5,000 messages Fast DDS holds may be outstanding
#: then: a node stopped for a second while a play at 50 kHz held them needed
#: 5.4-11.6 s after it went on (six runs, 2026-11-29, its lost packets repaired at the
#: heartbeats), and at ACK_TIMEOUT_S, the wait until then, one play in three exited before,
#: its messages lost. A stopped subscriber ends the play after this long.
FINAL_ACK_TIMEOUT_S = 30.0
NS_PER_S = 1e9
#: The speed factors played [-]: at the slowest a second of bag lasts 1000 s (17 min), slower
#: is no playback anyone watches (and a far slower one overflowed the wait); at the fastest a
#: 1 kHz bag's messages are due 1 ns apart, already faster than they can be published.
RATE_RANGE = (1e-3, 1e6)
#: The /clock rate by default [Hz of bag time].
DEFAULT_CLOCK_RATE_HZ = 100.0
#: The /clock rates [Hz of bag time]: at least one per 100 s, the period of the node's slowest
#: timer (diagnostics_rate_hz 0.01), which a slower clock would leave behind; at most one per
#: nanosecond, the resolution of log time (and the period, 1e9 / rate, stays an integer).
CLOCK_RATE_RANGE = (1e-2, 1e9)
#: The longest single wait for a message [s]: threading's waits refuse more than
#: threading.TIMEOUT_MAX (292 years), which a bag's log times at a slow rate can exceed.
LONGEST_WAIT_S = 3600.0


class PlayError(RuntimeError):
    """The play failed while it ran (no subscriber in time), or the bag has nothing to play
    (no message on the topics to play, or none before its damage)."""


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
    clock_rate_hz: float = DEFAULT_CLOCK_RATE_HZ
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
    """Messages published per topic, passes through the bag, the largest lateness [s], the
    topics whose reliable subscribers had not acknowledged everything at the end, and the
    damage of a damaged bag (the messages before it were played)."""

    published: Counter[str] = field(default_factory=Counter)
    passes: int = 0
    max_late_s: float = 0.0
    interrupted: bool = False
    unacknowledged: list[str] = field(default_factory=list)
    damage: BagError | None = None


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


def _reliable_subscribers(node: Any, topic: str) -> set[tuple[int, ...]]:
    """The reliable subscribers of ``topic``, by endpoint GID (a best-effort one acknowledges
    nothing)."""
    return {
        tuple(info.endpoint_gid)
        for info in node.get_subscriptions_info_by_topic(topic)
        if info.qos_profile.reliability == QoSReliabilityPolicy.RELIABLE
    }


@dataclass(frozen=True)
class BagSource:
    """A bag as the player plays it.

    ``types``: topic -> message type of every topic of the bag (of a damaged bag: those its
    metadata.yaml declares and those met before the damage). ``counts``: the messages of each
    topic to play. ``new_pass()``: a new pass over those, in log-time order, as ``(topic, log
    time [ns], CDR bytes)``. ``damage``: what ended the reading of a damaged bag (None: the
    bag is intact).
    """

    types: dict[str, str]
    counts: dict[str, int]
    new_pass: Callable[[], Iterable[tuple[str, int, bytes]]]
    damage: BagError | None = None


@contextmanager
def open_bag(bag: Path, topics: Collection[str]) -> Iterator[BagSource]:
    """The bag at ``bag`` with the messages of ``topics`` (all if empty) to play: an MCAP bag
    with this package's reader, up to any damage; a SQLite3 one with rosbags.

    Raises:
        PlayInputError: neither can open it (missing, not a bag).
    """
    if is_sqlite_bag(bag):
        try:
            reader = Reader(bag)
            reader.open()
        # rosbags raises assorted errors on what it cannot open (its ReaderError besides
        # UnicodeDecodeError, struct.error, OverflowError, MemoryError).
        except Exception as exc:
            raise PlayInputError(f"cannot open bag {bag}: {_one_line(exc)}") from exc
        try:
            yield _rosbags_source(reader, topics, bag)
        finally:
            reader.close()
        return
    try:
        raw = read_raw_messages(bag, topics)
    except BagError as unreadable:
        raise PlayInputError(f"cannot open bag {bag}: {_one_line(unreadable)}") from unreadable
    yield BagSource(raw.types, raw.counts(), lambda: raw, raw.damage)


def counts_text(counts: Mapping[str, int]) -> str:
    """Messages per topic as ``/a 10, /b 2`` (topics in order), empty for none."""
    return ", ".join(f"{topic} {n}" for topic, n in sorted(counts.items()))


def _one_line(error: BaseException) -> str:
    """An error's text on one line (a YAML parser's spans several)."""
    return " ".join(str(error).split())


def _rosbags_source(reader: Reader, topics: Collection[str], bag: Path) -> BagSource:
    """The (SQLite3) bag as rosbags opened it; a read that fails ends the pass with a
    :class:`~prsm_health.bags.errors.BagDamagedError` (the messages before it were played)."""
    played = [c for c in reader.connections if not topics or c.topic in topics]
    counts: Counter[str] = Counter()
    for connection in played:
        counts[connection.topic] += connection.msgcount

    def messages() -> Iterator[tuple[str, int, bytes]]:
        read = 0
        try:
            for connection, log_time_ns, raw in reader.messages(connections=played):
                if not counts[connection.topic]:  # rosbags takes the counts of metadata.yaml
                    raise PlayError(
                        f"{connection.topic}: the bag's metadata counts no message on it, yet "
                        "it holds some: its metadata.yaml disagrees with its files"
                    )
                read += 1
                yield connection.topic, log_time_ns, raw
        except PlayError:
            raise
        except Exception as exc:  # rosbags raises assorted errors on a corrupt chunk
            reason = f"unreadable after {read} messages: {type(exc).__name__}: {exc}"
            raise BagDamagedError(bag, reason) from exc

    types: dict[str, str] = {}
    for connection in reader.connections:
        types.setdefault(connection.topic, connection.msgtype)
    return BagSource(types, dict(counts), messages)


def _check(source: BagSource, options: PlayOptions) -> None:
    """Refuse topics the bag does not have and a loop over nothing (usage errors), and a
    bag with no message on the topics to play, or a damaged one with none before its damage
    (:class:`PlayError`)."""
    unknown = sorted(set(options.topics) - source.types.keys())
    available = ", ".join(sorted(source.types)) or "none"
    if unknown and source.damage is not None:
        raise PlayInputError(
            f"no topic {', '.join(unknown)} in the bag's metadata or before its damage; "
            f"topics known: {available} (the bag is damaged: {source.damage})"
        )
    if unknown:
        raise PlayInputError(f"no topic {', '.join(unknown)} in the bag; it has {available}")
    if source.damage is not None and not any(source.counts.values()):
        raise PlayError(f"nothing to play before the damage of the bag: {source.damage}")
    if options.loop and not any(source.counts.values()):  # it would spin on nothing
        raise PlayInputError("nothing to loop: the bag has no messages on the topics to play")
    if not any(source.counts.values()):
        asked = ", ".join(options.topics) or "any topic"
        raise PlayError(f"nothing to play: no message on {asked} in the bag; it has {available}")


def play(
    source: BagSource, options: PlayOptions, stop: threading.Event, warn: Callable[[str], None]
) -> PlayReport:
    """Play ``source`` (rclpy must be initialised) until its end, or until ``stop`` is set;
    ``warn`` is told, before the first message, what a damaged bag leaves out."""
    _check(source, options)
    if source.damage is not None:
        warn(
            f"the bag is damaged: the {sum(source.counts.values())} messages before the "
            f"damage are played ({counts_text(source.counts)})"
        )
    node = rclpy.create_node("prsm_health_player")
    try:
        qos = QoSProfile(
            history=QoSHistoryPolicy.KEEP_ALL, reliability=QoSReliabilityPolicy.RELIABLE
        )
        publishers: dict[str, Any] = {}
        for topic in (t for t, count in source.counts.items() if count):  # none for nothing
            try:
                cls = message_class(source.types[topic])
                publishers[topic] = node.create_publisher(cls, topic, qos)
            except (LookupError, InvalidTopicNameException) as exc:
                raise PlayInputError(f"topic {topic!r}: {_one_line(exc)}") from exc
        clock = _Clock(node, options.clock_rate_hz) if options.clock else None
        if options.wait_for_subscribers_s > 0.0:
            waited = {**publishers, **({"/clock": clock.publisher} if clock else {})}
            _wait_for_subscribers(waited, options.wait_for_subscribers_s, stop)
        report = PlayReport(damage=source.damage)
        while not stop.is_set():
            try:
                _one_pass(source.new_pass(), publishers, clock, options.rate, stop, report)
            except BagDamagedError as damage:  # found while reading: the pass ends there
                report.damage = damage
            report.passes += 1
            if not options.loop or report.damage is not None:
                break
        for topic, publisher in publishers.items():
            if not _acknowledged(node, topic, publisher):
                report.unacknowledged.append(topic)
        report.interrupted = stop.is_set()
        return report
    finally:
        node.destroy_node()


def _one_pass(
    messages: Iterable[tuple[str, int, bytes]],
    publishers: dict[str, Any],
    clock: _Clock | None,
    rate: float,
    stop: threading.Event,
    report: PlayReport,
) -> None:
    start: float | None = None  # at the first message: reading the first chunk takes time
    first_ns = 0
    for topic, log_time_ns, raw in messages:
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
        try:
            if not _publish_held_back(publishers[topic], bytes(raw), stop):
                return
        except _rclpy.RCLError as exc:
            raise PlayError(
                f"{topic}: no message taken by its reliable subscribers for {ACK_TIMEOUT_S:g} s"
                f" after {report.published[topic]} published (is a subscriber stopped?):"
                f" {_one_line(exc)}"
            ) from exc
        report.published[topic] += 1
        if stop.is_set():
            return


def _acknowledged(node: Any, topic: str, publisher: Any) -> bool:
    """Whether every reliable subscriber of ``topic`` acknowledged all ``publisher`` published
    within FINAL_ACK_TIMEOUT_S and is still there: Fast DDS drops a subscriber whose
    participant stops answering when its lease runs out (20 s), and the wait then ends as if
    it had acknowledged (a stopped node's 3,000 messages were reported taken). Waited for
    after Ctrl-C too, as what was published before it. True without a reliable subscriber:
    there is none to wait for."""
    waited_for = _reliable_subscribers(node, topic)
    if not waited_for:
        return True
    deadline = time.monotonic() + FINAL_ACK_TIMEOUT_S
    acknowledged = False
    while not acknowledged:
        left_s = deadline - time.monotonic()
        if left_s <= 0.0:
            return False
        acknowledged = publisher.wait_for_all_acked(Duration(seconds=min(1.0, left_s)))
        if acknowledged:
            time.sleep(SETTLE_S)  # the graph follows a subscriber dropped from the match
        if not waited_for <= _reliable_subscribers(node, topic):
            return False
    return True


def _publish_held_back(publisher: Any, raw: bytes, stop: threading.Event) -> bool:
    """Publish ``raw``, written again while the publisher's history is full of messages a
    reliable subscriber has not acknowledged (each write blocks 100 ms, then fails: module
    docstring); False if stopped first. The last write's RCLError after ``ACK_TIMEOUT_S``."""
    deadline = time.monotonic() + ACK_TIMEOUT_S
    while True:
        try:
            publisher.publish(raw)
            return True
        except _rclpy.RCLError:
            if stop.is_set():
                return False
            if time.monotonic() > deadline:
                raise
