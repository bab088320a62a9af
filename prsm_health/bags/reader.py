"""Reading the estimator's inputs (MotorState or JointState) and the ground truth from a bag.

A bag is a rosbag2 directory with ``metadata.yaml`` or a bare ``.mcap`` file. Messages come in
log-time order (the order rosbags and mcap readers give), decoded in bulk with numpy
(:mod:`prsm_health.bags.codecs`); header stamps become float seconds as described in
:mod:`prsm_health.bags.stamps` (NaN/inf markers included).

Damaged bags (a file cut short, a corrupt chunk or payload): every sample that was complete
before the damage is delivered first, then :class:`BagDamagedError` is raised, naming the file
and the byte where the damage is. :func:`iter_motor_samples` yields the good chunks and then
raises; :func:`read_motor_samples` and :func:`read_truth` with ``partial_ok=True`` return
``(samples, error)`` instead of raising, so an offline replay can process what was read and
report the damage. Other problems (no such topic, a topic of another type, a directory without
metadata.yaml) raise :class:`BagError` before anything is delivered.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from contextlib import closing
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any, Literal, overload

import numpy as np
from numpy.typing import NDArray

from prsm_health.bags.bagfiles import bag_files
from prsm_health.bags.codecs import (
    Columns,
    PayloadError,
    decode_joint_states,
    decode_motor_states,
    decode_truth,
)
from prsm_health.bags.errors import BagDamagedError, BagError, TopicNotFoundError
from prsm_health.bags.mcap_scan import BagScanner, RawBatch
from prsm_health.bags.stamps import stamps_to_seconds
from prsm_health.bags.topics import MOTOR_FRAME, MOTOR_STATE_TOPIC, TRUTH_TOPIC
from prsm_health.bags.typestore import GROUND_TRUTH, JOINT_STATE, MOTOR_STATE, typestore
from prsm_health.signals import MotorSamples, TruthSamples

Decoder = Callable[[NDArray[np.uint8], NDArray[np.int64], NDArray[np.int64]], Columns]
DEFAULT_CHUNK_SIZE = 20_000


@dataclass(frozen=True, kw_only=True)
class InputTopics:
    """Where the motor measurements are in a bag.

    motor_state: topic of prsm_health_msgs/MotorState messages (used unless joint_states).
    joint_states: if set, read sensor_msgs/JointState from this topic instead: the joint
        ``joint_name``'s position [rad], velocity [rad/s] and effort.
    effort: what JointState effort carries: ``"current"`` (the motor current in A, this
        package's convention) or ``"torque"`` (motor torque in N m; then
        current = effort / torque_constant_nm_per_a, which must be given).
    """

    motor_state: str = MOTOR_STATE_TOPIC
    joint_states: str | None = None
    joint_name: str = MOTOR_FRAME
    effort: Literal["current", "torque"] = "current"
    torque_constant_nm_per_a: float | None = None

    def __post_init__(self) -> None:
        for name in ("motor_state", "joint_states"):
            topic = getattr(self, name)
            if topic is not None and (not isinstance(topic, str) or not topic.startswith("/")):
                raise ValueError(
                    f"InputTopics.{name}: a topic name starting with '/', not {topic!r}"
                )
        if not self.joint_name:
            raise ValueError("InputTopics.joint_name: must not be empty")
        if self.effort not in ("current", "torque"):
            raise ValueError(f"InputTopics.effort: 'current' or 'torque', not {self.effort!r}")
        k_t = self.torque_constant_nm_per_a
        if self.effort == "torque":
            if k_t is None or not math.isfinite(k_t) or k_t <= 0:
                raise ValueError(
                    "InputTopics.torque_constant_nm_per_a: a finite value > 0 [N m/A] is "
                    f"needed when effort is a torque, not {k_t!r}"
                )
        elif k_t is not None:
            raise ValueError("InputTopics.torque_constant_nm_per_a: only used with effort='torque'")

    @property
    def topic(self) -> str:
        """The topic that is read."""
        return self.joint_states if self.joint_states is not None else self.motor_state

    @property
    def msgtype(self) -> str:
        """The message type expected on :attr:`topic`."""
        return JOINT_STATE if self.joint_states is not None else MOTOR_STATE


class _TopicReader:
    """Decoded columns of one topic in log-time order; damage kept in :attr:`error`."""

    def __init__(self, path: str | Path, topic: str, msgtype: str, decode: Decoder) -> None:
        self.files = bag_files(path)
        self.topic, self.msgtype, self.decode = topic, msgtype, decode
        self.error: BagError | None = None
        self.shapes: dict[str, tuple[int, ...]] = {}

    def present(self, scanner: BagScanner) -> bool | None:
        """Whether the topic is declared (None: unknown, the file has no intact summary).

        Raises:
            BagError: it is declared with another type.
        """
        declared = self.files.topics
        if declared is None:
            declared = scanner.declared_topics()
        if declared is None:
            return None
        found = declared.get(self.topic)
        if found is not None and found != self.msgtype:
            raise BagError(
                self.files.path, f"topic {self.topic} is {found}, expected {self.msgtype}"
            )
        return found is not None

    def require(self, scanner: BagScanner) -> bool | None:
        """:meth:`present`, but an absent topic raises :meth:`absent`'s error."""
        present = self.present(scanner)
        if present is False:
            raise self.absent(self.files.topics or scanner.declared_topics() or {})
        return present

    def absent(self, topics: dict[str, str]) -> TopicNotFoundError:
        """The error for a topic that is not in the bag."""
        listed = ", ".join(f"{t} ({m})" for t, m in sorted(topics.items())) or "none"
        return TopicNotFoundError(
            self.files.path, f"no topic {self.topic} ({self.msgtype}); topics: {listed}"
        )

    def _decode_until_bad(self, batch: RawBatch) -> tuple[Columns, PayloadError | None]:
        """The batch decoded; if a payload is bad, the messages before the first bad one."""
        count, bad = len(batch.starts), None
        while True:
            try:
                return self.decode(batch.buffer, batch.starts[:count], batch.sizes[:count]), bad
            except PayloadError as exc:  # the error names a bad index, not always the first
                count, bad = exc.index, exc

    def _shape_change(self, columns: Columns) -> str | None:
        """What changed if a column's shape per message (e.g. the roller count) did."""
        for name, values in columns.items():
            first = self.shapes.setdefault(name, values.shape[1:])
            if values.shape[1:] != first:
                return f"{name} has shape {values.shape[1:]}, earlier messages {first}"
        return None

    def pieces(self) -> Iterator[tuple[NDArray[np.uint64], int | None, int, Columns]]:
        """Per segment: log times, the final-before bound, its place in the bag
        (:class:`RawBatch`) and the decoded columns."""
        with closing(BagScanner(self.files.files)) as scanner:
            present = self.require(scanner)
            for batch in scanner.batches(self.topic):
                if batch.msgtype != self.msgtype:
                    raise BagError(
                        self.files.path,
                        f"topic {self.topic} is {batch.msgtype}, expected {self.msgtype}",
                    )
                columns, bad = self._decode_until_bad(batch)
                if (changed := self._shape_change(columns)) is not None:
                    self.error = BagDamagedError(self.files.path, f"{self.topic}: {changed}")
                    return
                if bad is None:
                    yield batch.log_time_ns, batch.final_before_ns, batch.place, columns
                    continue
                if bad.index:
                    yield (
                        batch.log_time_ns[: bad.index],
                        batch.final_before_ns,
                        batch.place,
                        columns,
                    )
                self.error = BagDamagedError(
                    self.files.path,
                    f"{self.topic}: the message at log time {batch.log_time_ns[bad.index]} ns "
                    f"is not a valid {bad.msgtype}: {bad.detail}",
                )
                return
            self.error = scanner.damage
            if present is None and self.topic not in scanner.seen:
                if self.error is None:
                    raise self.absent(scanner.seen)
                self.error = BagDamagedError(
                    self.error.path, f"{self.error.reason}; topic {self.topic} not seen before it"
                )


