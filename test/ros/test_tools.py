"""prsm-health play, monitor and demo from the command line (real processes)."""

from __future__ import annotations

import json
import re
import shutil
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import numpy as np
import pytest
import rclpy
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from mcap.reader import make_reader
from prsm_health_msgs.msg import GroundTruth, HealthEstimate, MotorState
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, QoSReliabilityPolicy
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as RosbagsWriter
from rosgraph_msgs.msg import Clock

from prsm_health.bags.bagfiles import is_sqlite_bag
from prsm_health.bags.codecs import encode_motor_states
from prsm_health.bags.stamps import seconds_to_stamps
from prsm_health.bags.typestore import MOTOR_STATE, typestore
from prsm_health.bags.writer import BagWriter, write_joint_states, write_motor_states
from prsm_health.outputs import CONFIGURATION, INPUT_HEALTH, Level
from prsm_health.ros.messages import stamp_seconds
from prsm_health.ros.monitor import (
    NOT_CONFIGURED,
    Monitor,
    MonitorOptions,
    diagnostics_record,
    table,
)
from prsm_health.ros.player import (
    ACK_TIMEOUT_S,
    CLOCK_RATE_RANGE,
    FINAL_ACK_TIMEOUT_S,
    RATE_RANGE,
    PlayOptions,
)
from prsm_health.ros.tools import DEMO_BAG
from prsm_health.signals import MotorSamples
from test.bags.samples import streamed_messages
from test.conftest import REPO
from test.ros.data import short_jam_scene, simulated_bag, synthetic_run, write_bag
from test.ros.harness import Listener, NodeProcess, start_player, stop_process

#: The node of the acknowledgement test (its diagnostics say what it received).
HARDWARE_ID = "ack_test"


def cli(*args: str, timeout_s: float = 60.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "prsm_health", *args],
        capture_output=True,
        text=True,
        timeout=timeout_s,
        check=False,
    )


def _count_none_on(bag: Path, topic: str) -> None:
    """Make the bag's metadata.yaml count no message on ``topic`` (the file keeps them)."""
    metadata = bag / "metadata.yaml"
    info = yaml.safe_load(metadata.read_text())
    for entry in info["rosbag2_bagfile_information"]["topics_with_message_count"]:
        if entry["topic_metadata"]["name"] == topic:
            entry["message_count"] = 0
    metadata.write_text(yaml.safe_dump(info))


def test_play_refuses_what_it_cannot_play(tmp_path: Path) -> None:
    """Input errors exit with 2 (usage, as replay's), failures while playing with 1."""
    missing = cli("play", str(tmp_path / "none"))
    assert missing.returncode == 2
    assert f"cannot open bag {tmp_path / 'none'}" in missing.stderr
    bag = write_bag(tmp_path / "bag", synthetic_run(0.1))
    unknown = cli("play", str(bag), "--topics", "/nope")
    assert unknown.returncode == 2
    assert "no topic /nope in the bag; it has /motor_state" in unknown.stderr
    bad_rate = cli("play", str(bag), "--rate", "0")
    assert bad_rate.returncode == 2
    assert "must be a finite number > 0" in bad_rate.stderr
    nobody = cli("play", str(bag), "--wait-for-subscribers", "0.5")
    assert nobody.returncode == 1
    assert "no subscriber after 0.5 s on /motor_state" in nobody.stderr
    empty = write_bag(tmp_path / "empty", synthetic_run(0.1)[:0])  # the topic, no message
    looped = cli("play", str(empty), "--loop", timeout_s=30.0)  # it spun at 100 % CPU
    assert looped.returncode == 2
    assert "nothing to loop: the bag has no messages on the topics to play" in looped.stderr
    # metadata.yaml counts none on /motor_state, the file holds them: it ended in a KeyError
    # traceback (found by a review session); the messages are counted as read now.
    uncounted = simulated_bag(tmp_path / "uncounted", short_jam_scene(0.5))
    _count_none_on(uncounted, "/motor_state")
    played = cli("play", str(uncounted), "--rate", "100")
    assert played.returncode == 0, played.stderr
    assert "play done: /motor_state 500, /truth/state 50 published" in played.stdout


