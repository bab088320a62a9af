"""Input rows from ROS messages, and the output messages (no DDS needed)."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest
import yaml
from builtin_interfaces.msg import Time
from prsm_health_msgs.msg import MotorState
from prsm_health_msgs.srv import ResetAfterMaintenance
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from prsm_health.outputs import DiagnosticStatusData, Level
from prsm_health.ros.messages import (
    InputSample,
    diagnostic_array,
    health_estimate,
    input_sample,
    stamp_seconds,
    time_msg,
)
from prsm_health.ros.parameters import NODE_NAME


def test_stamps() -> None:
    assert stamp_seconds(Time(sec=12, nanosec=500_000_000)) == 12.5
    assert math.isnan(stamp_seconds(Time(sec=0, nanosec=0xFFFFFFFF)))  # the bags' NaN marker
    assert math.isnan(stamp_seconds(Time(sec=5, nanosec=1_000_000_000)))
    assert time_msg(12.5) == Time(sec=12, nanosec=500_000_000)
    assert time_msg(1.9999999999) == Time(sec=2, nanosec=0)
    assert time_msg(math.nan) == Time() == time_msg(-1.0)


def test_input_sample() -> None:
    header = Header(stamp=Time(sec=4, nanosec=500_000_000))
    msg = JointState(
        header=header,
        name=["wheel", "prsm_motor"],
        position=[0.0, 3.0],
        velocity=[0.0, 150.0],
        effort=[0.0, 1.2],
    )
    assert input_sample(msg, "prsm_motor", None) == InputSample(4.5, 1.2, 150.0, 3.0)
    torque = input_sample(msg, "prsm_motor", 0.6)
    assert torque.current_a == pytest.approx(2.0)
    assert input_sample(msg, "other", None).problem == "joint_missing"
    msg.name = ["prsm_motor", "prsm_motor"]
    assert input_sample(msg, "prsm_motor", None).problem == "joint_repeated"
    msg.name = ["wheel", "prsm_motor"]
    msg.velocity = [0.0]
    assert input_sample(msg, "prsm_motor", None).problem == "joint_incomplete"
    motor = MotorState(header=header, current_a=1.5, speed_rad_s=-20.0, position_rad=7.0)
    assert input_sample(motor, "prsm_motor", 0.6) == InputSample(4.5, 1.5, -20.0, 7.0)


def test_output_messages() -> None:
    fields = {"axial_load_n": 100.0, "jammed_rollers_probability": [0.5, 0.5], "event": 1}
    msg = health_estimate(fields, 7.25, "prsm_motor")
    assert (msg.axial_load_n, msg.event, msg.header.frame_id) == (100.0, 1, "prsm_motor")
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (7, 250_000_000)
    status = DiagnosticStatusData("prsm_health: fatigue", Level.WARN, "m", "left", [("a", "1")])
    array = diagnostic_array([status], 3.0)
    assert array.header.stamp.sec == 3
    assert array.status[0].level == bytes([1])
    assert (array.status[0].name, array.status[0].hardware_id) == ("prsm_health: fatigue", "left")
    assert [(kv.key, kv.value) for kv in array.status[0].values] == [("a", "1")]


def test_the_readme_service_example_is_a_valid_request() -> None:
    """README's `ros2 service call` (no ros2 CLI here, so it cannot run as written): the
    service path is the node's, the type is ours, and the YAML sets every request field with
    values of the right types (the generated constructor and setters, with check_fields,
    refuse anything else)."""
    readme = (Path(__file__).parents[2] / "README.md").read_text()
    found = re.search(r"ros2 service call (\S+) (\S+) \\\n\s*\"(\{.*\})\"", readme)
    assert found, "README: no ros2 service call example"
    path, type_name, values = found.groups()
    assert path == f"/{NODE_NAME}/reset_after_maintenance"
    assert type_name == "prsm_health_msgs/srv/ResetAfterMaintenance"
    fields = yaml.safe_load(values)
    assert set(fields) == set(ResetAfterMaintenance.Request.get_fields_and_field_types())
    request = ResetAfterMaintenance.Request(check_fields=True, **fields)  # Jazzy: opt-in
    assert [getattr(request, name) for name in fields] == list(fields.values())


def test_a_time_past_2038_is_the_latest_a_message_holds() -> None:
    """Pins that a time beyond int32 seconds (a stamp in ns read as s, a clock far ahead)
    becomes the latest ``sec`` a message holds, not an exception that stops the publishing.
    A mutation review found the clamp unguarded."""
    assert time_msg(3e9).sec == 2**31 - 1
    assert time_msg(2.0**31 - 1.0) == Time(sec=2**31 - 1, nanosec=0)
