"""Writing rosbag2 bags (MCAP storage, format version 9) with rosbags, fast and reproducibly.

:class:`BagWriter` wraps :class:`rosbags.rosbag2.Writer`. The MCAP chunks are compressed with
zstd (rosbags' ``CompressionMode.STORAGE``): 25-40 bytes per MotorState instead of 99, and
still a plain ``.mcap`` with standard chunk compression, read directly by rosbags and by the
``mcap``/``mcap_ros2`` readers (tested). (rosbags' ``FILE`` mode gives a ``.mcap.zstd`` that no
MCAP reader opens; ``MESSAGE`` mode compresses each 52-byte payload on its own, gains nothing
and leaves payloads that ``mcap_ros2`` cannot decode. Measurements: docs/bags.md.)

Reproducible: the same inputs give byte-identical ``metadata.yaml`` and ``.mcap`` (rosbags
writes no wall-clock time and no random ids; the one version-dependent byte string, the MCAP
header's ``library`` field ``rosbags-<version>``, is replaced by the fixed :data:`LIBRARY`).
The ``.mcap`` inside is named after the bag directory, so compare bags of equal names. The
zstd output depends on the zstd library version (pinned in requirements.txt).

The ``write_*`` functions turn whole series into messages with numpy
(:mod:`prsm_health.bags.codecs`) and take header stamps from float seconds and log times as
described in :mod:`prsm_health.bags.stamps`.
"""

from __future__ import annotations

import os
import shutil
import struct
import zlib
from collections.abc import Mapping, Sequence
from io import BytesIO
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from rosbags.interfaces import Connection
from rosbags.rosbag2 import StoragePlugin, Writer, WriterError
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
from rosbags.rosbag2.storage_mcap import McapWriter, write_record, write_string

from prsm_health.bags.codecs import encode_joint_states, encode_motor_states, encode_truth
from prsm_health.bags.errors import BagError
from prsm_health.bags.mcap_scan import MAGIC
from prsm_health.bags.stamps import (
    StampRangeError,
    UInt64Array,
    log_times_from_stamps,
    seconds_to_stamps,
)
from prsm_health.bags.topics import JOINT_STATES_TOPIC, MOTOR_FRAME, MOTOR_STATE_TOPIC, TRUTH_TOPIC
from prsm_health.bags.typestore import GROUND_TRUTH, JOINT_STATE, MOTOR_STATE, typestore
from prsm_health.signals import MotorSamples, TruthSamples

#: ``library`` field of the MCAP header (instead of rosbags' ``rosbags-<version>``).
LIBRARY = "prsm_health.bags (rosbags MCAP writer)"
#: Where a Chunk record's uncompressed CRC sits: after its opcode and length (9 bytes) and its
#: message start time, end time and uncompressed size (8 bytes each).
CHUNK_CRC_OFFSET = 9 + 3 * 8
MAX_LOG_TIME_NS = 2**63 - 2


class _McapStorage(McapWriter):
    """rosbags' MCAP storage, with :data:`LIBRARY` in the header so bags do not depend on it,
    and each chunk's CRC-32 of its uncompressed records (rosbags writes 0, "none"): without
    it a flipped bit that zstd still decodes fed garbage samples to the estimator
    (docs/bags.md, "Damage")."""

    def __init__(self, path: Path, compression: CompressionMode) -> None:
        super().__init__(path, compression)
        # rosbags has written only the magic and the Header record to the file so far (records
        # go to an in-memory chunk until it is full): write them again with our library name.
        self.bio.seek(0)
        self.bio.truncate()
        self.bio.write(MAGIC)
        record = BytesIO()
        write_string(record, "ros2")
        write_string(record, LIBRARY)
        write_record(self.bio, 0x01, record)

    def close_chunk(self) -> None:
        """rosbags' chunk record, with the CRC filled in where rosbags wrote 0."""
        crc = zlib.crc32(self.chunk.bio.getbuffer())
        start = self.bio.tell()
        super().close_chunk()
        end = self.bio.tell()
        self.bio.seek(start + CHUNK_CRC_OFFSET)
        self.bio.write(struct.pack("<I", crc))
        self.bio.seek(end)


class _Writer(Writer):
    STORAGE_PLUGINS = {StoragePlugin.MCAP: _McapStorage}  # noqa: RUF012 - as in rosbags


def working_directory(path: Path) -> Path:
    """Where :class:`BagWriter` writes the bare MCAP file ``path`` as a bag first."""
    return path.parent / f".{path.name}.writing"