def test_play_plays_a_sqlite_bag_with_rosbags(tmp_path: Path) -> None:
    """MCAP bags are read as the replay reads them, a SQLite3 rosbag2 directory with rosbags
    (chosen by its metadata's storage, not by any error of the MCAP reader: a bag that
    reader refuses for another reason went to rosbags too; the session's final review)."""
    motor = synthetic_run(0.05)
    sec, nanosec = seconds_to_stamps(motor.stamp_s)
    columns = {"sec": sec, "nanosec": nanosec, "current_a": motor.current_a}
    columns |= {"speed_rad_s": motor.speed_rad_s, "position_rad": motor.position_rad}
    bag = tmp_path / "sqlite"
    with RosbagsWriter(bag, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        connections = [
            writer.add_connection(topic, MOTOR_STATE, typestore=typestore())
            for topic in ("/motor_state", "/other")
        ]
        for i, payload in enumerate(encode_motor_states(columns, frame_id="m")):
            for connection in connections:
                writer.write(connection, 1000 + i * 1_000_000, bytes(payload))
    assert is_sqlite_bag(bag) and not is_sqlite_bag(write_bag(tmp_path / "mcap", motor))
    played = cli("play", str(bag), "--rate", "100", "--topics", "/motor_state")
    assert played.returncode == 0, played.stderr
    assert f"play done: /motor_state {len(motor)} published" in played.stdout
    # rosbags takes the counts of metadata.yaml: one that counts none on a topic the bag
    # holds ended in a KeyError traceback (found by a review session); one line now.
    _count_none_on(bag, "/other")
    played = cli("play", str(bag), "--rate", "100")
    assert played.returncode == 1 and "Traceback" not in played.stderr
    assert "/other: the bag's metadata counts no message on it" in played.stderr


def test_play_refuses_rates_out_of_range(tmp_path: Path) -> None:
    """--rate 1e-300 and --clock-rate 1e-300 were OverflowError tracebacks (the wait, the
    clock's period); rates out of the played range are usage errors, the demo's too."""
    bag = write_bag(tmp_path / "bag", synthetic_run(0.01))
    refused = {
        ("--rate", "1e-300"): "--rate must be within 0.001 .. 1e+06, got 1e-300",
        ("--rate", "1e7"): "--rate must be within 0.001 .. 1e+06, got 1e+07",
        ("--clock", "--clock-rate", "1e-300"): (
            "--clock-rate must be within 0.01 .. 1e+09, got 1e-300"
        ),
        ("--clock-rate", "1e10"): "--clock-rate must be within 0.01 .. 1e+09, got 1e+10",
    }
    for args, error in refused.items():
        done = cli("play", str(bag), *args)
        assert (done.returncode, done.stderr) == (2, f"prsm-health: error: {error}\n"), args
    demo = cli("demo", "--bag", str(tmp_path / "none"), "--rate", "1e-300")
    expected = "prsm-health: error: --rate must be within 0.001 .. 1e+06, got 1e-300\n"
    assert (demo.returncode, demo.stderr) == (2, expected)
    demo = cli("demo", "--bag", str(tmp_path / "none"))
    expected = f"prsm-health: error: --bag: {tmp_path / 'none'} does not exist\n"
    assert (demo.returncode, demo.stderr) == (2, expected)  # a usage error; it said 1


def test_the_demo_bag_does_not_depend_on_the_working_directory() -> None:
    """``prsm-health demo`` run outside the checkout looked for bags/sudden-jam there."""
    assert DEMO_BAG.is_absolute() and (DEMO_BAG / "metadata.yaml").is_file()


def test_play_waits_out_a_gap_longer_than_a_wait_can_be(ros: None, tmp_path: Path) -> None:
    """Two messages 1e7 s apart at --rate 0.001 are due 1e10 s apart, more than
    threading.TIMEOUT_MAX (9.2e9 s): the player published the first, then ended with an
    OverflowError. It waits in steps instead, until interrupted."""
    first = synthetic_run(0.002)
    stamps = first.stamp_s + np.array([0.0, 1e7])
    samples = MotorSamples(stamps, first.current_a, first.speed_rad_s, first.position_rad)
    bag = write_bag(tmp_path / "bag", samples)
    listener = Listener()
    received: list[float] = []
    qos = QoSProfile(depth=10, reliability=QoSReliabilityPolicy.RELIABLE)
    listener.node.create_subscription(
        MotorState, "/motor_state", lambda m: received.append(stamp_seconds(m.header.stamp)), qos
    )
    player = start_player(bag, "--rate", "0.001")
    try:
        listener.wait_for(lambda: bool(received), 30.0, "the first message")
        listener.spin(1.0)
        assert player.poll() is None, player.communicate()[0]  # waiting for the second
        player.send_signal(signal.SIGINT)
        out, _ = player.communicate(timeout=20)
    finally:
        stop_process(player)
        listener.close()
    assert player.returncode == 130, out  # stopped by Ctrl-C, as the shell reports it
    assert "play interrupted: /motor_state 1 published" in out
    assert received == [stamps[0]]


def test_play_names_the_topics_without_a_subscriber(ros: None, tmp_path: Path) -> None:
    """--wait-for-subscribers waits for every played topic: one nothing reads (as a scene
    bag's /truth/state) makes it fail, and the error says which and how to leave it out."""
    samples = synthetic_run(0.1)
    with BagWriter(tmp_path / "bag") as writer:
        write_motor_states(writer, samples)
        write_joint_states(writer, samples)
    listener = Listener()
    qos = QoSProfile(depth=10, reliability=QoSReliabilityPolicy.RELIABLE)
    listener.node.create_subscription(MotorState, "/motor_state", lambda m: None, qos)
    try:
        waited = cli("play", str(tmp_path / "bag"), "--wait-for-subscribers", "5")
        clocked = cli("play", str(tmp_path / "bag"), "--clock", "--wait-for-subscribers", "5")
    finally:
        listener.close()
    assert waited.returncode == 1
    assert waited.stderr.strip().endswith(
        "no subscriber after 5 s on /joint_states; /motor_state has one:"
        " pass --topics /motor_state to play only the subscribed topics"
    )
    assert clocked.returncode == 1
    assert clocked.stderr.strip().endswith(
        "no subscriber after 5 s on /joint_states, /clock; /motor_state has one:"
        " pass --topics /motor_state to play only the subscribed topics;"
        " drop --clock if no node uses sim time"
    )


def _cut_copy(bag: Path, tmp_path: Path, fraction: float) -> tuple[Path, Path, int]:
    """A copy of the bag directory with its .mcap file cut at ``fraction`` of its length;
    returns the copy, its .mcap file and the length cut to."""
    copy = tmp_path / f"cut-{bag.name}"
    shutil.copytree(bag, copy)
    mcap = next(copy.glob("*.mcap"))
    data = mcap.read_bytes()
    cut = int(len(data) * fraction)
    mcap.write_bytes(data[:cut])
    return copy, mcap, cut


def test_play_plays_a_damaged_bag_up_to_the_damage(ros: None, tmp_path: Path) -> None:
    """A bundled scene bag cut a quarter into its .mcap (inside its second chunk, as a power
    loss leaves a recording): rosbags cannot open it, so play refused it with exit code 2. It
    plays the messages of the complete chunks before the damage with their timing and /clock,
    then names the damage and exits with 1."""
    bag, mcap, cut = _cut_copy(REPO / "bags" / "sudden-jam", tmp_path, 0.25)
    expected = [message for _, _, message in streamed_messages(mcap)]
    topics = ("/motor_state", "/truth/state")
    in_log_time_order = {
        topic: [data for t, _, data in sorted(expected, key=lambda m: m[1]) if t == topic]
        for topic in topics
    }
    counts = {topic: len(payloads) for topic, payloads in in_log_time_order.items()}
    assert 10_000 < len(expected) < 20_000 and all(counts.values())
    listener = Listener()
    received: dict[str, list[bytes]] = {topic: [] for topic in topics}
    clock_ns: list[int] = []
    qos = QoSProfile(depth=50_000, reliability=QoSReliabilityPolicy.RELIABLE)
    for topic, msgtype in ((topics[0], MotorState), (topics[1], GroundTruth)):
        listener.node.create_subscription(msgtype, topic, received[topic].append, qos, raw=True)
    listener.node.create_subscription(
        Clock, "/clock", lambda m: clock_ns.append(m.clock.sec * 10**9 + m.clock.nanosec), qos
    )
    args = ("--rate", "10", "--clock", "--wait-for-subscribers", "20")
    command = [sys.executable, "-m", "prsm_health", "play", str(bag), *args]
    player = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        listener.wait_for(lambda: player.poll() is not None, 60.0, "the player")
        out, err = player.communicate(timeout=20)
        assert player.returncode == 1, out + err
        listener.wait_for(
            lambda: all(len(received[t]) >= n for t, n in counts.items()), 10.0, "every message"
        )
    finally:
        stop_process(player)
        listener.close()
    played = f"/motor_state {counts[topics[0]]}, /truth/state {counts[topics[1]]}"
    assert f"play done: {played} published in 1 pass(es)" in out
    note, warning, error = err.splitlines()
    assert note.startswith(f"note: the scene of {bag} accelerates wear x100000;")
    assert warning == (
        f"prsm-health play: warning: the bag is damaged: the {len(expected)} messages"
        f" before the damage are played ({played})"
    )
    assert error.startswith(
        f"prsm-health play: error: played up to the damage: {mcap}: damaged at byte "
    )
    assert f"file cut at byte {cut}," in error
    assert received == in_log_time_order
    first_ns, last_ns = min(m[1] for m in expected), max(m[1] for m in expected)
    assert clock_ns[0] == first_ns and first_ns < clock_ns[-1] <= last_ns
    assert np.all(np.diff(clock_ns) >= 10**7)  # 100 Hz of bag time, never backwards


def test_play_ends_at_a_corrupt_chunk_of_a_bag_whose_summary_is_intact(tmp_path: Path) -> None:
    """rosbags opens a bag whose summary is intact even if a chunk in the middle is corrupt,
    and fails when it reaches that chunk: play published the messages before it and then died
    with a traceback. The pass now ends there: the damage in one line, exit code 1."""
    copy = tmp_path / "corrupt"
    shutil.copytree(REPO / "bags" / "sudden-jam", copy)
    mcap = next(copy.glob("*.mcap"))
    with mcap.open("rb") as stream:
        chunk = make_reader(stream).get_summary().chunk_indexes[3]
    data = bytearray(mcap.read_bytes())
    middle = chunk.chunk_start_offset + chunk.chunk_length // 2
    data[middle : middle + 4096] = bytes(4096)  # zeros: the zstd frame no longer decodes
    mcap.write_bytes(bytes(data))
    played = cli("play", str(copy), "--rate", "1e6")
    assert played.returncode == 1, played.stdout + played.stderr
    # Read as the replay reads it (since 2026-11-27; rosbags read it until the damage): the
    # damage is known before the first message and named to the byte.
    note, warning, error = played.stderr.splitlines()
    assert note.startswith(f"note: the scene of {copy} accelerates wear x100000;")
    found = re.fullmatch(
        r"prsm-health play: warning: the bag is damaged: the (\d+) messages before the "
        r"damage are played \(.+\)",
        warning,
    )
    assert found, warning
    assert error.startswith(
        f"prsm-health play: error: played up to the damage: {mcap}: damaged at byte "
        f"{chunk.chunk_start_offset}: Chunk record at byte {chunk.chunk_start_offset} does not "
        "decompress"
    ), error
    counts = re.search(r"/motor_state (\d+), /truth/state (\d+) published in 1 pass", played.stdout)
    assert counts and int(counts[1]) + int(counts[2]) == int(found[1]) > 0


def test_play_reads_around_a_summary_rosbags_cannot_decode(tmp_path: Path) -> None:
    """A byte of the summary's channel topic that is not UTF-8: rosbags fails to open the bag
    (UnicodeDecodeError, which play did not catch: exit 2 with the codec's words only), while
    every message is intact in the data section. It is played whole, as the replay reads it
    (with a warning that rosbags was not used until 2026-11-27), and exits 0."""
    bag = write_bag(tmp_path / "bag", synthetic_run(0.1))
    mcap = next(bag.glob("*.mcap"))
    data = bytearray(mcap.read_bytes())
    footer = len(data) - (9 + 20 + 8)
    summary_start = int.from_bytes(data[footer + 9 : footer + 17], "little")
    topic = data.index(b"/motor_state", summary_start)
    data[topic] = 0x82
    mcap.write_bytes(bytes(data))
    played = cli("play", str(bag), "--rate", "5")
    assert played.returncode == 0, played.stdout + played.stderr
    assert "play done: /motor_state 100 published in 1 pass(es)" in played.stdout
    assert played.stderr == ""


def test_play_refuses_what_a_damaged_bag_does_not_have(tmp_path: Path) -> None:
    """Nothing before the damage: an error naming it, exit 1, nothing published, also for a
    topic the bag's metadata.yaml declares; a topic neither declared nor seen before the
    damage: the usage error, naming the damage; a bag cut after its data section: every
    message played, then the damage and exit 1, after one pass with --loop too."""
    bag = write_bag(tmp_path / "bag", synthetic_run(0.1))
    empty, mcap, _ = _cut_copy(bag, tmp_path / "empty", 0.5)  # inside its only chunk
    nothing = cli("play", str(empty))
    assert (nothing.returncode, nothing.stdout) == (1, "")
    assert nothing.stderr.startswith(
        f"prsm-health play: error: nothing to play before the damage of the bag: {mcap}:"
        " damaged at byte "
    )
    looped = cli("play", str(empty), "--loop")
    assert looped.returncode == 1 and "nothing to play before the damage" in looped.stderr
    declared = cli("play", str(empty), "--topics", "/motor_state")
    assert declared.returncode == 1 and "nothing to play before the damage" in declared.stderr
    summary, mcap, _ = _cut_copy(bag, tmp_path / "summary", 0.9)
    unknown = cli("play", str(summary), "--topics", "/nope")
    assert unknown.returncode == 2
    assert unknown.stderr.startswith(
        "prsm-health: error: no topic /nope in the bag's metadata or before its damage;"
        f" topics known: /motor_state (the bag is damaged: {mcap}: damaged at byte "
    )
    for loop in ((), ("--loop",)):
        whole = cli("play", str(summary), "--rate", "5", *loop)
        assert whole.returncode == 1
        assert "play done: /motor_state 100 published in 1 pass(es)" in whole.stdout
        assert "every message in it was read" in whole.stderr.splitlines()[-1]


def test_play_publishes_every_message(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "bag", synthetic_run(0.5))
    done = cli("play", str(bag), "--rate", "5", "--clock")
    assert done.returncode == 0, done.stderr
    assert "play done: /motor_state 500 published in 1 pass(es)" in done.stdout


def test_play_loops_until_interrupted(ros: None, tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "bag", synthetic_run(0.2))
    listener = Listener()
    received: list[float] = []
    qos = QoSProfile(depth=1000, reliability=QoSReliabilityPolicy.RELIABLE)
    listener.node.create_subscription(
        MotorState, "/motor_state", lambda m: received.append(stamp_seconds(m.header.stamp)), qos
    )
    player = start_player(bag, "--loop", "--rate", "4")
    try:
        listener.wait_for(lambda: len(received) >= 600, 30.0, "three passes")
        player.send_signal(signal.SIGINT)
        out, _ = player.communicate(timeout=20)
    finally:
        stop_process(player)
        listener.close()
    assert player.returncode == 130
    match = re.search(r"play interrupted: /motor_state (\d+) published in (\d+) pass", out)
    assert match, out
    published, passes = int(match[1]), int(match[2])
    assert passes >= 3
    assert 200 * (passes - 1) <= published <= 200 * passes
    assert received[:200] == received[200:400]  # the same stamps again: a loop, not a shift


@pytest.mark.timeout(180)
def test_play_faster_than_a_reliable_node_loses_nothing(ros: None, tmp_path: Path) -> None:
    """15,000 messages at --rate 50 (50 kHz) into a node with reliable input, stopped
    (SIGSTOP) for 1 s once it has received 2,000: the play is held back (still running when
    the node goes on) and every message arrives.

    With a keep-last history of 10,000 the player overwrote what the node had not yet taken:
    a node fed the 60,000 of sudden-jam at --rate 10 received 25,474 and counted one jammed
    roller of two, and the play, which waits only for what its history still holds, exited 0.
    With keep-all, Fast DDS holds 5,000 unacknowledged messages; a write beyond blocks 100 ms
    and fails, which ended the play with an RCLError (in CI, a node 100 ms behind under load)
    until the player wrote it again. 15,000 exceeds the 2,000 received before the stop plus
    either depth (10,000 kept last, 5,000 held unacknowledged): such a history would lose
    messages here, and keep-all must hold the play back. (40,000 until 2026-11-29: 35 s.)
    The node then needs 5.4-11.6 s for the last 5,000: at the end the player waited 10 s
    until 2026-11-29 and failed one run in three (player.FINAL_ACK_TIMEOUT_S)."""
    count = 15_000
    bag = write_bag(tmp_path / "bag", synthetic_run(count / 1000.0, from_rest=False, seed=5))
    listener = Listener("fast")

    def received() -> int:
        inputs = listener.statuses("fast").get(INPUT_HEALTH)
        return int(inputs["values"]["received"]) if inputs else 0

    try:
        with NodeProcess(
            tmp_path,
            "fast",
            hardware_id="fast",
            input_qos="reliable",
            state_file=str(tmp_path / "state.json"),
            diagnostics_rate_hz=20.0,
        ) as node:
            player = start_player(bag, "--rate", "50")
            try:
                listener.wait_for(lambda: received() >= 2000, 60.0, "2000 received")
                node.process.send_signal(signal.SIGSTOP)
                time.sleep(1.0)
                held_back = player.poll() is None
                node.process.send_signal(signal.SIGCONT)
                out, _ = player.communicate(timeout=150)
            finally:
                node.process.send_signal(signal.SIGCONT)
                stop_process(player)
            assert player.returncode == 0, out
            assert held_back, out
            listener.wait_for(lambda: received() == count, 30.0, f"{count} received")
    finally:
        listener.close()


def _play_into_a_stopped_node(tmp_path: Path, seconds: float, rate: str) -> tuple[int, str, float]:
    """A bag of ``seconds`` at 1 kHz played at ``rate`` into a node subscribing reliably, which
    is stopped (SIGSTOP) once its diagnostics say it has received the player's messages (frozen
    earlier, it might not match the player at all: the player then owes it nothing and exits
    0; seen in CI when a publisher of an earlier test still counted on the graph). Returns
    the player's exit code, its output and how long it ran on after the stop [s]."""
    bag = write_bag(tmp_path / "bag", synthetic_run(seconds))
    graph = Listener()

    def received() -> int:
        inputs = graph.statuses(HARDWARE_ID).get(INPUT_HEALTH)
        return int(inputs["values"]["received"]) if inputs else 0

    try:
        with NodeProcess(
            tmp_path,
            hardware_id=HARDWARE_ID,
            input_qos="reliable",
            diagnostics_rate_hz=20.0,
            state_file=str(tmp_path / "state.json"),
        ) as node:
            graph.wait_for(lambda: bool(graph.statuses(HARDWARE_ID)), 30.0, "the node")
            player = start_player(bag, "--rate", rate)
            try:
                graph.wait_for(lambda: received() >= 100, 30.0, "the node receiving the bag")
                node.process.send_signal(signal.SIGSTOP)
                stopped = time.monotonic()
                out, _ = player.communicate(timeout=90)
                return player.returncode, out, time.monotonic() - stopped
            finally:
                node.process.send_signal(signal.SIGCONT)
                stop_process(player)
    finally:
        graph.close()


@pytest.mark.timeout(120)
def test_play_ends_when_a_reliable_subscriber_takes_nothing(ros: None, tmp_path: Path) -> None:
    """The node is stopped early in a bag of 8,000 messages, more than the 5,000 Fast DDS
    holds for it unacknowledged: the play, held back, waits ACK_TIMEOUT_S for it to take one,
    then exits 1 naming the topic and what was published."""
    returncode, out, waited_s = _play_into_a_stopped_node(tmp_path, 8.0, rate="5")
    assert returncode == 1, out
    assert waited_s > ACK_TIMEOUT_S, out
    match = re.search(
        rf"prsm-health play: error: /motor_state: no message taken by its reliable subscribers"
        rf" for {ACK_TIMEOUT_S:g} s after (\d+) published \(is a subscriber stopped\?\)",
        out,
    )
    assert match, out
    assert 5000 <= int(match[1]) < 8000, out  # at least the 5,000 held for the node


def test_play_names_what_a_reliable_subscriber_did_not_acknowledge(
    ros: None, tmp_path: Path
) -> None:
    """The node is stopped while a bag of 3,000 messages plays (all of them fit in what Fast
    DDS holds for it): its DDS threads acknowledge nothing more. The player waits at the end
    (at most FINAL_ACK_TIMEOUT_S), names the topic, exits 1. Fast DDS drops the stopped node
    from the match when its lease runs out (20 s after the stop), and the wait then ends as
    if it had acknowledged: the player says it left instead (with a 30 s wait and no such
    check the play reported the 3,000 messages taken)."""
    returncode, out, waited_s = _play_into_a_stopped_node(tmp_path, 3.0, rate="1")
    assert returncode == 1, out
    assert waited_s > ACK_TIMEOUT_S, out
    assert "play done: /motor_state 3000 published" in out
    assert (
        f"not acknowledged by every reliable subscriber within {FINAL_ACK_TIMEOUT_S:g} s, or one"
        " left" in out
    )
    assert out.rstrip().endswith("/motor_state (messages may be lost)")


def test_monitor_times_out_without_a_node() -> None:
    done = cli("monitor", "--node", "nobody", "--count", "1", "--timeout", "0.5")
    assert done.returncode == 1
    assert done.stderr == (
        "prsm-health monitor: nothing received on /nobody/health or /diagnostics within 0.5 s:"
        " is the node running, under this name, with the same ROS_DOMAIN_ID?\n"
    )


def test_monitor_refuses_an_invalid_node_name() -> None:
    done = cli("monitor", "--node", "bad name", "--timeout", "0.5")
    assert done.returncode == 2
    assert done.stderr == (
        "prsm-health: error: --node 'bad name' is not a node name such as /prsm_health:"
        " must not contain characters other than alphanumerics, '_', or '/'\n"
    )


def test_play_takes_the_bounds_of_its_rates() -> None:
    """Pins that --rate and --clock-rate take both bounds their error message names (within
    0.001 .. 1e+06, 0.01 .. 1e+09). A mutation review found them unguarded (exclusive bounds
    refused --rate 1e6)."""
    for rate in RATE_RANGE:
        assert PlayOptions(rate=rate).rate == rate
    for clock_rate in CLOCK_RATE_RANGE:
        assert PlayOptions(clock=True, clock_rate_hz=clock_rate).clock_rate_hz == clock_rate


def test_monitor_takes_a_node_name_with_a_trailing_slash() -> None:
    """Pins that --node prsm_health/ listens to /prsm_health/health. A mutation review found
    the trailing slash's removal unguarded (kept, the name was refused as invalid)."""
    assert MonitorOptions(node="prsm_health/").health_topic == "/prsm_health/health"


def test_monitor_says_what_was_missing(ros: None) -> None:
    """Received, but not enough printed: the count, that no status came to print, or that
    the node did not tell its hardware_id (which says which statuses are its)."""
    counted = Monitor(MonitorOptions(count=3, timeout_s=2.0, hardware_id="left"))
    listed = Monitor(MonitorOptions(timeout_s=2.0))
    try:
        counted.records = counted.health_received = 1
        counted.timed_out = listed.timed_out = True
        assert counted.shortfall() == "1 of 3 records printed within 2 s"
        listed.health_received = 4  # in table mode only a status prints a record
        assert listed.shortfall() == (
            "estimates received within 2 s, but /prsm_health did not tell its hardware_id"
            " (--hardware-id ID shows the statuses of ID)"
        )
        listed.hardware_id = "left"
        assert listed.shortfall() == (
            "estimates received within 2 s, but no prsm_health statuses of hardware_id left"
            " on /diagnostics"
        )
        # A mistyped --hardware-id looked like no node at all ("is the node running?").
        mistyped = Monitor(MonitorOptions(timeout_s=2.0, hardware_id="Left"))
        status = DiagnosticStatus(name=INPUT_HEALTH, hardware_id="left", message="ok")
        mistyped._on_diagnostics(DiagnosticArray(status=[status]))
        mistyped.timed_out = True
        assert mistyped.shortfall() == (
            "no status of hardware_id 'Left' on /diagnostics within 2 s; statuses came for"
            " 'left' (--hardware-id)"
        )
        mistyped.close()
    finally:
        counted.close()
        listed.close()


@pytest.mark.timeout(180)
def test_monitor_shows_only_the_nodes_statuses(tmp_path: Path) -> None:
    """Two nodes publish /diagnostics: the monitor of one showed the other's statuses too
    and counted them. It shows those of the node's hardware_id, which it asks the node."""
    nodes = {
        name: NodeProcess(
            tmp_path,
            name=name,
            hardware_id=hardware_id,
            state_file=str(tmp_path / f"{hardware_id}.json"),
            input_topic=f"/{hardware_id}/motor_state",
            diagnostics_rate_hz=5.0,
        )
        for name, hardware_id in (("mon_a", "left"), ("mon_b", "right"))
    }
    try:
        args = ("monitor", "--node", "/mon_a", "--json", "--count", "6", "--timeout", "90")
        done = cli(*args, timeout_s=120.0)
    finally:
        for node in nodes.values():
            stop_process(node.process)
    assert done.returncode == 0, done.stderr
    records = [json.loads(line) for line in done.stdout.splitlines()]
    assert [r["topic"] for r in records] == ["/diagnostics"] * 6
    assert {s["hardware_id"] for r in records for s in r["status"]} == {"left"}
    for record in records:  # each status once: no other node's in the same record
        assert len({s["name"] for s in record["status"]}) == len(record["status"]) == 7


@pytest.mark.timeout(120)
def test_monitor_shows_a_failed_configure(tmp_path: Path) -> None:
    """A node whose configure failed published nothing: the monitor said "nothing received
    ... is the node running?". It shows the node's configuration status, in the table under
    a first line that says the node is not configured, and as it is in JSON."""
    with NodeProcess(
        tmp_path,
        "mon_failed",
        hardware_id="failed",
        state_file=str(tmp_path / "state.json"),
        diagnostics_rate_hz=5,  # an integer for a double
    ) as node:
        node.wait_log("configure failed")
        args = ("monitor", "--node", "/mon_failed", "--count", "1", "--timeout", "30")
        shown = cli(*args, timeout_s=90.0)
        as_json = cli(*args, "--json", timeout_s=90.0)
    assert (shown.returncode, shown.stderr) == (0, "")
    reason = "configure failed: parameter diagnostics_rate_hz: refused by ROS: "
    assert shown.stdout.splitlines()[0] == NOT_CONFIGURED
    assert shown.stdout.splitlines()[1].startswith(f"  ERROR configuration      {reason}")
    assert (as_json.returncode, as_json.stderr) == (0, "")
    (status,) = json.loads(as_json.stdout)["status"]
    assert (status["name"], status["level"]) == (CONFIGURATION, "ERROR")
    assert status["hardware_id"] == "failed" and status["message"].startswith(reason)


def test_monitor_shows_foreign_messages_as_they_are(ros: None) -> None:
    """A default HealthEstimate (no probabilities; ``ros2 topic pub`` sends one) was an
    IndexError traceback, a status level 7 the usage error '7 is not a valid Level': both
    are shown as what they are. The other hardware id's status is not shown; a monitor
    without --hardware-id says this node has no hardware_id parameter."""
    name = f"foreign_{uuid.uuid4().hex[:8]}"
    node = rclpy.create_node(name)
    qos = QoSProfile(depth=10, reliability=QoSReliabilityPolicy.RELIABLE)
    health = node.create_publisher(HealthEstimate, f"/{name}/health", qos)
    diagnostics = node.create_publisher(DiagnosticArray, "/diagnostics", qos)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    statuses = [
        DiagnosticStatus(
            name="prsm_health: axial load", level=b"\x07", message="odd", hardware_id="odd"
        ),
        DiagnosticStatus(name="prsm_health: fatigue", message="other", hardware_id="other"),
    ]
    command = [sys.executable, "-m", "prsm_health", "monitor", "--node", name, "--count"]
    shown = subprocess.Popen(
        [*command, "5", "--timeout", "60", "--hardware-id", "odd"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    asked = None
    try:
        deadline = time.monotonic() + 90.0
        # The second monitor starts once the first one's subscriptions are matched: its own
        # made the publishing start while the first one saw only the diagnostics (a CI run
        # printed three records, each "no estimate received").
        while asked is None and shown.poll() is None and time.monotonic() < deadline:
            if health.get_subscription_count() and diagnostics.get_subscription_count():
                asked = subprocess.Popen(
                    [*command, "1", "--timeout", "15"],
                    stdout=subprocess.PIPE,
                    stderr=subprocess.PIPE,
                    text=True,
                )
            executor.spin_once(timeout_sec=0.2)
        assert asked is not None, "the first monitor never subscribed"
        while None in (shown.poll(), asked.poll()) and time.monotonic() < deadline:
            if health.get_subscription_count() and diagnostics.get_subscription_count():
                health.publish(HealthEstimate())
                diagnostics.publish(DiagnosticArray(status=statuses))
            executor.spin_once(timeout_sec=0.2)
        out, err = shown.communicate(timeout=20)
        asked_out, asked_err = asked.communicate(timeout=20)
    finally:
        stop_process(shown)
        if asked is not None:
            stop_process(asked)
        executor.shutdown()
        node.destroy_node()
    assert (shown.returncode, err) == (0, "")
    assert out.splitlines()[-2:] == [
        "t 0.00 s  load 0.00 ± 0.00 kN  jammed 0 (no probabilities)  loss 0 um (0 um/h)  fatigue 0",
        "  level 7 (unknown) axial load         odd",
    ]
    assert "other" not in out  # the status of the other hardware id
    assert (asked.returncode, asked_out) == (1, "")
    assert asked_err == (
        f"prsm-health monitor: 0 of 1 records printed within 15 s, but /{name} has no"
        " hardware_id parameter (--hardware-id ID shows the statuses of ID)\n"
    )


def test_monitor_table() -> None:
    health = {
        "stamp": 12.5,
        "axial_load_n": 30500.0,
        "axial_load_std_n": 250.0,
        "jammed_rollers_most_likely": 1,
        "jammed_rollers_probability": [0.02, 0.97, 0.01],
        "precision_loss_um": 1.25,
        "precision_loss_rate_um_per_h": 3.5,
        "fatigue_damage": 0.001,
    }
    status = {
        "name": "prsm_health: jammed rollers",
        "level": Level.ERROR.name,
        "message": "1 jammed roller (p = 0.97)",
    }
    text = table(health, {"status": [status]})
    assert text.splitlines() == [
        "t 12.50 s  load 30.50 ± 0.25 kN  jammed 1 (p 0.97)  loss 1.25 um (3.5 um/h)"
        "  fatigue 0.001",
        "  ERROR jammed rollers     1 jammed roller (p = 0.97)",
    ]
    assert table(None, {"status": []}) == (  # the node may have estimated before
        "no estimate received since the monitor started (the node publishes one per new estimate)"
    )
    failed = {"name": CONFIGURATION, "level": "ERROR", "message": "configure failed: x"}
    assert table(health, {"status": [failed]}).splitlines() == [  # the estimate is an old one
        NOT_CONFIGURED,
        "  ERROR configuration      configure failed: x",
    ]


def test_monitor_table_of_odd_messages() -> None:
    """Values the node never publishes (another publisher's) are shown, not refused."""
    health = {
        "stamp": 1.0,
        "axial_load_n": 0.0,
        "axial_load_std_n": 0.0,
        "jammed_rollers_most_likely": 2,
        "jammed_rollers_probability": [0.5, 0.5],
        "precision_loss_um": 0.0,
        "precision_loss_rate_um_per_h": 0.0,
        "fatigue_damage": 0.0,
    }
    assert "jammed 2 (no probability of 2)" in table(health, {"status": []})
    health["jammed_rollers_probability"] = []
    assert "jammed 2 (no probabilities)" in table(health, {"status": []})
    levels = [b"\x00", b"\x03", b"\x04", b"\xff"]
    array = DiagnosticArray(
        status=[DiagnosticStatus(name="prsm_health: x", level=v) for v in levels]
    )
    assert [s["level"] for s in diagnostics_record(array)["status"]] == [
        "OK",
        "STALE",
        "level 4 (unknown)",
        "level 255 (unknown)",
    ]


@pytest.mark.timeout(120)
def test_demo_runs_node_player_and_monitor(tmp_path: Path) -> None:
    bag = simulated_bag(tmp_path / "jam", short_jam_scene(8.0))
    done = cli(
        "demo",
        "--bag",
        str(bag),
        "--rate",
        "4",
        "--workdir",
        str(tmp_path / "demo"),
        timeout_s=100.0,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    out = done.stdout
    assert "loopback only" in out
    assert "ERROR jammed rollers     1 jammed roller" in out  # the live table
    summary = out[out.index("summary at bag time") :]
    assert "jammed rollers  1 most likely" in summary
    assert "truth           " in summary and "1 jammed" in summary  # from /truth/state
    assert "axial load" in summary and "precision loss" in summary
    assert "ERROR prsm_health: jammed rollers: 1 jammed roller" in summary
    # The diagnostics shown are the first after the bag's end: they count every sample the
    # estimate counts (those at the player's end missed the last ones), and are not STALE.
    accepted = re.search(r"\((\d+) samples accepted", summary)
    received = re.search(r"input health: .*, 0 rejected of (\d+) received", summary)
    assert accepted and received and received[1] == accepted[1], summary
    # The speed noise the node's estimator measured in motion: the scene's drive differences
    # a 4096-count encoder (docs/performance.md, "The drive's sensors").
    noise = re.search(
        r"input health: .* received, speed noise (\d+\.\d+) rad/s, position per speed "
        r"(\d+\.\d+)",
        summary,
    )
    assert noise and 0.4 < float(noise[1]) < 0.55, summary
    assert float(noise[2]) == 1.0, summary  # the scene's position and speed agree
    assert "STALE" not in summary
    # Which estimate the statuses report (they showed another load than the line above).
    assert re.search(r"\ndiagnostics of the estimate at bag time \d+\.\d{3} s:\n", summary)
    assert (tmp_path / "demo" / "node.log").read_text().count("configured") == 1
    assert (tmp_path / "demo" / "state.json").is_file()  # saved at the node's shutdown
