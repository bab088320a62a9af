"""Reading the messages of one topic out of MCAP files, in log-time order, up to any damage.

A small MCAP reader (https://mcap.dev/spec) made for two needs the general readers do not
meet together: speed (payloads are located, not copied into per-message objects, so numpy can
decode them in bulk) and damaged files (whatever is complete before the damage is delivered).

Pass 1 walks the top-level records of each file, reading only record headers: it finds the
chunks (and runs of unchunked messages) with their log-time ranges, and stops at the end of
the data section (``DataEnd``) or at the first record that runs past the end of the file.
Pass 2 decompresses the segments in order of their first log time and yields, per segment, the
messages of the topic sorted by log time (:class:`RawBatch`). Each batch says below which log
time its messages are final (no later batch has an earlier message), so a consumer merges
overlapping segments into exact log-time order with bounded memory.

Damage (a file cut short, a chunk that does not decompress or fails its CRC, a record that
overruns its chunk) is not raised from the iterator: iteration stops after the last complete
segment before it, and :attr:`BagScanner.damage` holds a :class:`BagDamagedError` naming the
file, the byte offset and what is wrong. Callers deliver what they got, then raise it. A file
cut inside its summary section (after the data section) has lost no message, but is reported
as damaged all the same.
"""

from __future__ import annotations

import mmap
import struct
import sys
import zlib
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import lz4.frame  # type: ignore[import-untyped]
import numpy as np
from numpy.typing import NDArray

from prsm_health.bags.errors import BagDamagedError, BagError
from prsm_health.bags.schemas import expected_fields, schema_fields

if sys.version_info >= (3, 14):  # pragma: no cover
    from compression import zstd
else:
    from backports import zstd

MAGIC = b"\x89MCAP0\r\n"
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK = 0x01, 0x02, 0x03, 0x04, 5, 6
OP_CHUNK_INDEX, OP_DATA_END = 0x08, 0x0F
RECORD_NAMES = {
    0x01: "Header",
    0x02: "Footer",
    0x03: "Schema",
    0x04: "Channel",
    0x05: "Message",
    0x06: "Chunk",
    0x07: "MessageIndex",
    0x08: "ChunkIndex",
    0x09: "Attachment",
    0x0A: "AttachmentIndex",
    0x0B: "Statistics",
    0x0C: "Metadata",
    0x0D: "MetadataIndex",
    0x0E: "SummaryOffset",
    0x0F: "DataEnd",
}
FOOTER_SIZE = 9 + 20 + len(MAGIC)
NO_MESSAGES = -1

_RECORD = struct.Struct("<BQ")
_MESSAGE = struct.Struct("<HIQ")
_CHUNK_TIMES = struct.Struct("<QQQI")
_CHUNK_INDEX_START = struct.Struct("<QQQ")  # first and last log time, the chunk's offset
_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")

DECOMPRESSORS: dict[str, Callable[[bytes], bytes]] = {
    "": bytes,
    "zstd": zstd.decompress,
    "lz4": lz4.frame.decompress,
}

UInt8Array = NDArray[np.uint8]
Int64Array = NDArray[np.int64]
UInt64Array = NDArray[np.uint64]


class _DamageError(Exception):
    """Internal: the file is damaged at byte ``offset``; ``reason`` says how."""

    def __init__(self, offset: int, reason: str) -> None:
        super().__init__(reason)
        self.offset = offset
        self.reason = reason

    def error(self, path: Path) -> BagError:
        """The public error for the file at ``path``."""
        return BagDamagedError(path, f"damaged at byte {self.offset}: {self.reason}")


class _NotMcapError(_DamageError):
    """Internal: the file does not start with the MCAP magic (:class:`BagScanner` refuses it:
    not a damaged bag but no MCAP at all)."""


class _MismatchError(Exception):
    """Internal: a channel of the topic is not what a reader of the topic can use."""

    def error(self, path: Path) -> BagError:
        """The public error for the file at ``path``."""
        return BagError(path, str(self))


