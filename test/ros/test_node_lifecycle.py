"""Lifecycle and parameters with real processes: bad values refused by name, inactive silent."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from builtin_interfaces.msg import Time
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterValue
from rcl_interfaces.srv import SetParameters, SetParametersAtomically
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, QoSReliabilityPolicy
from rosgraph_msgs.msg import Clock

from prsm_health.outputs import CONFIGURATION, INPUT_HEALTH
from prsm_health.ros.node import LogThrottle
from prsm_health.ros.parameters import PARAMETERS
from test.ros.harness import Listener, NodeProcess, stop_process


@pytest.mark.timeout(60)
def test_invalid_parameters_fail_configure_by_name(ros: None, tmp_path: Path) -> None:
    listener = Listener("bad_params")
    try:
        with NodeProcess(
            tmp_path,
            "bad_params",
            hardware_id="bad_params",
            state_file=str(tmp_path / "state.json"),
            health_rate_hz=-1.0,
            input_type="bogus",
            diagnostics_rate_hz=5,  # an integer for a double
        ) as node:
            node.wait_log("configure failed")
            log = node.log()
            assert "parameter health_rate_hz" in log and "out of range" in log
            assert "parameter input_type: must be one of motor_state, joint_state" in log
            assert "parameter diagnostics_rate_hz" in log and "INTEGER" in log
            assert node.alive()
            assert listener.lifecycle_state() == "unconfigured"
            # A refused atomic set changes nothing: health_rate_hz's error from the start
            # (ROS kept the default) is still reported at the next configure.
            atomic = SetParametersAtomically.Request(
                parameters=[
                    Parameter("health_rate_hz", value=0.0).to_parameter_msg(),
                    Parameter("input_type", value="can_bus").to_parameter_msg(),
                ]
            )
            service = "set_parameters_atomically"
            assert not listener.call(SetParametersAtomically, service, atomic).result.successful
            assert not listener.transition("configure")  # still refused, nothing changed
            listener.wait_for(
                lambda: node.log().count("parameter health_rate_hz") == 2,
                5.0,
                "health_rate_hz named by the second configure",
            )

            # Fixed through the lifecycle, without a restart.
            assert listener.set_parameter("health_rate_hz", 0.0) == (True, "")
            assert listener.set_parameter("input_type", "motor_state") == (True, "")
            ok, reason = listener.set_parameter("input_type", "can_bus")
            assert not ok and "parameter input_type: must be one of" in reason
            assert listener.set_parameter("diagnostics_rate_hz", 5.0) == (True, "")
            assert listener.transition("configure")
            assert listener.lifecycle_state() == "inactive"
            ok, reason = listener.set_parameter("hardware_id", "other")
            assert not ok and "applied at configure" in reason
            # The diagnostics' clock too (it was switched: every input age jumped by decades).
            ok, reason = listener.set_parameter("use_sim_time", True)
            assert not ok and "use_sim_time is applied at configure" in reason
            assert listener.transition("activate")
            listener.wait_for(
                lambda: INPUT_HEALTH in listener.statuses("bad_params"), 5.0, "diagnostics"
            )
    finally:
        listener.close()


@pytest.mark.timeout(60)
def test_inactive_node_publishes_nothing(ros: None, tmp_path: Path) -> None:
    listener = Listener("lifecycle")

    def published() -> int:
        return len(listener.statuses_of("lifecycle")) + len(listener.health)

    try:
        with NodeProcess(
            tmp_path,
            "lifecycle",
            hardware_id="lifecycle",
            state_file=str(tmp_path / "state.json"),
            autostart=False,
            diagnostics_rate_hz=20.0,
        ) as node:
            node.wait_log("autostart is false")
            assert listener.lifecycle_state() == "unconfigured"
            listener.spin(2.0)  # waiting is no failed configure: nothing to report
            assert published() == 0
            # A transition the state does not have is refused; rclpy 7.1 raised out of the
            # executor and ended the node (ros2/rclpy#1209).
            assert not listener.transition("deactivate")
            node.wait_log("lifecycle transition 4 refused: not available in state unconfigured")
            assert node.alive() and listener.lifecycle_state() == "unconfigured"
            assert listener.transition("configure")
            assert listener.lifecycle_state() == "inactive"
            listener.spin(1.0)  # 20 diagnostics if it were active
            assert published() == 0
            subscribers = listener.node.get_subscriptions_info_by_topic("/motor_state")
            assert not [s for s in subscribers if s.node_name == "lifecycle"]

            assert listener.transition("activate")
            listener.wait_for(lambda: published() > 0, 5.0, "diagnostics once active")
            assert listener.node.get_subscriptions_info_by_topic("/motor_state")

            assert listener.transition("deactivate")
            for _ in range(10):  # what was already on the way (it may come late under load)
                count = published()
                listener.spin(0.3)
                if published() == count:
                    break
            listener.spin(1.0)
            assert published() == count  # 20 diagnostics a second if it still published
            assert listener.transition("cleanup")
            assert listener.lifecycle_state() == "unconfigured"
            assert node.alive()

            # Shut down over the lifecycle service; SIGINT then ends the process cleanly
            # (rclpy raises on a second shutdown transition: exit code 1 and a traceback).
            assert listener.transition("shutdown")
            assert listener.lifecycle_state() == "finalized"
            assert stop_process(node.process) == 0
            assert "Traceback" not in node.log()
    finally:
        listener.close()


def _configure_failures(log: str) -> list[str]:
    """The reasons of the node's "configure failed" log lines, in order."""
    return [
        line.split("configure failed: ", 1)[1]
        for line in log.splitlines()
        if "configure failed: " in line
    ]


