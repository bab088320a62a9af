"""Fuzzing the inputs: damaged bag files, random CDR payloads, malformed motor samples and
malformed ROS messages through the node's conversions.

Whatever the bytes, reading a bag ends in data or a typed :class:`BagError` (never another
exception), and whatever the samples, the estimator rejects and counts what it cannot use
(every sample fed is accepted or rejected) and never emits a non-finite estimate.
"""

from __future__ import annotations

import math
import shutil
from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from prsm_health_msgs.msg import MotorState
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from prsm_health.actuator import Actuator
from prsm_health.bags import (
    MOTOR_STATE,
    BagDamagedError,
    BagError,
    BagWriter,
    InputTopics,
    iter_motor_samples,
    read_motor_samples,
    read_truth,
    write_motor_states,
)
from prsm_health.bags.topics import MOTOR_STATE_TOPIC
from prsm_health.estimation.estimate import HealthState
from prsm_health.estimation.estimator import HealthEstimator
from prsm_health.estimation.params import EstimatorParams
from prsm_health.physics.presets import load_preset
from prsm_health.ros.messages import JOINT_PROBLEMS, input_sample
from prsm_health.signals import MotorSamples
from test.bags.samples import (
    assert_same,
    mcap_file,
    motor_samples,
    truth_samples,
    with_quantised_stamps,
    write_bag,
)
from test.estimation.chunks import fed_in_chunks

#: Messages of the fuzzed bag: three MCAP chunks (about 12,600 MotorState each).
MESSAGES = 30_000
PARAMS = EstimatorParams(actuator=Actuator(preset=load_preset("dong2022-downhole")))
SHARED_DIRECTORY = [HealthCheck.function_scoped_fixture]