@dataclass(frozen=True)
class ChannelInfo:
    """An MCAP channel: topic, message type (its schema name) and message encoding; the
    fields its ros2msg schema defines (:func:`~prsm_health.bags.schemas.schema_fields`;
    None: another schema encoding, or none)."""

    id: int
    topic: str
    msgtype: str
    encoding: str
    fields: tuple[str, ...] | None = None


@dataclass(frozen=True)
class RawBatch:
    """Messages of one topic from one segment of a file, sorted by log time (stable).

    ``starts``/``sizes`` locate each CDR payload in ``buffer``. Messages with a log time below
    ``final_before_ns`` come before every message of later batches; ``None``: last batch.
    ``place``: where the segment is in the bag (file index times 2**48 plus its byte offset),
    which orders equal log times of different batches as they were written (batches come in
    the order of their first log time, not of the files).
    """

    msgtype: str
    buffer: UInt8Array
    starts: Int64Array
    sizes: Int64Array
    log_time_ns: UInt64Array
    final_before_ns: int | None
    place: int


@dataclass(frozen=True)
class _Segment:
    """A chunk record, or a run of unchunked records, with its message log-time range."""

    file: int
    offset: int
    end: int
    chunk: bool
    start_ns: int
    end_ns: int

    @property
    def sort_key(self) -> tuple[int, int, int]:
        """Processing order: segments without messages first, then by first log time."""
        return (
            self.start_ns if self.start_ns <= self.end_ns else NO_MESSAGES,
            self.file,
            self.offset,
        )


class _Reader:
    """Cursor over one record body (strings and maps of the MCAP spec)."""

    def __init__(self, data: bytes | mmap.mmap, pos: int, end: int) -> None:
        self.data, self.pos, self.end = data, pos, end

    def _take(self, size: int) -> int:
        start, self.pos = self.pos, self.pos + size
        if self.pos > self.end:
            raise _DamageError(start, "a record is shorter than its fields")
        return start

    def u16(self) -> int:
        return int(_U16.unpack_from(self.data, self._take(2))[0])

    def u32(self) -> int:
        return int(_U32.unpack_from(self.data, self._take(4))[0])

    def u64(self) -> int:
        return int(_U64.unpack_from(self.data, self._take(8))[0])

    def raw(self, size: int) -> bytes:
        start = self._take(size)
        return bytes(self.data[start : start + size])

    def string(self) -> str:
        return self.raw(self.u32()).decode("utf-8", errors="replace")


@dataclass
class _File:
    """One MCAP file: memory map, schema names, channels and segments found by pass 1."""

    path: Path
    data: mmap.mmap | bytes = b""
    schemas: dict[int, tuple[str, tuple[str, ...] | None]] = field(default_factory=dict)
    channels: dict[int, ChannelInfo] = field(default_factory=dict)
    summary_channels: dict[int, ChannelInfo] | None = None
    segments: list[_Segment] = field(default_factory=list)
    damage: _DamageError | None = None

    def register(self, op: int, data: bytes | mmap.mmap, body: int, end: int) -> ChannelInfo | None:
        """Record a Schema or Channel record; returns the channel if it was one."""
        rec = _Reader(data, body, end)
        if op == OP_SCHEMA:
            schema_id = rec.u16()
            name, schema_encoding = rec.string(), rec.string()
            fields = schema_fields(rec.string()) if schema_encoding == "ros2msg" else None
            self.schemas[schema_id] = (name, fields)
            return None
        channel_id, schema_id = rec.u16(), rec.u16()
        topic, encoding = rec.string(), rec.string()
        name, fields = self.schemas.get(schema_id, ("", None))
        channel = ChannelInfo(channel_id, topic, name, encoding, fields)
        self.channels[channel_id] = channel
        return channel


def _place(segment: _Segment, pos: int) -> int:
    """File offset for errors at ``pos`` of a segment: the chunk itself, or the exact byte."""
    return segment.offset if segment.chunk else segment.offset + pos


def _record_name(op: int) -> str:
    return RECORD_NAMES.get(op, f"opcode 0x{op:02x}")


