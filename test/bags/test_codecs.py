"""Vectorised CDR encode/decode against rosbags' serializer: byte for byte, value for value."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from prsm_health.bags.codecs import (
    TRUTH_FLOATS,
    TRUTH_FLOATS_AFTER,
    PayloadError,
    decode_joint_states,
    decode_motor_states,
    decode_truth,
    encode_joint_states,
    encode_motor_states,
    encode_truth,
)
from prsm_health.bags.typestore import GROUND_TRUTH, JOINT_STATE, MOTOR_STATE, typestore

SPECIAL = [np.nan, np.inf, -np.inf, -0.0, 5e-324, 1.7976931348623157e308]


def _types() -> Any:
    return typestore().types


def _header(sec: int, nanosec: int, frame: str) -> Any:
    types = _types()
    return types["std_msgs/msg/Header"](types["builtin_interfaces/msg/Time"](sec, nanosec), frame)


def _serialize(message: Any, msgtype: str, *, little_endian: bool = True) -> bytes:
    return bytes(typestore().serialize_cdr(message, msgtype, little_endian=little_endian))


def _batch(payloads: list[bytes]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Payloads laid end to end with a few junk bytes between, as inside an MCAP chunk."""
    buffer, starts = b"", []
    for payload in payloads:
        buffer += b"\xaa" * 3
        starts.append(len(buffer))
        buffer += payload
    sizes = [len(p) for p in payloads]
    return np.frombuffer(buffer, dtype=np.uint8), np.array(starts), np.array(sizes)


def _motor_messages(count: int) -> list[Any]:
    rng = np.random.default_rng(3)
    values = np.concatenate([SPECIAL, rng.normal(size=3 * count)])
    messages = []
    for i in range(count):
        frame = "f" * (i % 11)  # every alignment of the frame_id, including ""
        a, b, c = values[3 * i : 3 * i + 3]
        stamp = (int(rng.integers(-(2**31), 2**31)), int(rng.integers(0, 2**32)))
        messages.append(_types()[MOTOR_STATE](_header(*stamp, frame), a, b, c))
    return messages


def test_motor_state_encoding_is_rosbags_byte_for_byte() -> None:
    for frame in ["", "a", "prsm_motor", "x" * 13]:
        values = {
            "sec": np.array([0, -1, 2**31 - 1, 7], dtype=np.int32),
            "nanosec": np.array([0, 999_999_999, 2**32 - 1, 5], dtype=np.uint32),
            "current_a": np.array(SPECIAL[:4]),
            "speed_rad_s": np.array(SPECIAL[2:]),
            "position_rad": np.array([1.0, -2.0, 3.5, 1e-300]),
        }
        payloads = encode_motor_states(values, frame_id=frame)
        for i, payload in enumerate(payloads):
            message = _types()[MOTOR_STATE](
                _header(int(values["sec"][i]), int(values["nanosec"][i]), frame),
                values["current_a"][i],
                values["speed_rad_s"][i],
                values["position_rad"][i],
            )
            assert bytes(payload) == _serialize(message, MOTOR_STATE)


@pytest.mark.parametrize("little_endian", [True, False])
def test_fast_motor_decoding_equals_rosbags(little_endian: bool) -> None:
    """Mixed frame_id lengths (one batch, many layouts), NaN/inf; big-endian takes the fallback."""
    messages = _motor_messages(200)
    payloads = [_serialize(m, MOTOR_STATE, little_endian=little_endian) for m in messages]
    columns = decode_motor_states(*_batch(payloads))
    for i, payload in enumerate(payloads):
        expected = typestore().deserialize_cdr(payload, MOTOR_STATE)
        assert columns["sec"][i] == expected.header.stamp.sec
        assert columns["nanosec"][i] == expected.header.stamp.nanosec
        for name in ("current_a", "speed_rad_s", "position_rad"):
            got, want = columns[name][i], getattr(expected, name)
            assert np.array_equal(got, want, equal_nan=True) and np.signbit(got) == np.signbit(want)


def test_joint_state_encoding_is_rosbags_byte_for_byte() -> None:
    values = {
        "sec": np.array([1, 2], dtype=np.int32),
        "nanosec": np.array([3, 4], dtype=np.uint32),
        "position": np.array([np.nan, 1.0]),
        "velocity": np.array([2.0, np.inf]),
        "effort": np.array([-3.0, 0.5]),
    }
    payloads = encode_joint_states(values, joint="prsm_motor")
    for i, payload in enumerate(payloads):
        message = _types()[JOINT_STATE](
            _header(i + 1, i + 3, ""),
            ["prsm_motor"],
            *(np.array([values[n][i]]) for n in ("position", "velocity", "effort")),
        )
        assert bytes(payload) == _serialize(message, JOINT_STATE)


