"""Damaged bags: everything complete before the damage is delivered, then a BagDamagedError."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import NonSeekingReader
from mcap.stream_reader import CRCValidationError

from prsm_health.bags.errors import BagDamagedError, BagError
from prsm_health.bags.reader import InputTopics, iter_motor_samples, read_motor_samples, read_truth
from prsm_health.bags.typestore import MOTOR_STATE
from prsm_health.bags.writer import (
    CHUNK_CRC_OFFSET,
    BagWriter,
    write_motor_states,
    write_truth,
)
from prsm_health.signals import MotorSamples
from test.bags.samples import (
    assert_same,
    mcap_file,
    motor_samples,
    motor_state_payloads,
    split_bag,
    truth_samples,
    with_quantised_stamps,
    write_bag,
    write_with_mcap_library,
)

COUNT = 40000


@pytest.fixture(scope="module")
def intact(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, MotorSamples]:
    motor = motor_samples(COUNT)
    bag = write_bag(tmp_path_factory.mktemp("d") / "bag", motor=motor, truth=truth_samples(COUNT))
    return bag, with_quantised_stamps(motor)


def _chunk_offsets(data: bytes) -> list[int]:
    """Byte offsets of the top-level Chunk records."""
    pos, found = 8, []
    while pos + 9 <= len(data):
        op, length = struct.unpack_from("<BQ", data, pos)
        if op == 0x06:
            found.append(pos)
        if op == 0x0F:
            break
        pos += 9 + length
    return found


def _complete_messages(path: Path) -> int:
    """Messages of /motor_state the mcap library streams from the file before it fails."""
    count = 0
    with path.open("rb") as stream:
        try:
            for _, channel, _ in NonSeekingReader(stream).iter_messages(log_time_order=False):
                count += channel.topic == "/motor_state"
        except Exception:  # noqa: S110 - any error ends the stream; the count is what we want
            pass
    return count


def _cut_points(data: bytes) -> dict[str, int]:
    chunks = _chunk_offsets(data)
    last_chunk_end = chunks[-1] + 9 + struct.unpack_from("<Q", data, chunks[-1] + 1)[0]
    summary = struct.unpack_from("<Q", data, len(data) - 37 + 9)[0]
    return {
        "empty": 0,
        "inside the magic": 5,
        "inside the header record": 12,
        "inside the first chunk": chunks[0] + 5000,
        "inside a middle chunk": chunks[len(chunks) // 2] + 777,
        "between chunk and message index": last_chunk_end,
        "inside the summary": summary + 100,
        "before the end magic": len(data) - 3,
    }


@pytest.mark.parametrize(
    "where",
    [
        "empty",
        "inside the magic",
        "inside the header record",
        "inside the first chunk",
        "inside a middle chunk",
        "between chunk and message index",
        "inside the summary",
        "before the end magic",
    ],
)
def test_truncated_file_delivers_the_complete_chunks_then_raises(
    intact: tuple[Path, MotorSamples], tmp_path: Path, where: str
) -> None:
    bag, motor = intact
    data = mcap_file(bag).read_bytes()
    cut = _cut_points(data)[where]
    damaged = tmp_path / "cut.mcap"
    damaged.write_bytes(data[:cut])
    expected = _complete_messages(damaged)

    chunks: list[MotorSamples] = []
    with pytest.raises(BagDamagedError, match=rf"{damaged}: damaged at byte \d+: ") as info:
        for chunk in iter_motor_samples(damaged, chunk_size=5000):
            chunks.append(chunk)
    got = MotorSamples.concatenate(chunks) if chunks else motor[0:0]
    assert len(got) == expected
    assert_same(got, motor[0:expected])
    if where in ("inside the summary", "before the end magic"):
        assert expected == COUNT and "every message in it was read" in str(info.value)
    if expected == 0:
        assert "topic /motor_state not seen before it" in str(info.value)

    partial, error = read_motor_samples(damaged, partial_ok=True)
    assert_same(partial, got)
    assert isinstance(error, BagDamagedError) and error.path == damaged
    with pytest.raises(BagDamagedError):
        read_motor_samples(damaged)


def test_truncated_file_inside_a_bag_directory(
    intact: tuple[Path, MotorSamples], tmp_path: Path
) -> None:
    bag, motor = intact
    copy = tmp_path / "bag"
    copy.mkdir()
    (copy / "metadata.yaml").write_bytes((bag / "metadata.yaml").read_bytes())
    data = mcap_file(bag).read_bytes()
    mcap_file(copy).write_bytes(data[: len(data) // 5])  # all /motor_state chunks come first
    partial, error = read_motor_samples(copy, partial_ok=True)
    assert 0 < len(partial) < COUNT
    assert_same(partial, motor[0 : len(partial)])
    assert error is not None and error.path == mcap_file(copy)
    assert "record at byte" in str(error) and "truncated file?" in str(error)
    truth, truth_error = read_truth(copy, partial_ok=True)
    assert truth is not None and len(truth) == 0 and truth_error is not None
    with pytest.raises(BagDamagedError):
        read_truth(copy)


def test_corrupt_chunk_size_and_record_length(tmp_path: Path) -> None:
    motor = with_quantised_stamps(motor_samples(40000))
    for compress in (True, False):
        bag = write_bag(tmp_path / f"bag{compress}", motor=motor, compress=compress)
        data = bytearray(mcap_file(bag).read_bytes())
        second = _chunk_offsets(bytes(data))[1]
        if compress:  # the announced uncompressed size of the second chunk
            struct.pack_into("<Q", data, second + 9 + 16, 12345)
            reason = "12345 announced"
        else:  # the length of the first record inside the second chunk, its CRC removed
            struct.pack_into("<I", data, second + CHUNK_CRC_OFFSET, 0)  # as rosbags writes it
            records = second + 9 + 28 + 4 + 8  # times, size, crc, "" compression, records length
            struct.pack_into("<Q", data, records + 1, 2**40)
            reason = "overruns its chunk"
        mcap_file(bag).write_bytes(bytes(data))
        partial, error = read_motor_samples(bag, partial_ok=True)
        assert error is not None
        assert error.path == mcap_file(bag)
        assert f"Chunk record at byte {second}" in str(error) or f"byte {second}:" in str(error)
        assert 0 < len(partial) < len(motor)
        assert_same(partial, motor[0 : len(partial)])
        assert reason in str(error)


def test_a_chunk_whose_opcode_is_corrupt_is_damage_not_a_gap(tmp_path: Path) -> None:
    """One byte, the opcode of the second Chunk record: the MCAP spec has readers skip a
    record of unknown opcode, so its messages were lost without a word (a gap, exit 0). The
    summary's chunk index still names it: the damage is reported, the chunks before it are
    delivered."""
    motor = with_quantised_stamps(motor_samples(COUNT))
    bag = write_bag(tmp_path / "bag", motor=motor)
    data = bytearray(mcap_file(bag).read_bytes())
    second = _chunk_offsets(bytes(data))[1]
    data[second] = 0x99
    mcap_file(bag).write_bytes(bytes(data))
    partial, error = read_motor_samples(bag, partial_ok=True)
    assert error is not None and f"damaged at byte {second}" in str(error)
    assert f"indexes a Chunk record at byte {second} that the data section does not" in str(error)
    assert 0 < len(partial) < len(motor)
    assert_same(partial, motor[0 : len(partial)])


def test_zeroed_data_and_a_corrupt_length_are_named_where_they_are(tmp_path: Path) -> None:
    """A zeroed run from the second chunk's start, and that chunk's length made huge in a
    file of full length: the damage is named at that chunk and for what it is. (Both were
    'file cut at byte ... (truncated file?)', the zeroed one 200 kB further on, where the
    zeros ended; found by a review session.)"""
    motor = with_quantised_stamps(motor_samples(COUNT))
    bag = write_bag(tmp_path / "bag", motor=motor)
    intact_bytes = mcap_file(bag).read_bytes()
    second = _chunk_offsets(intact_bytes)[1]
    zeroed, long = bytearray(intact_bytes), bytearray(intact_bytes)
    zeroed[second : second + 200_000] = bytes(200_000)
    struct.pack_into("<Q", long, second + 1, 2**40)
    for data, reason in ((zeroed, "opcode 0x00"), (long, "a corrupt record header")):
        mcap_file(bag).write_bytes(bytes(data))
        partial, error = read_motor_samples(bag, partial_ok=True)
        assert error is not None and f"damaged at byte {second}: " in str(error), str(error)
        assert reason in str(error) and "truncated" not in str(error)
        assert_same(partial, motor[0 : len(partial)])


def test_corrupt_payload_delivers_the_messages_before_it(tmp_path: Path) -> None:
    motor = motor_samples(300, faults=False)
    bag = tmp_path / "bag"
    with BagWriter(bag) as writer:
        write_motor_states(writer, motor[0:100])
        writer.write_cdr("/motor_state", 99_950_000, b"\x00\x01\x00\x00garbage")
        write_motor_states(writer, motor[100:300])
    chunks = []
    match = rf"{bag}: /motor_state: the message at log time 99950000 ns is not a valid "
    with pytest.raises(BagDamagedError, match=match + MOTOR_STATE):
        for chunk in iter_motor_samples(bag, chunk_size=30):
            chunks.append(chunk)
    assert [len(c) for c in chunks] == [30, 30, 30, 10]
    assert_same(MotorSamples.concatenate(chunks), with_quantised_stamps(motor[0:100]))


def test_not_an_mcap_file(tmp_path: Path) -> None:
    """Refused before anything is read, as docs/bags.md says (it was reported as damage at
    byte 0: exit 1 and "estimates cover what was read before it"; found by a review session);
    an empty file is a recording cut inside the magic instead, i.e. damaged."""
    path = tmp_path / "fake.mcap"
    path.write_bytes(b"PK\x03\x04 this is a zip file")
    with pytest.raises(BagError, match=r"fake\.mcap: not an MCAP file") as refused:
        read_motor_samples(path, partial_ok=True)
    assert not isinstance(refused.value, BagDamagedError)
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    samples, error = read_motor_samples(empty, partial_ok=True)
    assert len(samples) == 0
    assert isinstance(error, BagDamagedError) and "cut inside the leading MCAP magic" in str(error)
    with pytest.raises(BagError, match="not an MCAP file"):
        read_motor_samples(path, InputTopics(joint_states="/joint_states"))


@pytest.mark.parametrize("split", [False, True])  # change inside one chunk, or between files
def test_truth_whose_roller_count_changes(tmp_path: Path, split: bool) -> None:
    before = 3000
    first, second = truth_samples(before, rollers=5), truth_samples(100, rollers=7, t0=100.0)
    if split:
        parts = [write_bag(tmp_path / "a", truth=first), write_bag(tmp_path / "b", truth=second)]
        bag = split_bag(tmp_path / "bag", parts)
    else:
        with BagWriter(tmp_path / "bag") as writer:
            write_truth(writer, first)
            write_truth(writer, second)
        bag = tmp_path / "bag"
    truth, error = read_truth(bag, partial_ok=True)
    assert truth is not None and truth.roller_jammed.shape == (before, 5)
    assert error is not None and "roller_jammed has shape (7,), earlier messages (5,)" in str(error)


def test_a_bit_flipped_inside_a_compressed_chunk_is_damage(tmp_path: Path) -> None:
    """Our writer stores each chunk's CRC (rosbags writes 0). Without it, one bit flipped in
    the second zstd chunk of a bundled bag went unnoticed by 5 of 12 flips that zstd still
    decoded: up to 256 changed samples were delivered as good. Every flip, anywhere in the
    compressed records, is now damage named at that chunk; the first chunk is delivered."""
    motor = with_quantised_stamps(motor_samples(40000))
    bag = write_bag(tmp_path / "bag", motor=motor)
    data = mcap_file(bag).read_bytes()
    second = _chunk_offsets(data)[1]
    compressed = second + CHUNK_CRC_OFFSET + 4 + 4 + len("zstd") + 8
    end = second + 9 + struct.unpack_from("<Q", data, second + 1)[0]
    rng = np.random.default_rng(5)
    for position, bit in zip(
        rng.integers(compressed, end, size=12), rng.integers(0, 8, size=12), strict=True
    ):
        flipped = bytearray(data)
        flipped[position] ^= 1 << int(bit)
        path = tmp_path / "flipped.mcap"
        path.write_bytes(bytes(flipped))
        partial, error = read_motor_samples(path, partial_ok=True)
        assert error is not None, f"bit {bit} of byte {position} flipped, no damage reported"
        assert f"Chunk record at byte {second} " in str(error)
        assert 0 < len(partial) < len(motor)
        assert_same(partial, motor[0 : len(partial)])


def test_a_chunk_failing_its_crc_check_is_damage(tmp_path: Path) -> None:
    """Uncompressed chunks written by the mcap library carry a CRC (the rosbags writer stores
    0, which no check reaches): one current changed inside a later chunk, 1.5 A to 150 A, is
    damage named by the CRC, and only the chunks before it are delivered. A mutation review
    found this unguarded: with the CRC check disabled all 2,000 samples were read, the
    changed 150 A among them, and no damage was reported."""
    motor = motor_samples(2000, faults=False)
    motor.current_a[1500] = 1.5
    path = tmp_path / "crc.mcap"
    messages = [("/motor_state", 1000 + i, p) for i, p in enumerate(motor_state_payloads(motor))]
    write_with_mcap_library(path, messages, chunk_size=50_000)
    data = bytearray(path.read_bytes())
    old, new = struct.pack("<d", 1.5), struct.pack("<d", 150.0)
    assert data.count(old) == 1
    where = data.index(old)
    chunks = _chunk_offsets(bytes(data))
    damaged = max(c for c in chunks if c < where)
    assert damaged != chunks[0]  # a later chunk: there are samples before it
    data[where : where + len(old)] = new
    path.write_bytes(bytes(data))
    before = 0  # messages the mcap library streams, checking CRCs, before the damaged chunk
    with path.open("rb") as stream, pytest.raises(CRCValidationError):
        reader = NonSeekingReader(stream, validate_crcs=True)
        for _ in reader.iter_messages(log_time_order=False):
            before += 1
    partial, error = read_motor_samples(path, partial_ok=True)
    assert isinstance(error, BagDamagedError) and error.path == path
    assert f"damaged at byte {damaged}: " in str(error)
    assert f"Chunk record at byte {damaged} fails its CRC check" in str(error)
    assert 0 < len(partial) == before < 1500
    assert_same(partial, with_quantised_stamps(motor[0:before]))
    assert np.max(np.abs(partial.current_a)) < 150.0