@pytest.fixture(scope="module")
def intact(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A bag with motor states (including NaN/inf and backwards stamps) and truth."""
    return write_bag(
        tmp_path_factory.mktemp("fuzz") / "bag",
        motor=motor_samples(MESSAGES),
        truth=truth_samples(MESSAGES // 10),
    )


def _read_everything(path: Path) -> int:
    """Read the motor samples and truth of ``path`` every way; returns the samples delivered.

    Only BagError may escape; damage found after the start comes back as BagDamagedError.
    """
    samples, error = read_motor_samples(path, partial_ok=True)
    assert error is None or isinstance(error, BagDamagedError)
    event("intact" if error is None else "damaged: the samples before the damage")
    for f in fields(MotorSamples):
        assert len(getattr(samples, f.name)) == len(samples)
    delivered = 0
    try:
        for chunk in iter_motor_samples(path, chunk_size=4096):
            delivered += len(chunk)
    except BagDamagedError:
        pass
    assert delivered == len(samples)
    truth, truth_error = read_truth(path, partial_ok=True)
    assert truth_error is None or isinstance(truth_error, BagDamagedError)
    assert truth is None or truth.roller_jammed.shape[0] == len(truth)
    return len(samples)


mutations = st.one_of(
    st.tuples(st.just("truncate"), st.floats(0.0, 1.0), st.binary(max_size=0)),
    st.tuples(st.just("flip"), st.floats(0.0, 1.0), st.binary(min_size=1, max_size=8)),
    st.tuples(st.just("overwrite"), st.floats(0.0, 1.0), st.binary(min_size=1, max_size=64)),
    st.tuples(st.just("insert"), st.floats(0.0, 1.0), st.binary(min_size=1, max_size=64)),
)


def _mutated(data: bytes, mutation: tuple[str, float, bytes]) -> bytes:
    kind, where, payload = mutation
    at = min(int(where * len(data)), len(data) - 1)
    if kind == "truncate":
        return data[:at]
    if kind == "flip":
        flipped = bytearray(data)
        for i, byte in enumerate(payload):
            flipped[min(at + 97 * i, len(data) - 1)] ^= byte or 0xFF
        return bytes(flipped)
    if kind == "overwrite":
        return data[:at] + payload + data[at + len(payload) :]
    return data[:at] + payload + data[at:]


@settings(max_examples=60, deadline=None, suppress_health_check=SHARED_DIRECTORY)
@given(mutation=mutations, bare=st.booleans())
def test_damaged_mcap_bytes_give_data_or_a_bag_error(
    intact: Path,
    tmp_path_factory: pytest.TempPathFactory,
    mutation: tuple[str, float, bytes],
    bare: bool,
) -> None:
    """Truncated, bit-flipped, overwritten or padded MCAP files, read as a bag directory or as
    a bare .mcap."""
    target = tmp_path_factory.mktemp("mutated") / "bag"
    shutil.copytree(intact, target)
    mcap = mcap_file(target)
    mcap.write_bytes(_mutated(mcap_file(intact).read_bytes(), mutation))
    try:
        delivered = _read_everything(mcap if bare else target)
    except BagError as exc:
        event(f"refused: {type(exc).__name__}")
        return
    assert 0 <= delivered <= MESSAGES + 64


@settings(max_examples=30, deadline=None, suppress_health_check=SHARED_DIRECTORY)
@given(mutation=mutations)
def test_damaged_metadata_gives_data_or_a_bag_error(
    intact: Path, tmp_path_factory: pytest.TempPathFactory, mutation: tuple[str, float, bytes]
) -> None:
    target = tmp_path_factory.mktemp("metadata") / "bag"
    shutil.copytree(intact, target)
    metadata = target / "metadata.yaml"
    damaged = _mutated(metadata.read_bytes(), mutation)
    metadata.write_bytes(damaged)
    try:
        _read_everything(target)
    except BagError as exc:
        event(f"refused: {type(exc).__name__}")
        return


payloads = st.one_of(
    st.binary(max_size=120),
    # A valid little-endian CDR header followed by random bytes.
    st.binary(max_size=120).map(lambda tail: b"\x00\x01\x00\x00" + tail),
)


@settings(max_examples=40, deadline=None, suppress_health_check=SHARED_DIRECTORY)
@given(data=st.lists(payloads, min_size=1, max_size=40), valid_first=st.integers(0, 50))
def test_random_cdr_payloads_are_a_damaged_bag_or_counted_samples(
    intact: Path, tmp_path_factory: pytest.TempPathFactory, data: list[bytes], valid_first: int
) -> None:
    """MotorState messages whose payloads are random bytes (after some valid ones): the valid
    prefix is delivered and the rest is BagDamagedError, or the bytes happen to decode; what
    is delivered goes through the estimator, which counts every sample."""
    target = tmp_path_factory.mktemp("cdr") / "bag"
    good = motor_samples(valid_first, faults=False)
    with BagWriter(target) as writer:
        writer.add_topic(MOTOR_STATE_TOPIC, MOTOR_STATE)
        write_motor_states(writer, good)  # no messages when valid_first is 0
        times = np.arange(len(data), dtype=np.int64) + 10**9
        writer.write_cdr_many(MOTOR_STATE_TOPIC, times, data)
    try:
        samples, error = read_motor_samples(target, InputTopics(), partial_ok=True)
    except BagError as exc:
        event(f"refused: {type(exc).__name__}")
        return
    assert error is None or isinstance(error, BagDamagedError)
    event("all payloads decoded" if error is None else "damaged after the valid prefix")
    assert valid_first <= len(samples) <= valid_first + len(data)
    assert_same(samples[:valid_first], with_quantised_stamps(good))
    estimator = HealthEstimator(PARAMS)
    states = estimator.process(samples) + estimator.finish()
    _check_states(states)
    assert estimator.counters.accepted + estimator.counters.rejected_total == len(samples)


# --- the estimator's input path ---------------------------------------------------------------
def _check_states(states: list[HealthState]) -> None:
    for state in states:
        for f in fields(HealthState):
            value = getattr(state, f.name)
            if isinstance(value, float):
                assert math.isfinite(value), (f.name, state)
        probabilities = np.asarray(state.jam_probabilities)
        assert np.all((probabilities >= 0.0) & (probabilities <= 1.0))
        assert abs(float(probabilities.sum()) - 1.0) <= 1e-12


floats = st.floats(allow_nan=True, allow_infinity=True, allow_subnormal=True, width=64)
plausible = st.floats(-100.0, 100.0)
#: Fuzzed stamps reach decades either side of zero: a forward jump by a drive clock switching
#: from boot time to the epoch (1.7e9 s) is a gap, never a crash; beyond the +-2^31 s a ROS
#: stamp carries, a stamp is out of range (and up to 1e308, finite, it overflowed the grid).
STAMP_LIMIT_S = 4e9
stamps = st.one_of(
    st.floats(-STAMP_LIMIT_S, STAMP_LIMIT_S),
    st.sampled_from([math.nan, math.inf, -math.inf, -1e308, 1e308]),
)
#: Column dtypes: the integer ones reach their extremes (abs(int8 -128) and abs of the int64
#: minimum are negative; uint64 differences wrap around).
DTYPES = [np.float64, np.float32, np.float16, np.int64, np.int8, np.uint64]


def _as_dtype(values: np.ndarray, dtype: Any) -> np.ndarray:
    """``values`` in ``dtype``; an integer type takes NaN as 0 and clips to its extremes."""
    if np.dtype(dtype).kind in "iu":
        info = np.iinfo(dtype)
        low, high = float(info.min), float(info.max)
        values = np.nan_to_num(values, posinf=high, neginf=low).clip(low, high)
    with np.errstate(over="ignore", invalid="ignore"):
        return values.astype(dtype)


@st.composite
def sample_arrays(draw: st.DrawFn) -> MotorSamples:
    """Malformed samples: plausible values mixed with anything a float can be, stamps that
    jump, repeat or go backwards, in float64, float32, float16 or integer arrays (integer
    stamps too, whole seconds), some entries masked (numpy masked arrays)."""
    n = draw(st.integers(1, 200))
    stamp = np.cumsum(draw(hnp.arrays(np.float64, n, elements=st.floats(-0.002, 0.01))))
    stamp = stamp + draw(st.sampled_from([0.0, 3e5, -5.0, 1.7e9]))
    columns: list[np.ndarray] = [stamp]
    for _ in range(3):
        values = draw(hnp.arrays(np.float64, n, elements=st.one_of(plausible, floats)))
        columns.append(_as_dtype(values, draw(st.sampled_from(DTYPES))))
    if draw(st.booleans()):  # bad stamps too
        bad = draw(hnp.arrays(np.float64, n, elements=stamps))
        mask = draw(hnp.arrays(np.bool_, n))
        columns[0] = np.where(mask, bad, stamp)
    if draw(st.integers(0, 4)) == 0:  # integer stamps: whole seconds, repeating
        columns[0] = _as_dtype(columns[0], draw(st.sampled_from([np.int64, np.uint64])))
    if draw(st.integers(0, 4)) == 0:
        column = draw(st.integers(0, 3))
        mask = draw(hnp.arrays(np.bool_, n))
        columns[column] = np.ma.masked_array(columns[column], mask=mask)
    return MotorSamples(*columns)


@settings(max_examples=50, deadline=None)
@given(chunks=st.lists(sample_arrays(), min_size=1, max_size=4))
def test_malformed_samples_are_rejected_and_counted_never_raised(
    chunks: list[MotorSamples],
) -> None:
    estimator = HealthEstimator(PARAMS)
    states: list[HealthState] = []
    for chunk in chunks:
        states += estimator.process(chunk)
    states += estimator.finish()
    _check_states(states)
    counters = estimator.counters
    assert counters.accepted + counters.rejected_total == sum(len(c) for c in chunks)
    assert all(count >= 0 for count in counters.rejected)


@settings(max_examples=40, deadline=None)
@given(chunks=st.lists(sample_arrays(), min_size=1, max_size=4), size=st.integers(1, 25))
def test_malformed_samples_give_the_same_result_in_any_chunks(
    chunks: list[MotorSamples], size: int
) -> None:
    """The same samples fed whole and ``size`` at a time (the node feeds a few at a time):
    the same counters and estimates."""
    stream = MotorSamples.concatenate(chunks)
    whole = HealthEstimator(PARAMS)
    reference = whole.process(stream) + whole.finish()
    split = HealthEstimator(PARAMS)
    states = fed_in_chunks(split.process, stream, size) + split.finish()
    assert split.counters == whole.counters
    assert states == reference


def test_samples_of_different_lengths_are_a_value_error() -> None:
    with pytest.raises(ValueError, match="differ in length"):
        MotorSamples(np.zeros(3), np.zeros(3), np.zeros(2), np.zeros(3))


# --- the node's input path -------------------------------------------------------------------
#: Joint names the messages draw from (the node watches "prsm_motor").
JOINT = "prsm_motor"
header_stamps = st.builds(
    Time, sec=st.integers(-(2**31), 2**31 - 1), nanosec=st.integers(0, 2**32 - 1)
)
message_floats = st.one_of(plausible, floats)
motor_messages = st.builds(
    MotorState,
    header=st.builds(Header, stamp=header_stamps),
    current_a=message_floats,
    speed_rad_s=message_floats,
    position_rad=message_floats,
)
joint_messages = st.builds(
    JointState,
    header=st.builds(Header, stamp=header_stamps),
    name=st.lists(st.sampled_from([JOINT, "wheel", ""]), max_size=3),
    position=st.lists(message_floats, max_size=3),
    velocity=st.lists(message_floats, max_size=3),
    effort=st.lists(message_floats, max_size=3),
)


@settings(max_examples=40, deadline=None)
@given(
    messages=st.lists(st.one_of(motor_messages, joint_messages), min_size=1, max_size=300),
    torque_constant=st.one_of(st.none(), st.floats(0.01, 10.0)),
)
def test_malformed_ros_messages_become_rejected_samples_or_joint_problems(
    messages: list[object], torque_constant: float | None
) -> None:
    """Random MotorState and JointState messages (any stamp, any float, joints missing or
    arrays too short) through the node's conversion (input_sample) into the
    estimator: every message is a sample or a named joint problem, none raises, every sample
    is counted and no estimate is non-finite."""
    rows: list[tuple[float, float, float, float]] = []
    problems = 0
    for msg in messages:
        sample = input_sample(msg, JOINT, torque_constant)
        if sample.problem:
            assert isinstance(msg, JointState) and sample.problem in JOINT_PROBLEMS
            problems += 1
            continue
        rows.append((sample.stamp_s, sample.current_a, sample.speed_rad_s, sample.position_rad))
    assert len(rows) + problems == len(messages)
    estimator = HealthEstimator(PARAMS)
    columns = np.array(rows, dtype=np.float64).reshape(-1, 4).T
    states = estimator.process(MotorSamples(*columns)) + estimator.finish()
    _check_states(states)
    counters = estimator.counters
    assert counters.accepted + counters.rejected_total == len(rows)
