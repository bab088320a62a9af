"""The raw messages of every topic of an MCAP bag, merged in log-time order, up to any damage.

:func:`read_raw_messages` reads a bag (a rosbag2 directory of MCAP files or a bare ``.mcap``
file, :func:`~prsm_health.bags.bagfiles.bag_files`) with
:class:`~prsm_health.bags.mcap_scan.BagScanner`, as the replay reads it, so that
``prsm-health play`` publishes what the replay reads (files and chunks merged, types and
schemas checked), also what a damaged bag holds before its damage (rosbags opens only intact
MCAP files). One pass meets the topics
(:meth:`BagScanner.topics`), then one pass per topic read collects its CDR payloads; nothing
is decoded.

Everything read is held in memory: the payloads copied one after the other into one numpy
buffer, plus 28 bytes per message (log time, place, size, topic), about the bag's
uncompressed size; while it is assembled the peak is about 2.5 times that (14 MB for a 60 s
bag at 1 kHz, so about 0.8 GB for an hour). A bag larger than memory cannot be played.
Holding everything, a single stable sort by log time merges the topics (where
:mod:`prsm_health.bags.reader` merges one topic's segments with bounded memory, using each
batch's ``final_before_ns``).
"""

from __future__ import annotations

from collections.abc import Collection, Iterator
from contextlib import closing
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from prsm_health.bags.bagfiles import bag_files
from prsm_health.bags.errors import BagError
from prsm_health.bags.mcap_scan import (
    BagScanner,
    Int64Array,
    RawBatch,
    UInt8Array,
    UInt64Array,
)


@dataclass(frozen=True)
class RawMessages:
    """Messages of a bag in log-time order; iterating gives ``(topic, log time [ns], CDR
    bytes)``.

    ``types``: topic -> message type of every topic the bag's metadata.yaml declares or that
    was met before any damage, read or not.
    ``topics``: the topics read (``topic_index`` indexes it). Per message, in log-time order
    (equal log times in the order of ``topics``, then of the bag): ``topic_index``,
    ``log_time_ns``, and its payload ``payloads[starts : starts + sizes]``. ``damage``: what
    ended the reading early (None: the bag was read to its end).
    """

    types: dict[str, str]
    topics: tuple[str, ...]
    topic_index: NDArray[np.int32]
    log_time_ns: UInt64Array
    starts: Int64Array
    sizes: Int64Array
    payloads: UInt8Array
    damage: BagError | None

    def __len__(self) -> int:
        return len(self.log_time_ns)

    def __iter__(self) -> Iterator[tuple[str, int, bytes]]:
        for k in range(len(self)):
            start = int(self.starts[k])
            payload = self.payloads[start : start + int(self.sizes[k])].tobytes()
            yield self.topics[self.topic_index[k]], int(self.log_time_ns[k]), payload

    def counts(self) -> dict[str, int]:
        """Messages per topic read (0 for a topic with none before the damage)."""
        counted = np.bincount(self.topic_index, minlength=len(self.topics))
        return dict(zip(self.topics, map(int, counted), strict=True))


def _payload_bytes(batch: RawBatch) -> tuple[UInt8Array, Int64Array]:
    """The batch's payloads copied one after the other, and where each starts in that copy."""
    firsts = np.cumsum(batch.sizes) - batch.sizes
    places = np.repeat(batch.starts - firsts, batch.sizes) + np.arange(int(batch.sizes.sum()))
    return batch.buffer[places], firsts


def read_raw_messages(path: str | Path, topics: Collection[str] = ()) -> RawMessages:
    """The raw messages of ``topics`` (every topic if empty) in the bag at ``path``, all in
    memory (module docstring), up to any damage.

    A requested topic the bag does not have (before its damage) is not read: compare with
    :attr:`RawMessages.types`. The damage (a file cut short, a corrupt chunk, a channel of a
    read topic that is not CDR or has a second type) is returned in
    :attr:`RawMessages.damage`, not raised.

    Raises:
        BagError: ``path`` is not an MCAP bag (see :func:`~prsm_health.bags.bagfiles.bag_files`),
            or a file of it cannot be opened or does not start as an MCAP file.
    """
    files = bag_files(path)
    with closing(BagScanner(files.files)) as scanner:
        met = scanner.topics()
        known = {**(files.topics or {}), **met}
        damages = [scanner.damage]
        read = tuple(t for t in met if not topics or t in topics)
        payloads: list[UInt8Array] = []
        starts: list[Int64Array] = []
        sizes: list[Int64Array] = []
        log_times: list[UInt64Array] = []
        topic_index: list[NDArray[np.int32]] = []
        places: list[NDArray[np.int64]] = []
        size = 0
        for index, topic in enumerate(read):
            for batch in scanner.batches(topic):
                payload, firsts = _payload_bytes(batch)
                payloads.append(payload)
                starts.append(size + firsts)
                sizes.append(batch.sizes)
                log_times.append(batch.log_time_ns)
                topic_index.append(np.full(len(batch.sizes), index, dtype=np.int32))
                places.append(np.full(len(batch.sizes), batch.place, dtype=np.int64))
                size += len(payload)
            damages.append(scanner.damage)
    log_time = np.concatenate([np.empty(0, np.uint64), *log_times])
    topic_of = np.concatenate([np.empty(0, np.int32), *topic_index])
    place = np.concatenate([np.empty(0, np.int64), *places])
    order = np.lexsort((place, topic_of, log_time))  # stable: a segment's ties keep their order
    return RawMessages(
        types=known,
        topics=read,
        topic_index=topic_of[order],
        log_time_ns=log_time[order],
        starts=np.concatenate([np.empty(0, np.int64), *starts])[order],
        sizes=np.concatenate([np.empty(0, np.int64), *sizes])[order],
        payloads=np.concatenate([np.empty(0, np.uint8), *payloads]),
        # the bag's damage (the topics' pass) before a topic's own (not CDR, two types)
        damage=damages[0] or next((d for d in damages[1:] if d is not None), None),
    )