def _take(columns: Columns, index: Any) -> Columns:
    return {name: values[index] for name, values in columns.items()}


def _join(parts: list[Columns]) -> Columns:
    if len(parts) == 1:
        return parts[0]
    return {name: np.concatenate([p[name] for p in parts]) for name in parts[0]}


def _in_time_order(
    pieces: Iterator[tuple[NDArray[np.uint64], int | None, int, Columns]],
) -> Iterator[Columns]:
    """Merge per-segment pieces into log-time order, holding back what a later one may precede;
    equal log times in the order written (the segments' places, then within a segment)."""
    held_times: NDArray[np.uint64] | None = None
    held_places: NDArray[np.int64] = np.zeros(0, dtype=np.int64)
    held: Columns = {}
    for times, final_before, place, columns in pieces:
        places = np.full(len(times), place, dtype=np.int64)
        if held_times is not None:
            times = np.concatenate([held_times, times])
            places = np.concatenate([held_places, places])
            columns = _join([held, columns])
            order = np.lexsort((places, times))  # stable: a segment's ties keep their order
            times, places, columns = times[order], places[order], _take(columns, order)
        cut = len(times)
        if final_before is not None:
            cut = int(np.searchsorted(times, np.uint64(final_before), side="left"))
        if cut:
            yield _take(columns, slice(0, cut))
        held_times, held = None, {}
        if cut < len(times):
            held_times, held_places = times[cut:], places[cut:]
            held = _take(columns, slice(cut, None))
    if held_times is not None:
        yield held