def _joint(
    names: list[str],
    position: list[float],
    velocity: list[float],
    effort: list[float],
    frame: str = "",
) -> Any:
    return _types()[JOINT_STATE](
        _header(1, 2, frame), names, np.array(position), np.array(velocity), np.array(effort)
    )


def test_joint_state_decoding_picks_the_joint_and_fills_nan_where_it_cannot() -> None:
    messages = [
        _joint(["prsm_motor"], [1.0], [2.0], [3.0]),
        _joint(["a", "prsm_motor"], [1.0, 4.0], [2.0, 5.0], [3.0, 6.0], frame="base"),
        _joint(["a", "prsm_motor"], [1.0, 4.0], [], [3.0]),  # velocity empty, effort short
        _joint(["a"], [1.0], [2.0], [3.0]),  # joint missing
        _joint(["prsm_motor", "b", "c"], [7.0, 0, 0], [8.0, 0, 0], [9.0, 0, 0]),
        _joint([], [], [], []),
        _joint(["prsm_motor", "b", "prsm_motor"], [1.0] * 3, [2.0] * 3, [3.0] * 3),  # repeated
    ]
    expected = [
        (1, 2, 3),
        (4, 5, 6),
        (4, np.nan, np.nan),
        (np.nan,) * 3,
        (7, 8, 9),
        (np.nan,) * 3,
        (np.nan,) * 3,
    ]
    for little_endian in (True, False):
        payloads = [_serialize(m, JOINT_STATE, little_endian=little_endian) for m in messages]
        columns = decode_joint_states(*_batch(payloads), joint="prsm_motor")
        got = np.column_stack([columns["position"], columns["velocity"], columns["effort"]])
        np.testing.assert_array_equal(got, np.array(expected, dtype=float))
        assert columns["sec"].tolist() == [1] * 7


def _truth_values(count: int, rollers: int) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(5)
    values: dict[str, np.ndarray] = {
        "sec": rng.integers(0, 100, count).astype(np.int32),
        "nanosec": rng.integers(0, 10**9, count).astype(np.uint32),
        "loading_case": rng.integers(1, 3, count).astype(np.uint8),
        "jammed_rollers": rng.integers(0, rollers + 1, count).astype(np.uint8),
        "roller_jammed": rng.random((count, rollers)) < 0.5,
    }
    for name in TRUTH_FLOATS + TRUTH_FLOATS_AFTER:
        values[name] = rng.normal(size=count)
    values["axial_load_n"][0] = np.nan
    return values


def _truth_message(values: dict[str, np.ndarray], i: int, frame: str = "") -> Any:
    kwargs = {name: values[name][i] for name in TRUTH_FLOATS + TRUTH_FLOATS_AFTER}
    return _types()[GROUND_TRUTH](
        header=_header(int(values["sec"][i]), int(values["nanosec"][i]), frame),
        loading_case=int(values["loading_case"][i]),
        jammed_rollers=int(values["jammed_rollers"][i]),
        roller_jammed=values["roller_jammed"][i].copy(),
        **kwargs,
    )


@pytest.mark.parametrize("rollers", [0, 1, 5, 9])
def test_truth_encoding_and_decoding_match_rosbags(rollers: int) -> None:
    values = _truth_values(20, rollers)
    payloads = encode_truth(values)
    for i, payload in enumerate(payloads):
        assert bytes(payload) == _serialize(_truth_message(values, i), GROUND_TRUTH)
    frames = ["", "ab", "abcdefg"]
    foreign = [  # other frame_ids (other layouts), every other one big-endian (the fallback)
        _serialize(_truth_message(values, i, frames[i % 3]), GROUND_TRUTH, little_endian=i % 2 == 0)
        for i in range(20)
    ]
    for batch in ([bytes(p) for p in payloads], foreign):
        columns = decode_truth(*_batch(batch))
        for name, expected in values.items():
            np.testing.assert_array_equal(columns[name], expected, name)
        assert columns["roller_jammed"].shape == (20, rollers)


def test_malformed_payloads_name_their_index() -> None:
    good = _serialize(_motor_messages(1)[0], MOTOR_STATE)
    with pytest.raises(PayloadError, match=r"message 1 is not a valid prsm_health_msgs/msg/Motor"):
        decode_motor_states(*_batch([good, good[:-9]]))
    values = _truth_values(2, 3)
    other = _truth_values(2, 4)
    mixed = [bytes(encode_truth(values)[0]), bytes(encode_truth(other)[0])]
    with pytest.raises(PayloadError, match="roller_jammed has shape"):
        decode_truth(*_batch(mixed))