class BagWriter:
    """A rosbag2 bag being written: MCAP, version 9, zstd-compressed chunks (module docstring).

    Use as a context manager: entering creates the directory ``path`` (it must not exist;
    BagError otherwise),
    leaving writes the MCAP summary and ``metadata.yaml``. After an exception the bag is
    left without them (incomplete, as a crashed recorder leaves it).

    Args:
        path: bag directory to create; the MCAP file inside is ``<name>/<name>.mcap``. A
            path ending in ``.mcap`` is a bare MCAP file instead (what Foxglove opens; the
            readers here take it too): the same bytes as the ``.mcap`` of a bag directory
            ``<stem>``, written as one in the hidden directory ``.<name>.writing`` beside it,
            whose MCAP is linked to ``path`` when the writer is left (incomplete after an
            exception) and the rest removed (``metadata.yaml``: the MCAP carries it too).
        compress: zstd-compress the MCAP chunks (default); False writes them uncompressed.
    """

    def __init__(self, path: str | Path, *, compress: bool = True) -> None:
        self.path = Path(path)
        directory = self.path
        self._working: Path | None = None  # where a bare .mcap file is written as a bag
        if self.path.suffix == ".mcap":
            self._working = working_directory(self.path)
            try:
                taken = self.path.exists() or self.path.is_symlink()
                left = self._working.exists()
            except OSError as exc:  # e.g. a name too long for the working directory's
                raise BagError(self.path, f"cannot create the bag: {exc}") from exc
            if taken:
                raise BagError(self.path, "exists already, not overwriting")
            if left:
                raise BagError(
                    self.path,
                    f"{self._working} is left from a write that was killed (or another is "
                    "writing this file): remove it first",
                )
            directory = self._working / self.path.stem
        try:
            self._writer = _Writer(directory, version=9, storage_plugin=StoragePlugin.MCAP)
        except WriterError as exc:
            raise BagError(self.path, f"cannot create the bag: {exc}") from exc
        if compress:
            self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        self._connections: dict[str, Connection] = {}
        self._latest_log_ns: dict[str, int] = {}  # per topic, the latest log time written
        self._open = False

    def __enter__(self) -> BagWriter:
        try:
            if self._working is not None:
                # Made here, never reused: a second writer of the same file fails now.
                self._working.mkdir(parents=True)
        except OSError as exc:
            raise BagError(self.path, f"cannot create the bag: {exc}") from exc
        try:
            self._writer.open()
        except (WriterError, OSError) as exc:
            if self._working is not None:
                shutil.rmtree(self._working, ignore_errors=True)
            raise BagError(self.path, f"cannot create the bag: {exc}") from exc
        self._open = True
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._open = False
        if exc_type is not None:
            self._writer.abort()
            self._bare_file(failing=True)
            return
        try:
            self._writer.close()
        except BaseException:
            self._writer.abort()
            self._bare_file(failing=True)
            raise
        self._bare_file(failing=False)

    def _bare_file(self, *, failing: bool) -> None:
        """For a bare ``.mcap`` path: its MCAP linked there and the working directory removed.

        A hard link never replaces what appeared at the path while the bag was written; then
        (or on a file system without hard links) the bag stays in the working directory,
        named in a BagError, or, ``failing`` (an exception is on its way), silently.
        """
        if self._working is None:
            return
        written = self._working / self.path.stem / f"{self.path.stem}.mcap"
        if written.exists():
            try:
                os.link(written, self.path)
            except OSError as exc:
                if failing:
                    return
                raise BagError(
                    self.path, f"not written there ({exc.strerror}): the bag is {written}"
                ) from exc
        shutil.rmtree(self._working, ignore_errors=True)

    @property
    def topics(self) -> dict[str, str]:
        """Topics added so far: name -> message type."""
        return {topic: c.msgtype for topic, c in self._connections.items()}

    def set_custom_data(self, key: str, value: str) -> None:
        """Store ``key: value`` in the bag's rosbag2 ``custom_data`` (``metadata.yaml`` and the
        MCAP's ``rosbag2`` metadata record, written when the bag is closed)."""
        self._writer.set_custom_data(key, value)

    def add_topic(self, topic: str, msgtype: str) -> None:
        """Declare ``topic`` with message type ``msgtype`` (again with the same type: no-op).

        Raises:
            BagError: the bag is not open, the topic exists with another type, or the type is
                not in :func:`prsm_health.bags.typestore.typestore`.
        """
        if not self._open:
            raise BagError(self.path, f"add_topic({topic!r}) outside the `with BagWriter` block")
        if (known := self._connections.get(topic)) is not None:
            if known.msgtype != msgtype:
                raise BagError(self.path, f"topic {topic} is {known.msgtype}, not {msgtype}")
            return
        store = typestore()
        if msgtype not in store.types:
            raise BagError(self.path, f"unknown message type {msgtype} for topic {topic}")
        self._connections[topic] = self._writer.add_connection(topic, msgtype, typestore=store)

    def _connection(self, topic: str) -> Connection:
        if not self._open:
            raise BagError(self.path, f"writing to {topic} outside the `with BagWriter` block")
        try:
            return self._connections[topic]
        except KeyError:
            raise BagError(self.path, f"topic {topic} was not added (add_topic)") from None

    def write(self, topic: str, timestamp_ns: int, message: object) -> None:
        """Serialise ``message`` (a rosbags message of the topic's type) and write it.

        Raises:
            BagError: unknown topic, wrong message type, or a log time outside [0, 2**63 - 1).
        """
        connection = self._connection(topic)
        msgtype = getattr(message, "__msgtype__", type(message).__name__)
        if msgtype != connection.msgtype:
            raise BagError(self.path, f"topic {topic} is {connection.msgtype}, got a {msgtype}")
        self.write_cdr(topic, timestamp_ns, typestore().serialize_cdr(message, msgtype))

    def write_cdr(self, topic: str, timestamp_ns: int, data: bytes | memoryview) -> None:
        """Write one already serialised CDR payload at log time ``timestamp_ns``.

        Raises:
            BagError: unknown topic or a log time outside [0, 2**63 - 1).
        """
        self.write_cdr_many(topic, np.asarray([timestamp_ns]), [data])

    def write_cdr_many(
        self,
        topic: str,
        timestamps_ns: ArrayLike,
        payloads: Sequence[bytes | memoryview],
    ) -> None:
        """Write many CDR payloads, ``payloads[i]`` at log time ``timestamps_ns[i]``.

        Raises:
            BagError: unknown topic, lengths differ, or a log time outside [0, 2**63 - 1).
        """
        connection = self._connection(topic)
        times = np.asarray(timestamps_ns)
        if times.shape != (len(payloads),):
            raise BagError(
                self.path, f"{topic}: {times.shape} log times for {len(payloads)} payloads"
            )
        if times.dtype.kind not in "iu" or (
            len(times) and (times.min() < 0 or times.max() > MAX_LOG_TIME_NS)
        ):
            raise BagError(self.path, f"{topic}: log times must be integers in [0, 2**63 - 1) ns")
        write = self._writer.write
        for timestamp, data in zip(times.tolist(), payloads, strict=True):
            write(connection, timestamp, data)
        if len(times):
            self._latest_log_ns[topic] = max(self._latest_log_ns.get(topic, 0), int(times.max()))

    def log_times_after(self, topic: str, times_ns: ArrayLike) -> UInt64Array:
        """``times_ns`` (non-decreasing), none before the latest log time written on ``topic``
        so far: log times that never go back over the bag, as a recorder's receive times, for
        a topic written in pieces (each piece's stamps made non-decreasing on their own put a
        piece after a clock jump back among the pieces before, in any reader's log-time
        order)."""
        times = np.atleast_1d(np.asarray(times_ns, dtype=np.uint64))
        return np.maximum(times, np.uint64(self._latest_log_ns.get(topic, 0)))


