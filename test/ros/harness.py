"""Real processes over Fast DDS for the node tests: the node, the player, and a listener.

The node runs in its own process (``python -m prsm_health.ros.node``), the player in another
(``python -m prsm_health play``); both inherit the DDS environment of test/conftest.py
(localhost discovery, UDPv4 built-in transports, this test process's ROS_DOMAIN_ID). The
:class:`Listener` lives in the test process (rclpy is initialised by the ``ros`` fixture) and
records what the node publishes.
Every wait has a deadline; every child is stopped with SIGINT, then SIGKILL.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Callable
from pathlib import Path
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
from prsm_health_msgs.msg import HealthEstimate
from rcl_interfaces.srv import SetParameters
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, QoSReliabilityPolicy

from prsm_health.ros.monitor import diagnostics_record, health_record

STOP_TIMEOUT_S = 15.0
#: After a fresh client finds its service, time for the server to match the client's response
#: reader [s] before the request: rmw_fastrtps drops a response whose reader it has not
#: matched within 100 ms (ros2/rmw_fastrtps#390, #467), and in CI on 2026-11-29 a get_state
#: sent as soon as wait_for_service returned went unanswered for 10 s.
SERVICE_SETTLE_S = 0.5
TRANSITIONS = {
    "configure": Transition.TRANSITION_CONFIGURE,
    "activate": Transition.TRANSITION_ACTIVATE,
    "deactivate": Transition.TRANSITION_DEACTIVATE,
    "cleanup": Transition.TRANSITION_CLEANUP,
    "shutdown": Transition.TRANSITION_UNCONFIGURED_SHUTDOWN,  # from unconfigured
}


def _ros_value(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return repr(value) if isinstance(value, float) else str(value)


def stop_process(process: subprocess.Popen[Any], sig: int = signal.SIGINT) -> int:
    """Signal the process, wait, SIGKILL if it does not end; returns its exit code."""
    if process.poll() is None:
        process.send_signal(sig)
        try:
            process.wait(STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
    return process.returncode


class NodeProcess:
    """prsm_health_node in a child process, its output in ``<tmp>/<name>.log``."""

    def __init__(self, tmp: Path, name: str = "prsm_health", **parameters: object) -> None:
        self.name = name
        self.log_path = tmp / f"{name}-{uuid.uuid4().hex[:6]}.log"
        command = [sys.executable, "-m", "prsm_health.ros.node", "--ros-args"]
        command += ["-r", f"__node:={name}"]
        for key, value in parameters.items():
            command += ["-p", f"{key}:={_ros_value(value)}"]
        with self.log_path.open("wb") as log:
            self.process = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT)

    def __enter__(self) -> NodeProcess:
        return self

    def __exit__(self, *exc: object) -> None:
        stop_process(self.process)

    def log(self) -> str:
        """Everything the node printed so far."""
        return self.log_path.read_text(errors="replace")

    def alive(self) -> bool:
        """The process is still running."""
        return self.process.poll() is None

    def wait_log(self, text: str, timeout_s: float = 20.0) -> None:
        """Wait until ``text`` appears in the log."""
        deadline = time.monotonic() + timeout_s
        while text not in self.log():
            assert self.alive(), f"node ended ({self.process.returncode}):\n{self.log()}"
            assert time.monotonic() < deadline, f"no {text!r} in the log:\n{self.log()}"
            time.sleep(0.05)


def start_player(bag: Path, *args: str) -> subprocess.Popen[str]:
    """``prsm-health play`` of the bag's /motor_state, started in a child process (it waits
    for the node's subscription)."""
    command = [sys.executable, "-m", "prsm_health", "play", str(bag)]
    command += ["--topics", "/motor_state", "--wait-for-subscribers", "20", *args]
    return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def play(bag: Path, *args: str, listener: Listener | None = None, timeout_s: float = 60.0) -> str:
    """``prsm-health play`` in a child process until the end of the bag, the ``listener``
    receiving meanwhile; returns the player's output."""
    player = start_player(bag, *args)
    try:
        if listener is not None:
            listener.wait_for(lambda: player.poll() is not None, timeout_s, "the player")
        out, _ = player.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired as exc:
        raise AssertionError(f"play did not end in {timeout_s} s") from exc
    finally:
        stop_process(player)
    assert player.returncode == 0, out
    return out