@pytest.mark.timeout(90)
def test_a_failed_configure_is_reported_on_diagnostics(ros: None, tmp_path: Path) -> None:
    """A node whose configure failed published nothing: a monitor said "is the node running?".
    It reports the failure on /diagnostics about once a second (under its hardware_id as given,
    valid or not: what the monitor asks for), the latest reason, until a configure succeeds."""
    typo = tmp_path / "typo.yaml"
    typo.write_text("actuator: {preset: dong2022-downhole, wear_acceleraton: 2.0}\n")
    listener = Listener("cfg_failed")

    def failures(hardware_id: str) -> list[dict[str, object]]:
        statuses = listener.statuses_of(hardware_id)
        return [s[CONFIGURATION] for s in statuses if CONFIGURATION in s]

    try:
        with NodeProcess(
            tmp_path,
            "cfg_failed",
            hardware_id="bad id",
            params_file=str(typo),
            state_file=str(tmp_path / "state.json"),
        ) as node:
            node.wait_log("configure failed")
            listener.wait_for(lambda: bool(failures("bad id")), 10.0, "the failure")
            (reason,) = _configure_failures(node.log())
            assert reason.startswith("parameter hardware_id: must match")
            status = failures("bad id")[-1]
            assert status["level"] == "ERROR"
            assert status["message"] == f"configure failed: {reason}"
            count, started = len(failures("bad id")), time.monotonic()
            listener.wait_for(lambda: len(failures("bad id")) >= count + 3, 10.0, "three more")
            # About once a second: three more take two seconds (one may have been on its way).
            assert time.monotonic() - started >= 1.0

            assert listener.set_parameter("hardware_id", "cfg_failed") == (True, "")
            assert not listener.transition("configure")
            listener.wait_for(lambda: bool(failures("cfg_failed")), 10.0, "the new failure")
            reason = _configure_failures(node.log())[-1]
            assert "parameter params_file: " in reason and "wear_acceleraton: unknown" in reason
            assert failures("cfg_failed")[-1]["message"] == f"configure failed: {reason}"

            good = tmp_path / "good.yaml"
            good.write_text("actuator: {preset: dong2022-downhole, wear_acceleration: 2.0}\n")
            assert listener.set_parameter("params_file", str(good)) == (True, "")
            assert listener.transition("configure")
            configured_at = time.time()  # the node's clock: the system's
            listener.spin(2.0)
            # Configured, inactive: silent (what was on its way is stamped before).
            assert [d["stamp"] for d in listener.diagnostics if d["stamp"] > configured_at] == []
            assert listener.transition("activate")
            listener.wait_for(
                lambda: INPUT_HEALTH in listener.statuses("cfg_failed"), 5.0, "diagnostics"
            )
            assert CONFIGURATION not in listener.statuses("cfg_failed")
    finally:
        listener.close()


@pytest.mark.timeout(60)
def test_a_misspelt_parameter_fails_configure_by_name(ros: None, tmp_path: Path) -> None:
    """A value given at start for a parameter nobody declared left the default in place
    without a word."""
    with NodeProcess(
        tmp_path,
        "misspelt",
        hardware_id="misspelt",
        state_file=str(tmp_path / "state.json"),
        input_topc="/left/motor_state",
    ) as node:
        node.wait_log("configure failed")
        assert "input_topc: unknown parameter (did you mean input_topic?)" in node.log()
        assert node.alive()