def _stamp_columns(writer: BagWriter, topic: str, stamp_s: NDArray[np.float64]) -> dict[str, Any]:
    try:
        sec, nanosec = seconds_to_stamps(stamp_s)
    except StampRangeError as exc:
        raise BagError(writer.path, f"{topic}: {exc}") from exc
    return {"sec": sec, "nanosec": nanosec}


def _sample_columns(
    writer: BagWriter, topic: str, samples: MotorSamples, names: tuple[str, str, str]
) -> dict[str, Any]:
    """Stamp columns plus current, speed and position under the message's field ``names``."""
    values = (samples.current_a, samples.speed_rad_s, samples.position_rad)
    return _stamp_columns(writer, topic, samples.stamp_s) | dict(zip(names, values, strict=True))


def _log_times(
    writer: BagWriter, topic: str, stamp_s: NDArray[np.float64], receive_time_ns: ArrayLike | None
) -> UInt64Array | NDArray[Any]:
    if receive_time_ns is None:
        return writer.log_times_after(topic, log_times_from_stamps(stamp_s))
    times = np.asarray(receive_time_ns)
    if times.shape != stamp_s.shape:
        raise BagError(
            writer.path, f"{topic}: receive_time_ns has shape {times.shape}, {stamp_s.shape} needed"
        )
    return times