def _open(path: Path) -> _File:
    """Map ``path`` and run pass 1 (record headers only); damage is kept, not raised."""
    found = _File(path)
    try:
        with path.open("rb") as handle:
            size = handle.seek(0, 2)
            found.data = mmap.mmap(handle.fileno(), 0, access=mmap.ACCESS_READ) if size else b""
    except OSError as exc:
        raise BagError(path, f"cannot open: {exc.strerror or exc}") from exc
    try:
        _pass1(found)
    except _DamageError as damage:
        found.damage = damage
    return found


def _pass1(found: _File) -> None:
    data, size = found.data, len(found.data)
    if data[: len(MAGIC)] != MAGIC:
        if size < len(MAGIC) and MAGIC.startswith(bytes(data)):
            raise _DamageError(0, f"file is {size} bytes long, cut inside the leading MCAP magic")
        raise _NotMcapError(0, "not an MCAP file (no MCAP magic at the start)")
    pos = len(MAGIC)
    loose: list[tuple[int, int, int]] = []  # unchunked messages: (record start, end, log time)
    while True:
        if pos + 9 > size:
            where = "the end of its data section" if pos == size else "a record header"
            raise _DamageError(pos, f"file cut at byte {size}, before {where} (truncated file?)")
        op, length = _RECORD.unpack_from(data, pos)
        body, end = pos + 9, pos + 9 + length
        if op == 0x00:  # reserved by the spec: zeroed or overwritten data, not a record
            raise _DamageError(pos, f"invalid record opcode 0x00 at byte {pos} (zeroed data?)")
        if end > size:
            where = f"the {length}-byte body of the {_record_name(op)} record at byte {pos}"
            if data[size - len(MAGIC) :] == MAGIC:  # the file ends whole: not cut short
                raise _DamageError(
                    pos, f"{where} would run past the file's end: a corrupt record header"
                )
            raise _DamageError(
                pos, f"file cut at byte {size}, {size - body} bytes into {where} (truncated file?)"
            )
        if op == OP_MESSAGE:
            if length < 22:
                raise _DamageError(
                    pos, f"Message record at byte {pos} is too short ({length} bytes)"
                )
            loose.append((pos, end, int(_MESSAGE.unpack_from(data, body)[2])))
        else:
            _close_loose(found, loose)
        if op == OP_HEADER and pos != len(MAGIC):
            raise _DamageError(pos, f"second Header record at byte {pos}")
        if op in (OP_SCHEMA, OP_CHANNEL):
            found.register(op, data, body, end)
        elif op == OP_CHUNK:
            if length < _CHUNK_TIMES.size:
                raise _DamageError(pos, f"Chunk record at byte {pos} is too short ({length} bytes)")
            start_ns, end_ns, _, _ = _CHUNK_TIMES.unpack_from(data, body)
            found.segments.append(_Segment(0, pos, end, True, int(start_ns), int(end_ns)))
        elif op in (OP_DATA_END, OP_FOOTER):
            break
        pos = end
    if op == OP_DATA_END:
        _read_summary(found, end)


def _close_loose(found: _File, loose: list[tuple[int, int, int]]) -> None:
    if loose:
        times = [t for _, _, t in loose]
        found.segments.append(_Segment(0, loose[0][0], loose[-1][1], False, min(times), max(times)))
        loose.clear()


