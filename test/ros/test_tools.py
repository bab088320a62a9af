"""prsm-health play, monitor and demo from the command line (real processes)."""

from __future__ import annotations

import re
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from prsm_health_msgs.msg import MotorState
from rclpy.qos import QoSProfile, QoSReliabilityPolicy

from prsm_health.bags.writer import BagWriter, write_joint_states, write_motor_states
from prsm_health.outputs import INPUT_HEALTH, Level
from prsm_health.ros.messages import stamp_seconds
from prsm_health.ros.monitor import Monitor, MonitorOptions, table
from prsm_health.ros.player import ACK_TIMEOUT_S
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


def test_play_refuses_what_it_cannot_play(tmp_path: Path) -> None:
    """Input errors exit with 2 (usage, as replay's), failures while playing with 1."""
    missing = cli("play", str(tmp_path / "none"))
    assert missing.returncode == 2
    assert f"cannot open bag {tmp_path / 'none'}" in missing.stderr
    bag = write_bag(tmp_path / "bag", synthetic_run(0.1))
    cut = tmp_path / "cut"
    shutil.copytree(bag, cut)
    mcap = next(cut.glob("*.mcap"))
    mcap.write_bytes(mcap.read_bytes()[:-100])
    damaged = cli("play", str(cut))
    assert damaged.returncode == 2
    assert "read up to the damage by prsm-health replay" in damaged.stderr
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
    assert player.returncode == 0
    match = re.search(r"play interrupted: /motor_state (\d+) published in (\d+) pass", out)
    assert match, out
    published, passes = int(match[1]), int(match[2])
    assert passes >= 3
    assert 200 * (passes - 1) <= published <= 200 * passes
    assert received[:200] == received[200:400]  # the same stamps again: a loop, not a shift


def test_play_names_what_a_reliable_subscriber_did_not_acknowledge(
    ros: None, tmp_path: Path
) -> None:
    """A node subscribing reliably is frozen (SIGSTOP) while the bag plays: its DDS threads
    acknowledge nothing more, so the player waits ACK_TIMEOUT_S, names the topic, exits 1.

    The node is frozen once its diagnostics say it has received the player's messages: frozen
    earlier, it might not match the player at all (the player then owes it nothing and exits
    0; seen in CI when a publisher of an earlier test still counted on the graph)."""
    bag = write_bag(tmp_path / "bag", synthetic_run(3.0))
    graph = Listener()

    def received() -> int:
        inputs = graph.statuses(HARDWARE_ID).get(INPUT_HEALTH)
        return int(inputs["values"]["received"]) if inputs else 0

    try:
        with NodeProcess(
            tmp_path,
            hardware_id=HARDWARE_ID,
            input_qos="reliable",
            input_queue_depth=10_000,
            diagnostics_rate_hz=20.0,
        ) as node:
            graph.wait_for(lambda: bool(graph.statuses(HARDWARE_ID)), 30.0, "the node")
            player = start_player(bag, "--rate", "1")
            try:
                graph.wait_for(lambda: received() >= 100, 30.0, "the node receiving the bag")
                node.process.send_signal(signal.SIGSTOP)
                out, _ = player.communicate(timeout=60)
            finally:
                node.process.send_signal(signal.SIGCONT)
                stop_process(player)
    finally:
        graph.close()
    assert player.returncode == 1, out
    assert "play done: /motor_state 3000 published" in out
    assert f"not acknowledged by every reliable subscriber within {ACK_TIMEOUT_S:g} s" in out
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


def test_monitor_says_what_was_missing(ros: None) -> None:
    """Received, but not enough printed: the count, or that no status came to print."""
    counted = Monitor(MonitorOptions(count=3, timeout_s=2.0))
    listed = Monitor(MonitorOptions(timeout_s=2.0))
    try:
        counted.records = counted.health_received = 1
        counted.timed_out = listed.timed_out = True
        assert counted.shortfall() == "1 of 3 records printed within 2 s"
        listed.health_received = 4  # in table mode only a status prints a record
        expected = "estimates received within 2 s, but no prsm_health statuses on /diagnostics"
        assert listed.shortfall() == expected
    finally:
        counted.close()
        listed.close()


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
        "t 12.50 s  load 30.50 +- 0.25 kN  jammed 1 (p 0.97)  loss 1.25 um (3.5 um/h)"
        "  fatigue 0.001",
        "  ERROR jammed rollers     1 jammed roller (p = 0.97)",
    ]
    assert table(None, {"status": []}) == (  # the node may have estimated before
        "no estimate received since the monitor started (the node publishes one per new estimate)"
    )


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
    assert (tmp_path / "demo" / "node.log").read_text().count("configured") == 1
    assert (tmp_path / "demo" / "state.json").is_file()  # saved at the node's shutdown
