"""Whole series of MotorState, JointState and GroundTruth messages <-> CDR payloads.

Encoding fills a payload serialised once by rosbags (so constant bytes, padding included, are
rosbags' own) with the numbers of every sample; decoding reads every payload of a common layout
with numpy views and leaves the rest (big-endian CDR, unusual layouts) to rosbags'
``deserialize_cdr``, message by message. Columns are plain arrays keyed by field name; header
stamps stay ``sec``/``nanosec`` (see :mod:`prsm_health.bags.stamps`).

JointState convention: the samples of one joint; ``position`` is the motor position [rad],
``velocity`` the motor speed [rad/s] and ``effort`` the motor current [A] (or a torque, see
:class:`prsm_health.bags.reader.InputTopics`). A value whose array is too short for the joint's
index, or every value when the joint is not named or named more than once (which entry is the
motor cannot be told), decodes as NaN.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from prsm_health.bags.cdr import (
    Cursor,
    Field,
    Int64Array,
    Layout,
    LayoutError,
    UInt8Array,
    column,
    fill_rows,
    group_layouts,
    split_rows,
)
from prsm_health.bags.typestore import GROUND_TRUTH, JOINT_STATE, MOTOR_STATE, typestore

Columns = dict[str, NDArray[Any]]
_Name = TypeVar("_Name", str, bytes)

MOTOR_FIELDS = ("current_a", "speed_rad_s", "position_rad")
JOINT_FIELDS = ("position", "velocity", "effort")
TRUTH_FLOATS = ("axial_load_n", "radial_load_n")
TRUTH_FLOATS_AFTER = (
    "precision_loss_um",
    "friction_torque_nm",
    "fatigue_damage",
    "screw_speed_rad_s",
    "carrier_angle_rad",
    "wear_coefficient_factor",
)


class PayloadError(ValueError):
    """Message ``index`` of a batch is not a valid payload of its type (text says why)."""

    def __init__(self, index: int, msgtype: str, detail: str) -> None:
        super().__init__(f"message {index} is not a valid {msgtype}: {detail}")
        self.index = index
        self.msgtype = msgtype
        self.detail = detail


def _stamp(cursor: Cursor) -> None:
    cursor.field("sec", "<i4")
    cursor.field("nanosec", "<u4")
    cursor.string()


def motor_state_layout(payload: bytes | memoryview) -> Layout:
    """Layout of a MotorState payload (header, current, speed, position)."""
    cursor = Cursor(payload)
    _stamp(cursor)
    for name in MOTOR_FIELDS:
        cursor.field(name, "<f8")
    return cursor.finish()


def truth_layout(payload: bytes | memoryview) -> Layout:
    """Layout of a GroundTruth payload (its roller count is part of the structure)."""
    cursor = Cursor(payload)
    _stamp(cursor)
    for name in TRUTH_FLOATS:
        cursor.field(name, "<f8")
    cursor.field("loading_case", "u1")
    cursor.field("jammed_rollers", "u1")
    cursor.field("roller_jammed", "u1", cursor.length())
    for name in TRUTH_FLOATS_AFTER:
        cursor.field(name, "<f8")
    return cursor.finish()


def _single_index(names: list[_Name], joint: _Name) -> int | None:
    """The index of ``joint`` in ``names`` if it is named exactly once, else None."""
    return names.index(joint) if names.count(joint) == 1 else None


def joint_state_layout(payload: bytes | memoryview, joint: str) -> Layout:
    """Layout of a JointState payload with fields for ``joint`` only where its value exists."""
    cursor = Cursor(payload)
    _stamp(cursor)
    names = [cursor.string(structural=True) for _ in range(cursor.length())]
    index = _single_index(names, joint.encode())
    for name in JOINT_FIELDS:
        count = cursor.length()
        if index is None or index >= count:
            cursor.skip("<f8", count)
            continue
        cursor.skip("<f8", index)
        cursor.field(name, "<f8")
        cursor.skip("<f8", count - index - 1)
    return cursor.finish()


@dataclass(frozen=True)
class _Codec:
    """How one message type maps to columns: fast (layout) and per-message (rosbags) paths."""

    msgtype: str
    layout_of: Callable[[bytes], Layout]
    from_rows: Callable[[UInt8Array, Layout], Columns]
    from_message: Callable[[Any], Columns]


def _decode(codec: _Codec, buffer: UInt8Array, starts: Int64Array, sizes: Int64Array) -> Columns:
    count = len(starts)
    out: Columns = {}
    store = typestore()
    for indices, layout, rows in group_layouts(buffer, starts, sizes, codec.layout_of):
        if layout is not None:
            parts = codec.from_rows(rows, layout)
        else:
            parts = _per_message(codec, store, indices, rows)
        for name, values in parts.items():
            if name not in out:
                out[name] = np.empty((count, *values.shape[1:]), dtype=values.dtype)
            elif out[name].shape[1:] != values.shape[1:]:
                raise PayloadError(
                    int(indices[0]),
                    codec.msgtype,
                    f"{name} has shape {values.shape[1:]}, earlier messages {out[name].shape[1:]}",
                )
            out[name][indices] = values
    return out


def _per_message(codec: _Codec, store: Any, indices: Int64Array, rows: UInt8Array) -> Columns:
    parts: list[Columns] = []
    for index, row in zip(indices, rows, strict=True):
        try:
            message = store.deserialize_cdr(row.tobytes(), codec.msgtype)
        except Exception as exc:  # rosbags raises assorted errors on malformed data
            raise PayloadError(int(index), codec.msgtype, str(exc) or type(exc).__name__) from exc
        parts.append(codec.from_message(message))
    try:
        return {name: np.stack([p[name] for p in parts]) for name in parts[0]}
    except ValueError as exc:  # e.g. GroundTruth messages with different roller counts
        raise PayloadError(int(indices[0]), codec.msgtype, str(exc)) from exc


def _header_columns(message: Any) -> Columns:
    stamp = message.header.stamp
    return {
        "sec": np.asarray(stamp.sec, dtype=np.int32),
        "nanosec": np.asarray(stamp.nanosec, dtype=np.uint32),
    }


def _named(rows: UInt8Array, layout: Layout, names: tuple[str, ...]) -> Columns:
    found = {"sec": column(rows, _required(layout, "sec"))}
    found["nanosec"] = column(rows, _required(layout, "nanosec"))
    for name in names:
        field = layout.field(name)
        found[name] = column(rows, field) if field else np.full(len(rows), np.nan)
    return found


def _required(layout: Layout, name: str) -> Field:
    field = layout.field(name)
    if field is None:  # pragma: no cover - the layout functions always record it
        raise LayoutError(f"layout has no field {name}")
    return field


_MOTOR = _Codec(
    MOTOR_STATE,
    motor_state_layout,
    lambda rows, layout: _named(rows, layout, MOTOR_FIELDS),
    lambda m: _header_columns(m) | {n: np.asarray(getattr(m, n), float) for n in MOTOR_FIELDS},
)


def _truth_rows(rows: UInt8Array, layout: Layout) -> Columns:
    found = _named(rows, layout, TRUTH_FLOATS + TRUTH_FLOATS_AFTER)
    for name in ("loading_case", "jammed_rollers"):
        found[name] = column(rows, _required(layout, name))
    jammed = column(rows, _required(layout, "roller_jammed")).reshape(len(rows), -1)
    found["roller_jammed"] = jammed != 0
    return found


def _truth_message(message: Any) -> Columns:
    found = _header_columns(message)
    for name in TRUTH_FLOATS + TRUTH_FLOATS_AFTER:
        found[name] = np.asarray(getattr(message, name), dtype=np.float64)
    for name in ("loading_case", "jammed_rollers"):
        found[name] = np.asarray(getattr(message, name), dtype=np.uint8)
    found["roller_jammed"] = np.asarray(message.roller_jammed, dtype=np.bool_).reshape(-1)
    return found


_TRUTH = _Codec(GROUND_TRUTH, truth_layout, _truth_rows, _truth_message)


def _joint_codec(joint: str) -> _Codec:
    def from_message(message: Any) -> Columns:
        found = _header_columns(message)
        names = list(message.name)
        index = _single_index(names, joint)
        for name in JOINT_FIELDS:
            values = getattr(message, name)
            ok = index is not None and index < len(values)
            found[name] = np.asarray(values[index] if ok else np.nan, dtype=np.float64)
        return found

    return _Codec(
        JOINT_STATE,
        lambda payload: joint_state_layout(payload, joint),
        lambda rows, layout: _named(rows, layout, JOINT_FIELDS),
        from_message,
    )


def decode_motor_states(buffer: UInt8Array, starts: Int64Array, sizes: Int64Array) -> Columns:
    """Columns ``sec, nanosec, current_a, speed_rad_s, position_rad`` of MotorState payloads.

    ``starts``/``sizes`` locate the payloads (CDR header included) in ``buffer``.

    Raises:
        PayloadError: a payload is not a MotorState (its index is in the error).
    """
    return _decode(_MOTOR, buffer, starts, sizes)


def decode_joint_states(
    buffer: UInt8Array, starts: Int64Array, sizes: Int64Array, *, joint: str
) -> Columns:
    """Columns ``sec, nanosec, position, velocity, effort`` of ``joint`` in JointState payloads.

    A missing or repeated joint or a too short array gives NaN (module docstring).

    Raises:
        PayloadError: a payload is not a JointState (its index is in the error).
    """
    return _decode(_joint_codec(joint), buffer, starts, sizes)


def decode_truth(buffer: UInt8Array, starts: Int64Array, sizes: Int64Array) -> Columns:
    """Columns of GroundTruth payloads (field names of the message, ``roller_jammed`` bool 2-D).

    Raises:
        PayloadError: a payload is not a GroundTruth, or the roller count changes.
    """
    return _decode(_TRUTH, buffer, starts, sizes)


def _encode(
    message: Any,
    msgtype: str,
    layout_of: Callable[[bytes], Layout],
    values: Mapping[str, NDArray[Any]],
    count: int,
) -> list[memoryview]:
    template = bytes(typestore().serialize_cdr(message, msgtype))
    return split_rows(fill_rows(template, layout_of(template), values, count))


def _header(frame_id: str) -> Any:
    types = typestore().types
    return types["std_msgs/msg/Header"](types["builtin_interfaces/msg/Time"](0, 0), frame_id)


def encode_motor_states(values: Mapping[str, NDArray[Any]], *, frame_id: str) -> list[memoryview]:
    """MotorState payloads from columns ``sec, nanosec, current_a, speed_rad_s, position_rad``."""
    message = typestore().types[MOTOR_STATE](_header(frame_id), 0.0, 0.0, 0.0)
    return _encode(message, MOTOR_STATE, motor_state_layout, values, len(values["sec"]))


def encode_joint_states(values: Mapping[str, NDArray[Any]], *, joint: str) -> list[memoryview]:
    """One-joint JointState payloads from columns ``sec, nanosec, position, velocity, effort``."""
    one = np.zeros(1)
    message = typestore().types[JOINT_STATE](_header(""), [joint], one, one, one)
    return _encode(
        message,
        JOINT_STATE,
        lambda payload: joint_state_layout(payload, joint),
        values,
        len(values["sec"]),
    )


def encode_truth(values: Mapping[str, NDArray[Any]]) -> list[memoryview]:
    """GroundTruth payloads from columns named as :func:`decode_truth` returns them (an
    empty header.frame_id)."""
    rollers = values["roller_jammed"].shape[1]
    message = typestore().types[GROUND_TRUTH](
        _header(""), 0.0, 0.0, 0, 0, np.zeros(rollers, dtype=np.bool_), *([0.0] * 6)
    )
    return _encode(message, GROUND_TRUTH, truth_layout, values, len(values["sec"]))