def _read_summary(found: _File, data_end: int) -> None:
    """Check the footer and read the channels of the summary section (if it has them).

    A chunk that the summary indexes but the data section does not hold as a Chunk record
    (its record header corrupt: a reader skips a record of unknown opcode, and its messages
    were silently lost) is damage: the segments that start at its first log time or later
    are dropped.
    """
    data, size = found.data, len(found.data)
    footer = size - FOOTER_SIZE
    if footer < data_end or data[size - len(MAGIC) :] != MAGIC or data[footer] != OP_FOOTER:
        raise _DamageError(
            data_end,
            f"no valid footer after the data section (file cut at byte {size}?); "
            "the data section is complete, every message in it was read",
        )
    summary_start = int(_U64.unpack_from(data, footer + 9)[0])
    if not summary_start:
        return
    if not data_end <= summary_start <= footer:
        raise _DamageError(footer, f"footer points to a summary at byte {summary_start}")
    channels: dict[int, ChannelInfo] = {}
    indexed: list[tuple[int, int]] = []  # (first log time, offset) of each indexed chunk
    pos = summary_start
    while pos < footer:
        op, length = _RECORD.unpack_from(data, pos)
        body, end = pos + 9, pos + 9 + length
        if end > footer:
            raise _DamageError(pos, f"summary record at byte {pos} overruns the footer")
        if op in (OP_SCHEMA, OP_CHANNEL) and (channel := found.register(op, data, body, end)):
            channels[channel.id] = channel
        elif op == OP_CHUNK_INDEX and length >= _CHUNK_INDEX_START.size:
            start_ns, _, offset = _CHUNK_INDEX_START.unpack_from(data, body)
            indexed.append((int(start_ns), int(offset)))
        pos = end
    # A summary without Channel records (the mcap writer's repeat_channels=False) declares
    # nothing: the topics come from the data section (they read as "none").
    found.summary_channels = channels or None
    held = {s.offset for s in found.segments if s.chunk}
    if missing := sorted((t, offset) for t, offset in indexed if offset not in held):
        first_ns, offset = missing[0]
        found.segments = [s for s in found.segments if s.sort_key[0] < first_ns]
        raise _DamageError(
            offset,
            f"the summary indexes a Chunk record at byte {offset} that the data section does "
            f"not hold ({len(missing)} such chunk(s); a corrupt record header?): the chunks "
            f"that start at its first log time, {first_ns} ns, or later are not read",
        )


def _decompress(found: _File, segment: _Segment) -> bytes:
    """The records of a chunk (or the bytes of an unchunked run), checked."""
    data = found.data
    if not segment.chunk:
        return bytes(data[segment.offset : segment.end])
    rec = _Reader(data, segment.offset + 9 + 16, segment.end)  # after the two log times
    size, crc = rec.u64(), rec.u32()
    compression = rec.string()
    stored = rec.raw(rec.u64())
    where = f"Chunk record at byte {segment.offset}"
    if compression not in DECOMPRESSORS:
        raise _DamageError(segment.offset, f"{where}: unsupported compression {compression!r}")
    try:
        records = DECOMPRESSORS[compression](stored)
    except Exception as exc:  # zstd and lz4 raise their own error types
        raise _DamageError(segment.offset, f"{where} does not decompress ({exc})") from exc
    if len(records) != size:
        raise _DamageError(segment.offset, f"{where}: {len(records)} bytes, {size} announced")
    if crc and zlib.crc32(records) != crc:
        raise _DamageError(segment.offset, f"{where} fails its CRC check")
    return records