class Listener:
    """Records ``/<node>/health`` and ``/diagnostics`` in the test process."""

    def __init__(self, node_name: str = "prsm_health") -> None:
        self.node_name = node_name
        self.node = rclpy.create_node(f"test_listener_{uuid.uuid4().hex[:8]}")
        self.health: list[dict[str, Any]] = []
        self.diagnostics: list[dict[str, Any]] = []
        qos = QoSProfile(depth=1000, reliability=QoSReliabilityPolicy.RELIABLE)
        self._subscriptions = [
            self.node.create_subscription(
                HealthEstimate, f"/{node_name}/health", self._on_health, qos
            ),
            self.node.create_subscription(
                DiagnosticArray, "/diagnostics", self._on_diagnostics, qos
            ),
        ]
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)

    def _on_health(self, msg: Any) -> None:
        self.health.append({**health_record(msg), "received_s": time.monotonic()})

    def _on_diagnostics(self, msg: Any) -> None:
        record = diagnostics_record(msg)
        if record["status"]:
            self.diagnostics.append({**record, "received_s": time.monotonic()})

    def close(self) -> None:
        """Destroy the executor and the node."""
        self.executor.shutdown()
        self.node.destroy_node()

    def spin(self, seconds: float) -> None:
        """Receive for ``seconds``."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.02)

    def wait_for(self, condition: Callable[[], bool], timeout_s: float, what: str) -> None:
        """Receive until ``condition()`` holds; fail naming ``what`` after ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        while not condition():
            assert time.monotonic() < deadline, f"timed out after {timeout_s} s waiting for {what}"
            self.executor.spin_once(timeout_sec=0.02)

    def health_publishers(self) -> set[bytes]:
        """The GIDs of the ``~/health`` publishers the graph knows now (a killed node's stays
        until its lease expires, so a count of matched publishers cannot tell a restart)."""
        topic = f"/{self.node_name}/health"
        return {bytes(info.endpoint_gid) for info in self.node.get_publishers_info_by_topic(topic)}

    def wait_matched(self, timeout_s: float = 20.0) -> None:
        """Receive until both subscriptions are matched with a publisher (what is published
        before that is not delivered: the node's publishers are volatile)."""
        self.wait_for(
            lambda: all(s.get_publisher_count() > 0 for s in self._subscriptions),
            timeout_s,
            "the node's health and diagnostics publishers",
        )

    def statuses_of(self, hardware_id: str) -> list[dict[str, dict[str, Any]]]:
        """The statuses (name -> status) of ``hardware_id`` in each diagnostics message."""
        arrays = [
            {s["name"]: s for s in d["status"] if s["hardware_id"] == hardware_id}
            for d in self.diagnostics
        ]
        return [a for a in arrays if a]

    def statuses(self, hardware_id: str) -> dict[str, dict[str, Any]]:
        """The latest statuses (name -> status) of ``hardware_id`` ({} if none came)."""
        arrays = self.statuses_of(hardware_id)
        return arrays[-1] if arrays else {}

    def call(self, service_type: Any, service: str, request: Any, timeout_s: float = 10.0) -> Any:
        """Call a service of the node under test and return the response."""
        client = self.node.create_client(service_type, f"/{self.node_name}/{service}")
        try:
            assert client.wait_for_service(timeout_sec=timeout_s), f"no service {service}"
            self.spin(SERVICE_SETTLE_S)
            future = client.call_async(request)
            self.executor.spin_until_future_complete(future, timeout_sec=timeout_s)
            assert future.done(), f"no answer from {service}"
            return future.result()
        finally:
            self.node.destroy_client(client)

    def transition(self, name: str) -> bool:
        """Trigger a lifecycle transition of the node; True if it succeeded."""
        request = ChangeState.Request()
        request.transition.id = TRANSITIONS[name]
        return bool(self.call(ChangeState, "change_state", request).success)

    def lifecycle_state(self) -> str:
        """The node's lifecycle state label."""
        return str(self.call(GetState, "get_state", GetState.Request()).current_state.label)

    def set_parameter(self, name: str, value: object) -> tuple[bool, str]:
        """Set one parameter of the node; (successful, reason)."""
        request = SetParameters.Request(
            parameters=[Parameter(name, value=value).to_parameter_msg()]
        )
        result = self.call(SetParameters, "set_parameters", request).results[0]
        return bool(result.successful), str(result.reason)
