"""The speed floor of offline replay: rosbags reading and deserialising a topic of a bag.

The estimator's replay must take at most twice :func:`decode_time_baseline` on the same bag
(docs/bags.md). The baseline is plain rosbags: :class:`rosbags.rosbag2.Reader` (a bag
directory or a bare ``.mcap``) and ``deserialize_cdr`` of every message of the topic, with the
type store of :func:`prsm_health.bags.typestore.typestore`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from rosbags.rosbag2 import Reader, ReaderError

from prsm_health.bags.errors import BagError, TopicNotFoundError
from prsm_health.bags.topics import MOTOR_STATE_TOPIC
from prsm_health.bags.typestore import typestore


@dataclass(frozen=True)
class Baseline:
    """``seconds`` rosbags took to read and deserialise ``messages`` messages."""

    seconds: float
    messages: int


def decode_baseline(path: str | Path, topic: str = MOTOR_STATE_TOPIC) -> Baseline:
    """Time rosbags opening the bag and deserialising every message of ``topic`` (one run).

    Raises:
        TopicNotFoundError: the bag has no ``topic``.
        BagError: rosbags cannot read the bag (e.g. it is damaged).
    """
    store = typestore()  # built before the clock starts: not part of reading
    start = time.perf_counter()
    count = 0
    try:
        with Reader(Path(path)) as reader:
            connections = [c for c in reader.connections if c.topic == topic]
            if not connections:
                raise TopicNotFoundError(path, f"no topic {topic} for the rosbags baseline")
            for connection, _, data in reader.messages(connections):
                store.deserialize_cdr(data, connection.msgtype)
                count += 1
    except (ReaderError, FileNotFoundError) as exc:
        raise BagError(path, f"rosbags cannot read it: {exc}") from exc
    return Baseline(time.perf_counter() - start, count)


def decode_time_baseline(path: str | Path) -> float:
    """Seconds of :func:`decode_baseline` of the bag's MotorState topic (the replay's speed
    floor)."""
    return decode_baseline(path, MOTOR_STATE_TOPIC).seconds