class BagScanner:
    """The MCAP files of one bag, scanned for the messages of a topic (module docstring).

    The files are memory-mapped until :meth:`close` (use ``contextlib.closing``). ``files``
    are scanned together (the files of a split bag). ``seen`` maps every topic met so far to
    its type.

    Raises:
        BagError: a file cannot be opened, or does not start with the MCAP magic (one cut
            inside the magic, or empty, is a damaged MCAP file instead).
    """

    def __init__(self, files: Sequence[Path]) -> None:
        self.damage: BagError | None = None
        self.seen: dict[str, str] = {}
        self._files: list[_File] = []
        try:
            for path in files:
                self._files.append(_open(path))
            for found in self._files:
                if isinstance(found.damage, _NotMcapError):
                    raise BagError(found.path, found.damage.reason)
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Unmap the files."""
        for found in self._files:
            if isinstance(found.data, mmap.mmap):
                found.data.close()
        self._files.clear()

    def declared_topics(self) -> dict[str, str] | None:
        """Topic -> message type from the summary sections; None if a file has no summary."""
        topics: dict[str, str] = {}
        for found in self._files:
            if found.summary_channels is None:
                return None
            topics.update({c.topic: c.msgtype for c in found.summary_channels.values()})
        return topics

    def topics(self) -> dict[str, str]:
        """Topic -> message type of every channel in the segments before any damage.

        A pass over every segment that collects no message (a ROS topic name is never
        empty); it sets :attr:`damage` as :meth:`batches` does.
        """
        for _ in self.batches(""):
            pass
        return dict(self.seen)

    def _fail(self, found: _File, damage: _DamageError | _MismatchError) -> None:
        self.damage = damage.error(found.path)

    def batches(self, topic: str) -> Iterator[RawBatch]:
        """The messages of ``topic``, one batch per segment that has any (module docstring).

        On damage, iteration stops after the last complete segment and :attr:`damage` is set;
        so it does at a channel of ``topic`` that is not CDR or has a second type (then
        :attr:`damage` is a plain :class:`BagError`).
        """
        self.damage = None
        segments = sorted(
            (replace(s, file=i) for i, f in enumerate(self._files) for s in f.segments),
            key=lambda s: s.sort_key,
        )
        starts = [s.sort_key[0] for s in segments]
        for k, segment in enumerate(segments):
            found = self._files[segment.file]
            try:
                batch = self._scan(found, segment, topic)
            except (_DamageError, _MismatchError) as damage:
                self._fail(found, damage)
                return
            if batch is not None:
                later = [t for t in starts[k + 1 :] if t != NO_MESSAGES]
                yield RawBatch(
                    *batch,
                    final_before_ns=later[0] if later else None,
                    place=segment.file * 2**48 + segment.offset,
                )
        for found in self._files:
            if found.damage is not None:
                self._fail(found, found.damage)
                return

    def _wanted(self, found: _File, topic: str, channel: ChannelInfo) -> bool:
        """Whether ``channel`` carries ``topic``; checks that it is CDR of one type."""
        self.seen.setdefault(channel.topic, channel.msgtype)
        if channel.topic != topic:
            return False
        if channel.encoding != "cdr":
            raise _MismatchError(f"topic {topic} is encoded as {channel.encoding!r}, not 'cdr'")
        if self.seen[topic] != channel.msgtype:
            raise _MismatchError(
                f"topic {topic} has two types: {self.seen[topic]} and {channel.msgtype}"
            )
        expected = expected_fields(channel.msgtype)
        if channel.fields is not None and expected is not None and channel.fields != expected:
            raise _MismatchError(
                f"topic {topic}: its schema {channel.msgtype} defines "
                f"[{', '.join(channel.fields)}], not the installed [{', '.join(expected)}] "
                "(another version of the message)"
            )
        return True

    def _scan(
        self, found: _File, segment: _Segment, topic: str
    ) -> tuple[str, UInt8Array, Int64Array, Int64Array, UInt64Array] | None:
        """Pass 2 over one segment: the messages of ``topic`` in it, sorted by log time."""
        known = (found.summary_channels or {}) | found.channels  # the data section's win
        wanted = {cid for cid, c in known.items() if self._wanted(found, topic, c)}
        data = _decompress(found, segment)
        times: list[int] = []
        starts: list[int] = []
        sizes: list[int] = []
        pos, end = 0, len(data)
        while pos < end:
            if pos + 9 > end:
                raise _DamageError(
                    _place(segment, pos), f"record header at {pos} overruns its segment"
                )
            op, length = _RECORD.unpack_from(data, pos)
            body = pos + 9
            if body + length > end:
                raise _DamageError(
                    _place(segment, pos), f"{_record_name(op)} record at {pos} overruns its chunk"
                )
            if op == OP_MESSAGE:
                if length < 22:
                    raise _DamageError(
                        _place(segment, pos), f"Message record too short ({length} bytes)"
                    )
                channel_id, _, log_time = _MESSAGE.unpack_from(data, body)
                if channel_id in wanted:
                    times.append(log_time)
                    starts.append(body + 22)
                    sizes.append(length - 22)
                elif channel_id not in known:
                    raise _DamageError(
                        _place(segment, pos), f"message on unknown channel {channel_id}"
                    )
            elif op in (OP_SCHEMA, OP_CHANNEL):
                channel = found.register(op, data, body, body + length)
                if channel is not None:
                    known[channel.id] = channel
                    if self._wanted(found, topic, channel):
                        wanted.add(channel.id)
            pos = body + length
        if not times:
            return None
        log_time = np.asarray(times, dtype=np.uint64)
        order = np.argsort(log_time, kind="stable")
        return (
            self.seen[topic],
            np.frombuffer(data, dtype=np.uint8),
            np.asarray(starts, dtype=np.int64)[order],
            np.asarray(sizes, dtype=np.int64)[order],
            log_time[order],
        )