def _sized(pieces: Iterator[Columns], size: int) -> Iterator[Columns]:
    """Re-cut into pieces of exactly ``size`` samples (the last one may be shorter)."""
    parts: list[Columns] = []
    count = 0
    for piece in pieces:
        parts.append(piece)
        count += len(piece["sec"])
        while count >= size:
            joined = _join(parts)
            yield _take(joined, slice(0, size))
            count -= size
            parts = [_take(joined, slice(size, None))] if count else []
    if count:
        yield _join(parts)


def _motor_samples(columns: Columns, topics: InputTopics) -> MotorSamples:
    if not columns:
        empty = np.empty(0)
        return MotorSamples(empty, empty, empty, empty)
    stamp_s = stamps_to_seconds(columns["sec"], columns["nanosec"])
    if topics.joint_states is None:
        return MotorSamples(
            stamp_s, columns["current_a"], columns["speed_rad_s"], columns["position_rad"]
        )
    current = columns["effort"]
    if topics.torque_constant_nm_per_a is not None:
        current = current / topics.torque_constant_nm_per_a
    return MotorSamples(stamp_s, current, columns["velocity"], columns["position"])


def iter_motor_samples(
    path: str | Path,
    topics: InputTopics = InputTopics(),
    *,
    chunk_size: int = DEFAULT_CHUNK_SIZE,
) -> Iterator[MotorSamples]:
    """The motor samples of a bag, in consecutive chunks of ``chunk_size`` in log-time order.

    Every chunk but the last has exactly ``chunk_size`` samples. A JointState message that does
    not name the joint gives a sample of NaN values, one whose arrays are too short gives NaN for
    the missing values (never dropped: the estimator rejects and counts them).

    Raises:
        BagError: before the first chunk, if the topic is absent or of another type, or the
            bag is not a readable MCAP bag.
        BagDamagedError: after the last chunk that could be read, if the bag is damaged.
    """
    if chunk_size < 1:
        raise ValueError(f"chunk_size: at least 1, not {chunk_size}")
    decode: Decoder = decode_motor_states
    if topics.joint_states is not None:
        decode = partial(decode_joint_states, joint=topics.joint_name)
    reader = _TopicReader(path, topics.topic, topics.msgtype, decode)
    for columns in _sized(_in_time_order(reader.pieces()), chunk_size):
        yield _motor_samples(columns, topics)
    if reader.error is not None:
        raise reader.error


def joint_names(path: str | Path, topic: str) -> list[str]:
    """The joint names of the first JointState message on ``topic`` (diagnostics of a
    ``--joint-name`` that matches nothing); empty if the topic has no readable message.

    Raises:
        BagError: the topic is absent or of another type, or the bag is not readable.
    """
    # Its columns are not decoded: the reader serves for its checks of the topic only.
    reader = _TopicReader(path, topic, JOINT_STATE, partial(decode_joint_states, joint=""))
    with closing(BagScanner(reader.files.files)) as scanner:
        reader.require(scanner)
        for batch in scanner.batches(topic):
            if len(batch.starts):
                start, size = int(batch.starts[0]), int(batch.sizes[0])
                payload = batch.buffer[start : start + size].tobytes()
                try:
                    message: Any = typestore().deserialize_cdr(payload, JOINT_STATE)
                except Exception:  # rosbags raises assorted errors on malformed data
                    return []
                return [str(name) for name in message.name]
    return []


