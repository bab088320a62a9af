"""Reading bags back: round trips, JointState input, log-time order, foreign MCAP files, speed."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from rosbags.rosbag2 import Reader

from prsm_health.bags.baseline import decode_baseline, decode_time_baseline
from prsm_health.bags.codecs import encode_motor_states
from prsm_health.bags.errors import BagError, TopicNotFoundError
from prsm_health.bags.raw import read_raw_messages
from prsm_health.bags.reader import InputTopics, iter_motor_samples, read_motor_samples, read_truth
from prsm_health.bags.stamps import seconds_to_stamps
from prsm_health.bags.typestore import MOTOR_STATE, typestore
from prsm_health.bags.writer import BagWriter, write_joint_states, write_motor_states
from prsm_health.signals import MotorSamples, TruthSamples
from test.bags.samples import (
    assert_same,
    mcap_file,
    motor_samples,
    quantised,
    split_bag,
    truth_samples,
    with_quantised_stamps,
    write_bag,
)


def test_motor_samples_round_trip_with_faulty_stamps_and_values(tmp_path: Path) -> None:
    motor = motor_samples(30000)
    bag = write_bag(tmp_path / "bag", motor=motor)
    got = read_motor_samples(bag)
    assert_same(got, with_quantised_stamps(motor))
    assert np.isnan(got.stamp_s[5]) and got.stamp_s[6] == np.inf and got.stamp_s[7] == -np.inf
    assert got.stamp_s[10] < got.stamp_s[9] and got.stamp_s[11] == -3.25
    assert np.signbit(got.current_a[9])
    assert_same(read_motor_samples(mcap_file(bag)), got)  # a bare .mcap file reads the same


def test_epoch_stamps_round_trip_exactly(tmp_path: Path) -> None:
    motor = motor_samples(2000, t0=1.7e9)
    got = read_motor_samples(write_bag(tmp_path / "bag", motor=motor))
    assert_same(got, motor)


def test_chunks_are_consecutive_and_of_the_requested_size(tmp_path: Path) -> None:
    motor = motor_samples(30001)
    bag = write_bag(tmp_path / "bag", motor=motor)
    chunks = list(iter_motor_samples(bag, chunk_size=7000))
    assert [len(c) for c in chunks] == [7000] * 4 + [2001]
    assert_same(MotorSamples.concatenate(chunks), read_motor_samples(bag))
    assert [len(c) for c in iter_motor_samples(bag, chunk_size=1)][:3] == [1, 1, 1]
    with pytest.raises(ValueError, match="chunk_size"):
        next(iter_motor_samples(bag, chunk_size=0))


def test_joint_states_input(tmp_path: Path) -> None:
    motor = motor_samples(5000)
    bag = write_bag(tmp_path / "bag", joint=motor)
    topics = InputTopics(joint_states="/joint_states")
    assert_same(read_motor_samples(bag, topics), with_quantised_stamps(motor))
    torque = InputTopics(
        joint_states="/joint_states", effort="torque", torque_constant_nm_per_a=0.5
    )
    np.testing.assert_array_equal(read_motor_samples(bag, torque).current_a, motor.current_a / 0.5)
    missing = read_motor_samples(bag, InputTopics(joint_states="/joint_states", joint_name="other"))
    assert len(missing) == 5000
    np.testing.assert_array_equal(missing.stamp_s, quantised(motor.stamp_s))
    assert np.isnan(missing.current_a).all() and np.isnan(missing.position_rad).all()


def test_input_topics_are_validated() -> None:
    with pytest.raises(ValueError, match="torque_constant_nm_per_a: a finite value > 0"):
        InputTopics(joint_states="/j", effort="torque")
    with pytest.raises(
        ValueError, match="torque_constant_nm_per_a: only used with effort='torque'"
    ):
        InputTopics(torque_constant_nm_per_a=0.5)
    with pytest.raises(
        ValueError, match=r"InputTopics\.motor_state: a topic name starting with '/'"
    ):
        InputTopics(motor_state="motor")
    with pytest.raises(ValueError, match=r"InputTopics\.effort"):
        InputTopics(effort="power")  # type: ignore[arg-type]
    assert InputTopics(joint_states="/j").topic == "/j"


def test_truth_round_trip_and_absence(tmp_path: Path) -> None:
    truth = truth_samples(3000, rollers=7)
    bag = write_bag(tmp_path / "bag", motor=motor_samples(10), truth=truth)
    got = read_truth(bag)
    assert got is not None
    changed = {"stamp_s", "precision_loss_m"}
    expected = TruthSamples(
        **{f: getattr(truth, f) for f in truth.__dataclass_fields__ if f not in changed},
        stamp_s=quantised(truth.stamp_s),
        precision_loss_m=truth.precision_loss_m * 1e6 / 1e6,
    )
    assert_same(got, expected)
    np.testing.assert_allclose(got.precision_loss_m, truth.precision_loss_m, rtol=1e-15)
    np.testing.assert_array_equal(got.jammed_rollers, truth.roller_jammed.sum(axis=1))
    assert read_truth(write_bag(tmp_path / "none", motor=motor_samples(10))) is None
    assert read_truth(bag, partial_ok=True)[1] is None


def test_split_bag_reads_its_files_in_time_order(tmp_path: Path) -> None:
    motor = motor_samples(20000)
    later, earlier = motor[10000:20000], motor[0:10000]
    parts = [write_bag(tmp_path / "b", motor=later), write_bag(tmp_path / "a", motor=earlier)]
    bag = split_bag(tmp_path / "bag", parts)
    assert_same(read_motor_samples(bag), with_quantised_stamps(motor))


def test_empty_topic_reads_as_no_samples(tmp_path: Path) -> None:
    with BagWriter(tmp_path / "bag") as writer:
        writer.add_topic("/motor_state", MOTOR_STATE)
    assert len(read_motor_samples(tmp_path / "bag")) == 0
    assert list(iter_motor_samples(tmp_path / "bag")) == []


def test_an_empty_series_writes_no_messages(tmp_path: Path) -> None:
    with BagWriter(tmp_path / "bag") as writer:
        write_motor_states(writer, motor_samples(0))
    assert len(read_motor_samples(tmp_path / "bag")) == 0


def test_log_time_order_across_overlapping_chunks(tmp_path: Path) -> None:
    """Receive times in random order: chunks overlap in time; the reader merges them exactly."""
    motor = motor_samples(40000, faults=False)
    receive = np.random.default_rng(7).permutation(40000).astype(np.int64) * 1000 + 5
    with BagWriter(tmp_path / "bag") as writer:
        write_motor_states(writer, motor, receive_time_ns=receive)
        write_joint_states(writer, motor_samples(3000, seed=9))  # interleaved chunks
    order = np.argsort(receive, kind="stable")
    expected = motor[slice(None)]
    expected = MotorSamples(*(getattr(motor, f)[order] for f in motor.__dataclass_fields__))
    got = MotorSamples.concatenate(list(iter_motor_samples(tmp_path / "bag", chunk_size=3333)))
    assert_same(got, with_quantised_stamps(expected))
    with Reader(tmp_path / "bag") as reader:
        conns = [c for c in reader.connections if c.topic == "/motor_state"]
        rosbags_times = [t for _, t, _ in reader.messages(conns)]
    assert rosbags_times == np.sort(receive).tolist()


@pytest.mark.parametrize(
    ("compression", "chunked", "summary_channels"),
    [
        (CompressionType.LZ4, True, True),
        (CompressionType.NONE, True, True),
        (CompressionType.NONE, False, True),
        (CompressionType.NONE, True, False),
    ],
)
def test_foreign_mcap_files_lz4_uncompressed_unchunked(
    tmp_path: Path, compression: CompressionType, chunked: bool, summary_channels: bool
) -> None:
    """MCAP written by the mcap library (CRCs on): lz4 chunks, plain chunks, no chunks, a
    summary without Channel records (refused as 'no topic /motor_state; topics: none' until
    a review session found it: such a summary declares nothing)."""
    motor = motor_samples(5000)
    sec, nanosec = seconds_to_stamps(motor.stamp_s)
    payloads = encode_motor_states(
        {
            "sec": sec,
            "nanosec": nanosec,
            "current_a": motor.current_a,
            "speed_rad_s": motor.speed_rad_s,
            "position_rad": motor.position_rad,
        },
        frame_id="odd_frame",
    )
    path = tmp_path / "foreign.mcap"
    msgdef, _ = typestore().generate_msgdef(MOTOR_STATE, ros_version=2)
    with path.open("wb") as stream:
        writer = McapWriter(
            stream,
            chunk_size=50_000,
            compression=compression,
            use_chunking=chunked,
            repeat_channels=summary_channels,
            repeat_schemas=summary_channels,
        )
        writer.start(profile="ros2", library="test")
        schema = writer.register_schema(MOTOR_STATE, "ros2msg", msgdef.encode())
        other = writer.register_channel("/other", "cdr", schema)
        channel = writer.register_channel("/motor_state", "cdr", schema)
        for i, payload in enumerate(payloads):
            writer.add_message(channel, 1000 + i, bytes(payload), 1000 + i, sequence=i)
            if i % 100 == 0:
                writer.add_message(other, 1000 + i, bytes(payload), 0)
        writer.finish()
    assert_same(read_motor_samples(path), with_quantised_stamps(motor))


def test_errors_name_the_file_and_what_is_wrong(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "bag", motor=motor_samples(10), joint=motor_samples(10))
    with pytest.raises(TopicNotFoundError, match=rf"{bag}: no topic /nope .*topics: /joint_states"):
        read_motor_samples(bag, InputTopics(motor_state="/nope"))
    with pytest.raises(TopicNotFoundError, match=r"bag.mcap: no topic /nope"):
        read_motor_samples(mcap_file(bag), InputTopics(motor_state="/nope"))
    with pytest.raises(
        BagError, match=r"topic /joint_states is sensor_msgs/msg/JointState, expected .*MotorState"
    ):
        read_motor_samples(bag, InputTopics(motor_state="/joint_states"))
    with pytest.raises(
        BagError, match=r"topic /motor_state is .*MotorState, expected .*GroundTruth"
    ):
        read_truth(bag, "/motor_state")
    (bag / "metadata.yaml").unlink()
    with pytest.raises(BagError, match=rf"{bag / 'metadata.yaml'}: missing"):
        read_motor_samples(bag)
    with pytest.raises(BagError, match="no such bag"):
        read_motor_samples(tmp_path / "nothing")
    # A path the system cannot even look at (here: a name too long; as well a directory
    # without read permission) is a BagError too, not an OSError from deep inside pathlib.
    with pytest.raises(BagError, match="cannot read: File name too long"):
        read_motor_samples(tmp_path / ("x" * 300) / "bag")
    (tmp_path / "x.txt").write_text("")
    with pytest.raises(BagError, match=r"not a \.mcap file"):
        read_motor_samples(tmp_path / "x.txt")
    (tmp_path / "bad").mkdir()
    (tmp_path / "bad" / "metadata.yaml").write_text(
        "rosbag2_bagfile_information: {storage_identifier: sqlite3}"
    )
    with pytest.raises(BagError, match="storage_identifier is 'sqlite3'"):
        read_motor_samples(tmp_path / "bad")
    (tmp_path / "bad" / "metadata.yaml").write_text(
        "rosbag2_bagfile_information: {storage_identifier: mcap, relative_file_paths: [],"
        " topics_with_message_count: [{topic_metadata: null}]}"
    )
    with pytest.raises(BagError, match="topic entry without name and type"):
        read_motor_samples(tmp_path / "bad")


def test_baseline_counts_every_message(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "bag", motor=motor_samples(3000))
    baseline = decode_baseline(bag)
    assert baseline.messages == 3000 and baseline.seconds > 0
    assert decode_time_baseline(mcap_file(bag)) > 0
    with pytest.raises(TopicNotFoundError, match="no topic /x"):
        decode_baseline(bag, "/x")


def _best(function: object, repeats: int = 3) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()  # type: ignore[operator]
        times.append(time.perf_counter() - start)
    return min(times)


def test_reading_is_faster_than_the_rosbags_baseline(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "bag", motor=motor_samples(60000))
    ours = _best(lambda: read_motor_samples(bag))
    baseline = min(decode_time_baseline(bag) for _ in range(3))
    assert ours < baseline / 2, (ours, baseline)


def test_equal_log_times_across_chunks_keep_the_order_written(tmp_path: Path) -> None:
    """Stamps that jump back by 40 s at 30 s: the writer gives the 30,000 samples after the
    jump one log time (the running maximum), over three chunks, and the truth written after
    them starts a chunk at log time 0 that holds the last motor samples too. Read back: the
    order written, by iter_motor_samples and read_raw_messages alike. (Batches came in the
    order of their first log time, so that chunk's tied samples came before the earlier
    chunks'; found by a review session.)"""
    motor = motor_samples(60_000, faults=False)
    motor.stamp_s[30_000:] -= 40.0
    bag = write_bag(tmp_path / "bag", motor=motor, truth=truth_samples(6000))
    expected = with_quantised_stamps(motor)
    assert_same(read_motor_samples(bag), expected)
    for size in (1000, 7777):
        chunks = list(iter_motor_samples(bag, chunk_size=size))
        assert_same(MotorSamples.concatenate(chunks), expected)
    store = typestore()
    stamps = [
        store.deserialize_cdr(cdr, MOTOR_STATE).header.stamp
        for _, _, cdr in read_raw_messages(bag, ["/motor_state"])
    ]
    sec, nanosec = seconds_to_stamps(motor.stamp_s)
    assert [(s.sec, s.nanosec) for s in stamps] == list(
        zip(sec.tolist(), nanosec.tolist(), strict=True)
    )