def _write_series(
    writer: BagWriter,
    topic: str,
    msgtype: str,
    log_times: ArrayLike,
    payloads: Sequence[memoryview],
) -> None:
    writer.add_topic(topic, msgtype)
    writer.write_cdr_many(topic, log_times, payloads)


def write_motor_states(
    writer: BagWriter,
    samples: MotorSamples,
    *,
    topic: str = MOTOR_STATE_TOPIC,
    frame_id: str = MOTOR_FRAME,
    receive_time_ns: ArrayLike | None = None,
) -> None:
    """Write ``samples`` as MotorState messages on ``topic`` (added if needed).

    header.stamp comes from ``stamp_s``, rounded to the nanosecond; NaN and +-inf stamps are
    written as markers that read back as NaN and +-inf (:mod:`prsm_health.bags.stamps`). The
    log time is ``receive_time_ns`` [ns since the epoch] when given, else the stamp made
    non-decreasing (a backwards, non-finite or negative stamp takes the previous log time), so
    readers return the samples in the order written.

    Raises:
        BagError: a finite stamp beyond +-2**31 s, bad receive times, or a bag error.
    """
    columns = _sample_columns(writer, topic, samples, ("current_a", "speed_rad_s", "position_rad"))
    payloads = encode_motor_states(columns, frame_id=frame_id)
    log_times = _log_times(writer, topic, samples.stamp_s, receive_time_ns)
    _write_series(writer, topic, MOTOR_STATE, log_times, payloads)


def write_joint_states(
    writer: BagWriter,
    samples: MotorSamples,
    *,
    topic: str = JOINT_STATES_TOPIC,
    joint_name: str = MOTOR_FRAME,
) -> None:
    """Write ``samples`` as sensor_msgs/JointState messages of the single joint ``joint_name``.

    ``name = [joint_name]``, ``position = [position_rad]``, ``velocity = [speed_rad_s]`` and
    ``effort = [current_a]``: by this package's convention the effort of the motor joint
    carries the motor current in A (read it back with ``InputTopics(effort="current")``).
    Stamps and log times as in :func:`write_motor_states`; header.frame_id is empty.
    """
    columns = _sample_columns(writer, topic, samples, ("effort", "velocity", "position"))
    payloads = encode_joint_states(columns, joint=joint_name)
    log_times = _log_times(writer, topic, samples.stamp_s, None)
    _write_series(writer, topic, JOINT_STATE, log_times, payloads)


def _truth_columns(writer: BagWriter, topic: str, truth: TruthSamples) -> Mapping[str, Any]:
    jammed = np.asarray(truth.roller_jammed, dtype=np.bool_)
    if jammed.ndim != 2 or len(jammed) != len(truth):
        raise BagError(writer.path, f"{topic}: roller_jammed must be (samples, rollers)")
    case = np.asarray(truth.loading_case)
    if len(case) and (case.min() < 0 or case.max() > 255 or jammed.shape[1] > 255):
        raise BagError(writer.path, f"{topic}: loading_case and roller count must fit a uint8")
    columns = _stamp_columns(writer, topic, truth.stamp_s)
    return columns | {
        "axial_load_n": truth.axial_load_n,
        "radial_load_n": truth.radial_load_n,
        "loading_case": case.astype(np.uint8),
        "jammed_rollers": jammed.sum(axis=1).astype(np.uint8),
        "roller_jammed": jammed.astype(np.uint8),
        "precision_loss_um": np.asarray(truth.precision_loss_m) * 1e6,
        "friction_torque_nm": truth.friction_torque_nm,
        "fatigue_damage": truth.fatigue_damage,
        "screw_speed_rad_s": truth.screw_speed_rad_s,
        "carrier_angle_rad": truth.carrier_angle_rad,
        "wear_coefficient_factor": truth.wear_coefficient_factor,
    }


def write_truth(writer: BagWriter, truth: TruthSamples, *, topic: str = TRUTH_TOPIC) -> None:
    """Write ``truth`` as GroundTruth messages (``precision_loss_um = precision_loss_m * 1e6``).

    ``jammed_rollers`` is the count of ``roller_jammed``. Stamps and log times as in
    :func:`write_motor_states`; header.frame_id is empty.

    Raises:
        BagError: roller_jammed not 2-D, loading_case or roller count beyond a uint8, stamps.
    """
    payloads = encode_truth(_truth_columns(writer, topic, truth))
    log_times = _log_times(writer, topic, truth.stamp_s, None)
    _write_series(writer, topic, GROUND_TRUTH, log_times, payloads)
