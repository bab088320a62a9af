"""read_raw_messages: every topic's raw messages merged in log-time order, up to any damage."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from prsm_health.bags.errors import BagDamagedError, BagError
from prsm_health.bags.raw import read_raw_messages
from prsm_health.bags.typestore import GROUND_TRUTH, MOTOR_STATE
from prsm_health.bags.writer import BagWriter, write_motor_states, write_truth
from test.bags.samples import (
    mcap_file,
    motor_samples,
    motor_state_payloads,
    split_bag,
    streamed_messages,
    truth_samples,
    write_bag,
    write_with_mcap_library,
)

MOTOR_COUNT = 30_000
TRUTH_COUNT = 3_000
TYPES = {"/motor_state": MOTOR_STATE, "/truth/state": GROUND_TRUTH}

Message = tuple[str, int, bytes]


@pytest.fixture(scope="module")
def intact(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Motor at 1 kHz and truth at 100 Hz (every tenth motor message has a truth message of
    the same log time), written in three blocks of 10 s each, so that chunks hold both topics
    and overlap in log time."""
    motor = motor_samples(MOTOR_COUNT, faults=False)
    truth = truth_samples(TRUTH_COUNT)
    truth = dataclasses.replace(truth, stamp_s=1e-2 * np.arange(TRUTH_COUNT))
    bag = tmp_path_factory.mktemp("raw") / "bag"
    with BagWriter(bag) as writer:
        for block in range(3):
            write_motor_states(writer, motor[block * 10_000 : (block + 1) * 10_000])
            write_truth(writer, truth[block * 1_000 : (block + 1) * 1_000])
    return bag


def _in_log_time_order(path: Path, topics: tuple[str, ...] = ()) -> list[Message]:
    """The streamed messages by log time; equal log times in the order of their channels
    (the order the topics were met), then of the file."""
    found = sorted(streamed_messages(path), key=lambda m: m[:2])  # stable: file order within a tie
    return [m for _, _, m in found if not topics or m[0] in topics]


def _cut(intact: Path, tmp_path: Path, fraction: float) -> Path:
    data = mcap_file(intact).read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * fraction)])
    return cut


def test_an_intact_bag_gives_every_message_of_every_topic_in_log_time_order(intact: Path) -> None:
    raw = read_raw_messages(intact)
    assert raw.damage is None
    assert raw.types == TYPES and raw.topics == tuple(TYPES)
    assert raw.counts() == {"/motor_state": MOTOR_COUNT, "/truth/state": TRUTH_COUNT}
    messages = list(raw)
    assert messages == _in_log_time_order(mcap_file(intact))
    times = [t for _, t, _ in messages]
    assert times == sorted(times)
    assert [m[0] for m in messages[:12]] == ["/motor_state", "/truth/state"] + ["/motor_state"] * 10


def test_a_damaged_bag_gives_what_is_complete_before_the_damage(
    intact: Path, tmp_path: Path
) -> None:
    cut = _cut(intact, tmp_path, 0.5)
    raw = read_raw_messages(cut)
    expected = _in_log_time_order(cut)
    assert 0 < len(expected) < MOTOR_COUNT + TRUTH_COUNT
    assert list(raw) == expected
    assert raw.counts() == {t: sum(m[0] == t for m in expected) for t in TYPES}
    assert isinstance(raw.damage, BagDamagedError)
    assert str(raw.damage).startswith(f"{cut}: damaged at byte ")
    assert "(truncated file?)" in str(raw.damage)


def test_only_the_topics_asked_are_read(intact: Path, tmp_path: Path) -> None:
    cut = _cut(intact, tmp_path, 0.5)
    raw = read_raw_messages(cut, ["/truth/state", "/not/in/the/bag"])
    assert raw.types == TYPES  # every topic met before the damage, read or not
    assert raw.topics == ("/truth/state",)
    assert list(raw) == _in_log_time_order(cut, ("/truth/state",))
    assert raw.damage is not None


def test_a_split_bag_is_merged_across_its_files(tmp_path: Path) -> None:
    """Two files whose messages interleave in log time (0.5 ms apart)."""
    parts = [
        write_bag(tmp_path / name, motor=motor_samples(2000, t0=t0, faults=False))
        for name, t0 in (("a", 0.0005), ("b", 0.0))
    ]
    bag = split_bag(tmp_path / "bag", parts)
    raw = read_raw_messages(bag)
    first = [m for _, _, m in streamed_messages(mcap_file(parts[0]))]
    second = [m for _, _, m in streamed_messages(mcap_file(parts[1]))]
    interleaved = [m for pair in zip(second, first, strict=True) for m in pair]
    assert raw.damage is None and list(raw) == interleaved


def test_nothing_before_the_damage(intact: Path, tmp_path: Path) -> None:
    header = tmp_path / "header.mcap"
    header.write_bytes(mcap_file(intact).read_bytes()[:12])  # inside the Header record
    raw = read_raw_messages(header)
    assert (len(raw), raw.types, raw.counts()) == (0, {}, {})
    assert isinstance(raw.damage, BagDamagedError) and raw.damage.path == header
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")  # a recorder that never wrote: damaged, not refused
    assert "cut inside the leading MCAP magic" in str(read_raw_messages(empty).damage)


def test_what_is_not_an_mcap_bag_is_refused(tmp_path: Path) -> None:
    with pytest.raises(BagError, match="no such bag"):
        read_raw_messages(tmp_path / "none")
    fake = tmp_path / "fake.mcap"
    fake.write_bytes(b"PK\x03\x04 this is a zip file")
    with pytest.raises(BagError, match=r"fake\.mcap: not an MCAP file \(no MCAP magic"):
        read_raw_messages(fake)


def test_equal_log_times_come_in_the_order_of_the_topics_before_that_of_the_bag(
    tmp_path: Path,
) -> None:
    """RawMessages promises equal log times "in the order of ``topics``, then of the bag":
    /a@0, /b@5, /a@5, one message per chunk (the mcap library's writer, chunk_size=1), come
    out /a@0, /a@5, /b@5 (/a was met first), not in the bag's order /a@0, /b@5, /a@5. A
    mutation review found this unguarded: the sort keys place and topic swapped survived."""
    payloads = motor_state_payloads(motor_samples(3, faults=False))
    written = [("/a", 0, payloads[0]), ("/b", 5, payloads[1]), ("/a", 5, payloads[2])]
    path = tmp_path / "ties.mcap"
    write_with_mcap_library(path, written, chunk_size=1)
    with path.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None and len(summary.chunk_indexes) == 3  # one message per chunk
    raw = read_raw_messages(path)
    assert raw.damage is None and raw.topics == ("/a", "/b")
    assert list(raw) == [written[0], written[2], written[1]]