@pytest.mark.parametrize("flag", ["--help", "-h"])
def test_help_lists_every_parameter_and_exits_0(flag: str) -> None:
    """--help was an "unexpected argument" with exit code 2."""
    command = [sys.executable, "-m", "prsm_health.ros.node", flag]
    result = subprocess.run(command, capture_output=True, text=True, timeout=60, check=False)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("usage: prsm-health-node [--ros-args -p NAME:=VALUE ...]")
    for spec in PARAMETERS:
        assert f"\n  {spec.name} = " in result.stdout


@pytest.mark.parametrize(
    ("ros_args", "problem"),
    [
        (["-p", "hardware_id"], "Failed to parse ROS arguments: "),
        # rclpy's UnknownROSArgsError was a traceback and exit code 1.
        (["-p", "diagnostics_rate_hz:=5.0", "--garbage"], "unknown ROS arguments ['--garbage']"),
    ],
)
def test_malformed_ros_arguments_are_one_line_and_exit_2(ros_args: list[str], problem: str) -> None:
    command = [sys.executable, "-m", "prsm_health.ros.node", "--ros-args", *ros_args]
    result = subprocess.run(command, capture_output=True, text=True, timeout=60, check=False)
    assert result.returncode == 2, result.stderr
    assert result.stderr.startswith(f"prsm-health-node: invalid --ros-args: {problem}")
    assert result.stderr.count("\n") == 1 and "Traceback" not in result.stderr


@pytest.mark.timeout(90)
@pytest.mark.parametrize("second_after_s", [0.02, 0.05, 0.1])
def test_a_second_signal_during_shutdown_keeps_the_clean_exit(
    ros: None, tmp_path: Path, second_after_s: float
) -> None:
    """Ctrl-C twice: the state is saved and the node exits 0 (a second SIGINT during rclpy's
    shutdown ended the process by the signal, exit code -2, hiding a failed save's 1)."""
    state_file = tmp_path / "state.json"
    with NodeProcess(tmp_path, hardware_id="twice", state_file=str(state_file)) as node:
        node.wait_log("configured")
        node.process.send_signal(signal.SIGINT)
        time.sleep(second_after_s)
        assert stop_process(node.process, signal.SIGINT) == 0, node.log()
    assert state_file.exists()


@pytest.mark.timeout(60)
def test_a_malformed_clock_or_parameter_message_costs_the_node_nothing(
    ros: None, tmp_path: Path
) -> None:
    """rclpy's own callbacks raise on a negative /clock and on a parameter value of an unknown
    type: the node ended with a traceback and without saving its state (found by a review
    session). The message is lost and counted, the node goes on and saves its state."""
    listener = Listener("odd_msgs")
    reliable = QoSProfile(depth=10, reliability=QoSReliabilityPolicy.RELIABLE)
    clock = listener.node.create_publisher(Clock, "/clock", reliable)
    state = tmp_path / "state.json"
    try:
        with NodeProcess(tmp_path, "odd_msgs", use_sim_time=True, state_file=str(state)) as node:
            node.wait_log("configured")
            listener.wait_for(lambda: clock.get_subscription_count() > 0, 20.0, "/clock")
            negative = "a ROS callback: ValueError('Seconds value must not be negative')"
            deadline = time.monotonic() + 20.0
            while negative not in node.log():  # until the node's side has matched too
                assert node.alive() and time.monotonic() < deadline, node.log()
                clock.publish(Clock(clock=Time(sec=100)))
                clock.publish(Clock(clock=Time(sec=-1)))
                listener.spin(0.2)
            request = SetParameters.Request(
                parameters=[ParameterMsg(name="joint_name", value=ParameterValue(type=10))]
            )
            client = listener.node.create_client(SetParameters, "/odd_msgs/set_parameters")
            assert client.wait_for_service(timeout_sec=10.0)
            time.sleep(1.1)  # the node logs errors at most once a second
            client.call_async(request)  # no answer comes: the service's callback raised
            node.wait_log("a ROS callback: ValueError('10 is not a valid Parameter.Type')")
            assert listener.set_parameter("joint_name", "x") == (
                False,
                "parameter joint_name is applied at configure: deactivate and clean up the "
                "node first",
            )  # the services still answer
            assert listener.lifecycle_state() == "active"
            assert node.alive()
            assert stop_process(node.process) == 0
        assert "the state is saved" in node.log() and state.is_file()
    finally:
        listener.close()


def test_the_log_throttle_holds_each_kind_apart() -> None:
    """One kind logged does not hold back another (the node's errors shared one rclpy
    throttle: an error in the processing hid one in a save for a second)."""
    throttle = LogThrottle(60.0)
    assert throttle.due("processing")
    assert not throttle.due("processing")  # within its period
    assert throttle.due("save")  # another kind: due at once
    assert LogThrottle(0.0).due("save")