@overload
def read_motor_samples(
    path: str | Path, topics: InputTopics = ..., *, partial_ok: Literal[False] = False
) -> MotorSamples: ...


@overload
def read_motor_samples(
    path: str | Path, topics: InputTopics = ..., *, partial_ok: Literal[True]
) -> tuple[MotorSamples, BagDamagedError | None]: ...


def read_motor_samples(
    path: str | Path,
    topics: InputTopics = InputTopics(),
    *,
    partial_ok: bool = False,
) -> MotorSamples | tuple[MotorSamples, BagDamagedError | None]:
    """All motor samples of a bag (see :func:`iter_motor_samples`).

    With ``partial_ok=True``, returns ``(samples, error)``: the samples read before any damage,
    and the :class:`BagDamagedError` (None for an intact bag) instead of raising it.

    Raises:
        BagError: the topic is absent or of another type, or the bag is not readable.
        BagDamagedError: the bag is damaged (only without ``partial_ok``).
    """
    parts: list[MotorSamples] = []
    error: BagDamagedError | None = None
    try:
        parts.extend(iter_motor_samples(path, topics, chunk_size=2**62))
    except BagDamagedError as exc:
        if not partial_ok:
            raise
        error = exc
    samples = parts[0] if len(parts) == 1 else _motor_samples({}, topics)
    return (samples, error) if partial_ok else samples


def _truth_samples(columns: Columns) -> TruthSamples:
    if not columns:
        empty = np.empty(0)
        return TruthSamples(
            empty,
            empty,
            empty,
            np.empty(0, dtype=np.int64),
            np.empty((0, 0), dtype=np.bool_),
            empty,
            empty,
            empty,
            empty,
            empty,
            empty,
        )
    return TruthSamples(
        stamp_s=stamps_to_seconds(columns["sec"], columns["nanosec"]),
        axial_load_n=columns["axial_load_n"],
        radial_load_n=columns["radial_load_n"],
        loading_case=columns["loading_case"].astype(np.int64),
        roller_jammed=columns["roller_jammed"],
        precision_loss_m=columns["precision_loss_um"] / 1e6,
        friction_torque_nm=columns["friction_torque_nm"],
        fatigue_damage=columns["fatigue_damage"],
        screw_speed_rad_s=columns["screw_speed_rad_s"],
        carrier_angle_rad=columns["carrier_angle_rad"],
        wear_coefficient_factor=columns["wear_coefficient_factor"],
    )


@overload
def read_truth(
    path: str | Path, topic: str = ..., *, partial_ok: Literal[False] = False
) -> TruthSamples | None: ...


@overload
def read_truth(
    path: str | Path, topic: str = ..., *, partial_ok: Literal[True]
) -> tuple[TruthSamples | None, BagDamagedError | None]: ...


def read_truth(
    path: str | Path, topic: str = TRUTH_TOPIC, *, partial_ok: bool = False
) -> TruthSamples | tuple[TruthSamples | None, BagDamagedError | None] | None:
    """The ground truth of a simulated run (GroundTruth on ``topic``); None if the bag has none.

    ``precision_loss_m = precision_loss_um / 1e6``; the jammed count is recomputed from
    ``roller_jammed``. ``partial_ok`` as in :func:`read_motor_samples`.

    Raises:
        BagError: the topic has another type, or the bag is unreadable.
        BagDamagedError: the bag is damaged or the roller count changes (only without
            ``partial_ok``).
    """
    reader = _TopicReader(path, topic, GROUND_TRUTH, decode_truth)
    try:
        parts = list(_in_time_order(reader.pieces()))
    except TopicNotFoundError:
        return (None, None) if partial_ok else None
    truth = _truth_samples(_join(parts) if parts else {})
    error = reader.error
    if error is not None and (not partial_ok or not isinstance(error, BagDamagedError)):
        raise error
    return (truth, error) if partial_ok else truth
