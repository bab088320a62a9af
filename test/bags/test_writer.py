"""BagWriter: compressed MCAP readable by rosbags and by mcap + mcap_ros2, reproducible, fast."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.records import Chunk
from mcap.stream_reader import StreamReader
from mcap_ros2.decoder import DecoderFactory
from rosbags.rosbag2 import Reader

from prsm_health.bags.bagfiles import custom_data
from prsm_health.bags.errors import BagError
from prsm_health.bags.reader import InputTopics, read_motor_samples
from prsm_health.bags.stamps import log_times_from_stamps, seconds_to_stamps
from prsm_health.bags.typestore import GROUND_TRUTH, JOINT_STATE, MOTOR_STATE, typestore
from prsm_health.bags.writer import (
    LIBRARY,
    BagWriter,
    write_joint_states,
    write_motor_states,
    write_truth,
)
from test.bags.samples import (
    assert_same,
    mcap_file,
    motor_samples,
    truth_samples,
    with_quantised_stamps,
    write_bag,
)


def _rows(t: np.ndarray, *columns: Any) -> list[tuple[Any, ...]]:
    """(sec, nanosec, values...) per message, stamps as the writer converts them."""
    sec, nanosec = seconds_to_stamps(t)
    return list(zip(sec.tolist(), nanosec.tolist(), *columns, strict=True))


def _expected(motor: Any, joint: Any, truth: Any) -> dict[str, list[tuple[Any, ...]]]:
    """Per topic, the rows the writer must have put in the bag (as :func:`_row` reads them)."""
    jammed = truth.roller_jammed
    return {
        "/motor_state": _rows(
            motor.stamp_s, motor.current_a, motor.speed_rad_s, motor.position_rad
        ),
        "/joint_states": _rows(
            joint.stamp_s,
            [["prsm_motor"]] * len(joint),
            joint.position_rad,
            joint.speed_rad_s,
            joint.current_a,
        ),
        "/truth/state": _rows(
            truth.stamp_s,
            truth.axial_load_n,
            truth.loading_case.tolist(),
            jammed.sum(axis=1).tolist(),
            jammed.tolist(),
            truth.precision_loss_m * 1e6,
            truth.wear_coefficient_factor,
        ),
    }


def _row(topic: str, m: Any) -> tuple[Any, ...]:
    stamp = (m.header.stamp.sec, m.header.stamp.nanosec)
    if topic == "/motor_state":
        return (*stamp, m.current_a, m.speed_rad_s, m.position_rad)
    if topic == "/joint_states":
        return (
            *stamp,
            list(m.name),
            *(float(getattr(m, n)[0]) for n in ("position", "velocity", "effort")),
        )
    return (
        *stamp,
        m.axial_load_n,
        m.loading_case,
        m.jammed_rollers,
        [bool(x) for x in m.roller_jammed],
        m.precision_loss_um,
        m.wear_coefficient_factor,
    )


def _same_rows(got: list[tuple[Any, ...]], want: list[tuple[Any, ...]]) -> None:
    assert len(got) == len(want)
    for g, w in zip(got, want, strict=True):
        assert len(g) == len(w)
        for a, b in zip(g, w, strict=True):
            assert a == b or (a != a and b != b), (g, w)  # NaN == NaN


@pytest.fixture(scope="module")
def full_bag(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    motor, joint, truth = motor_samples(3000), motor_samples(500, seed=4), truth_samples(700)
    bag = write_bag(tmp_path_factory.mktemp("w") / "bag", motor=motor, joint=joint, truth=truth)
    return bag, _expected(motor, joint, truth)


def test_rosbags_reads_every_message(full_bag: tuple[Path, dict[str, Any]]) -> None:
    bag, expected = full_bag
    store = typestore()
    got: dict[str, list[tuple[Any, ...]]] = {topic: [] for topic in expected}
    with Reader(bag) as reader:
        types = {c.topic: c.msgtype for c in reader.connections}
        assert types == {
            "/motor_state": MOTOR_STATE,
            "/joint_states": JOINT_STATE,
            "/truth/state": GROUND_TRUTH,
        }
        for connection, _, data in reader.messages():
            message = store.deserialize_cdr(data, connection.msgtype)
            got[connection.topic].append(_row(connection.topic, message))
    for topic, rows in expected.items():
        _same_rows(got[topic], rows)


def test_mcap_ros2_decodes_every_message_from_the_embedded_schemas(
    full_bag: tuple[Path, dict[str, Any]],
) -> None:
    bag, expected = full_bag
    got: dict[str, list[tuple[Any, ...]]] = {topic: [] for topic in expected}
    with mcap_file(bag).open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()], validate_crcs=True)
        assert reader.get_header().library == LIBRARY
        summary = reader.get_summary()
        assert summary is not None
        assert {c.compression for c in summary.chunk_indexes} == {"zstd"}
        for _, channel, _, message in reader.iter_decoded_messages(log_time_order=False):
            got[channel.topic].append(_row(channel.topic, message))
    for topic, rows in expected.items():
        _same_rows(got[topic], rows)
    with mcap_file(bag).open("rb") as stream:  # every chunk has a CRC (rosbags writes 0)
        records = StreamReader(stream, emit_chunks=True, validate_crcs=True).records
        crcs = [record.uncompressed_crc for record in records if isinstance(record, Chunk)]
    assert crcs and all(crcs)


def test_log_times_follow_the_stamps_or_the_receive_times(tmp_path: Path) -> None:
    motor = motor_samples(50)
    receive = np.arange(50, dtype=np.int64) * 7 + 1_700_000_000_000_000_000
    with BagWriter(tmp_path / "a") as writer:
        write_motor_states(writer, motor)
        write_motor_states(writer, motor, topic="/received", receive_time_ns=receive)
    with Reader(tmp_path / "a") as reader:
        times: dict[str, list[int]] = {"/motor_state": [], "/received": []}
        for connection, timestamp, _ in reader.messages():
            times[connection.topic].append(timestamp)
    assert times["/motor_state"] == log_times_from_stamps(motor.stamp_s).tolist()
    assert times["/received"] == receive.tolist()


def test_same_inputs_give_byte_identical_bags(tmp_path: Path) -> None:
    kwargs = {
        "motor": motor_samples(20000),
        "joint": motor_samples(100),
        "truth": truth_samples(900),
    }
    first = write_bag(tmp_path / "1" / "bag", **kwargs)
    time.sleep(1.1)  # a wall-clock time anywhere in the files would now differ
    second = write_bag(tmp_path / "2" / "bag", **kwargs)
    for name in ("metadata.yaml", "bag.mcap"):
        assert (first / name).read_bytes() == (second / name).read_bytes(), name
    assert b"rosbags-" not in mcap_file(first).read_bytes()[:200]


def test_chunk_compression_makes_small_files(tmp_path: Path) -> None:
    motor = motor_samples(20000, faults=False)
    motor = type(motor)(
        motor.stamp_s,
        np.round(motor.current_a, 2),
        motor.speed_rad_s * 0,
        np.cumsum(np.full(20000, 1e-3)),
    )
    small = mcap_file(write_bag(tmp_path / "z", motor=motor)).stat().st_size
    plain = mcap_file(write_bag(tmp_path / "p", motor=motor, compress=False)).stat().st_size
    assert plain / 20000 > 80
    assert small < plain / 2


def test_sixty_thousand_motor_states_write_well_under_two_seconds(tmp_path: Path) -> None:
    motor = motor_samples(60000)
    typestore()
    start = time.perf_counter()
    write_bag(tmp_path / "fast", motor=motor)
    assert time.perf_counter() - start < 1.0


def test_single_messages_and_raw_cdr(tmp_path: Path) -> None:
    store = typestore()
    types = store.types
    message = types[MOTOR_STATE](
        types["std_msgs/msg/Header"](types["builtin_interfaces/msg/Time"](1, 2), "m"), 1.0, 2.0, 3.0
    )
    with BagWriter(tmp_path / "one") as writer:
        writer.add_topic("/m", MOTOR_STATE)
        writer.add_topic("/m", MOTOR_STATE)  # again: no-op
        writer.write("/m", 5, message)
        writer.write_cdr("/m", 6, store.serialize_cdr(message, MOTOR_STATE))
        assert writer.topics == {"/m": MOTOR_STATE}
    with Reader(tmp_path / "one") as reader:
        got = [(t, store.deserialize_cdr(d, MOTOR_STATE)) for _, t, d in reader.messages()]
    assert [t for t, _ in got] == [5, 6]
    assert all(m == message for _, m in got)


def test_a_path_ending_in_mcap_is_a_bare_mcap_file(tmp_path: Path) -> None:
    """The same bytes as the MCAP of a bag directory of its stem, read back by our reader and
    its custom data with it, nothing left beside it. (Until 2026-11-27 such a path was
    refused: it had made a directory holding out.mcap/out.mcap.mcap.)"""
    motor = motor_samples(500)
    bag = write_bag(tmp_path / "dir" / "out", motor=motor)
    bare = write_bag(tmp_path / "out.mcap", motor=motor)
    assert bare.is_file() and bare.read_bytes() == mcap_file(bag).read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dir", "out.mcap"]
    back = read_motor_samples(bare, InputTopics())
    np.testing.assert_array_equal(back.current_a, motor.current_a)
    deep = tmp_path / "a" / "b" / "c.mcap"  # its folders are made, as a bag directory's
    with BagWriter(deep) as writer:
        writer.set_custom_data("scene", "x")
        write_motor_states(writer, motor)
    assert custom_data(deep) == {"scene": "x"}
    with pytest.raises(BagError, match=r"out.mcap: exists already, not overwriting"):
        BagWriter(bare)


def test_a_bare_mcap_file_cut_by_an_error_is_left_as_a_recorder_leaves_it(
    tmp_path: Path,
) -> None:
    """An exception inside the writer leaves the MCAP written so far at the path (incomplete:
    no summary), as a crashed recorder leaves its file, and no working directory; one that a
    killed process left is named."""
    path = tmp_path / "cut.mcap"
    with pytest.raises(RuntimeError), BagWriter(path) as writer:
        write_motor_states(writer, motor_samples(5000))
        raise RuntimeError
    assert path.is_file() and path.read_bytes().startswith(b"\x89MCAP0\r\n")
    assert [p.name for p in tmp_path.iterdir()] == ["cut.mcap"]
    (tmp_path / ".left.mcap.writing").mkdir()
    with pytest.raises(BagError, match=r"left.mcap.writing is left from a write that was killed"):
        BagWriter(tmp_path / "left.mcap")


def test_a_bare_mcap_file_never_replaces_or_takes_what_another_wrote(tmp_path: Path) -> None:
    """A file that appears at the path during the write is kept (the bag stays in the working
    directory, named); a second writer of the same path fails without touching the first's
    work; a name too long for the working directory is a BagError. (Found in review: the
    first was replaced, the second moved the first writer's partial file and removed its
    directory, the third was an OSError traceback.)"""
    path = tmp_path / "t.mcap"
    refused = r"t.mcap: not written there \(File exists\): the bag is"
    with pytest.raises(BagError, match=refused), BagWriter(path) as writer:
        write_motor_states(writer, motor_samples(100))
        path.write_text("mine")
    assert path.read_text() == "mine"
    left = tmp_path / ".t.mcap.writing" / "t" / "t.mcap"
    assert len(read_motor_samples(left, InputTopics())) == 100

    two = tmp_path / "two.mcap"
    first, second = BagWriter(two), BagWriter(two)
    with first:
        write_motor_states(first, motor_samples(100))
        with pytest.raises(BagError, match=r"two.mcap: cannot create the bag: .*File exists"):
            second.__enter__()
    assert len(read_motor_samples(two, InputTopics())) == 100
    assert sorted(p.name for p in tmp_path.iterdir()) == [".t.mcap.writing", "t.mcap", "two.mcap"]

    with pytest.raises(BagError, match=r"cannot create the bag: .*File name too long"):
        BagWriter(tmp_path / f"{'a' * 245}.mcap")


@pytest.mark.parametrize("kind", ["motor", "joint", "truth"])
def test_stamps_written_in_pieces_keep_their_order_after_a_clock_jump(
    tmp_path: Path, kind: str
) -> None:
    """Log times from the stamps never go back over the topic, across calls too, whichever
    series is written: a second piece whose stamps jumped back by 1 s has the first piece's
    last log time, so every reader returns the messages in the order written. (Each call made
    its own stamps non-decreasing; the replay's output, written in pieces, interleaved the
    pieces after a jump back until 2026-11-27, and /joint_states and /truth/state did until
    a review found them left out of the fix.)"""
    series = truth_samples(2000) if kind == "truth" else motor_samples(2000, faults=False)
    series.stamp_s[1000:] -= 1.0
    write = {"motor": write_motor_states, "joint": write_joint_states, "truth": write_truth}[kind]
    bag = tmp_path / "pieces"
    with BagWriter(bag) as writer:
        write(writer, series[:1000])
        write(writer, series[1000:])
    with mcap_file(bag).open("rb") as stream:
        messages = make_reader(stream).iter_messages(log_time_order=False)
        log_times = [message.log_time for _, _, message in messages]
    assert len(log_times) == 2000
    expected = log_times_from_stamps(series.stamp_s)
    expected[1000:] = expected[999]
    np.testing.assert_array_equal(log_times, expected)
    if kind == "motor":
        assert_same(read_motor_samples(bag, InputTopics()), with_quantised_stamps(series))


def test_writer_errors_name_the_bag(tmp_path: Path) -> None:
    (tmp_path / "exists").mkdir()
    with (
        pytest.raises(BagError, match=r"exists: cannot create the bag"),
        BagWriter(tmp_path / "exists"),
    ):
        pass
    bag = tmp_path / "bag"
    with BagWriter(bag) as writer:
        writer.add_topic("/m", MOTOR_STATE)
        with pytest.raises(BagError, match=rf"{bag}: topic /m is .*MotorState, not .*JointState"):
            writer.add_topic("/m", JOINT_STATE)
        with pytest.raises(BagError, match="unknown message type pkg/msg/Nope"):
            writer.add_topic("/x", "pkg/msg/Nope")
        with pytest.raises(BagError, match=r"topic /y was not added"):
            writer.write_cdr("/y", 0, b"")
        with pytest.raises(BagError, match=r"log times must be integers in \[0, 2\*\*63 - 1\)"):
            writer.write_cdr("/m", -1, b"")
        with pytest.raises(BagError, match="got a sensor_msgs/msg/JointState"):
            writer.write("/m", 0, typestore().types[JOINT_STATE](None, [], [], [], []))
        bad = motor_samples(20)
        bad.stamp_s[3] = 5e9
        with pytest.raises(BagError, match=r"/motor_state: 1 finite stamp\(s\) outside"):
            write_motor_states(writer, bad)
        with pytest.raises(BagError, match="receive_time_ns has shape"):
            write_motor_states(writer, motor_samples(20), receive_time_ns=np.zeros(3, dtype=int))
    with pytest.raises(BagError, match="outside the `with BagWriter` block"):
        writer.add_topic("/late", MOTOR_STATE)
