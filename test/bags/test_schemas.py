"""Schema field lists: the installed definitions, as other writers spell them, and others."""

from __future__ import annotations

from pathlib import Path

import pytest
from mcap.writer import Writer as McapWriter

from prsm_health.bags.codecs import encode_motor_states
from prsm_health.bags.errors import BagError
from prsm_health.bags.reader import read_motor_samples
from prsm_health.bags.schemas import expected_fields, schema_fields
from prsm_health.bags.stamps import seconds_to_stamps
from prsm_health.bags.typestore import MOTOR_STATE, typestore
from test.bags.samples import motor_samples
from test.conftest import REPO

SEPARATOR = "=" * 80


def test_the_msg_file_as_ros2_bag_record_writes_it_has_the_installed_fields() -> None:
    """Comments, a dependency section, a constant, a default value, Header spelt bare."""
    text = (REPO / "msg_defs/prsm_health_msgs/msg/MotorState.msg").read_text()
    assert schema_fields(text) == expected_fields(MOTOR_STATE)
    spelt = (
        "# a comment\nHeader header  # the stamp\nuint8 MODE_A = 1\nfloat64 current_a 0.0\n"
        f"float64 speed_rad_s\nfloat64 position_rad\n{SEPARATOR}\nMSG: std_msgs/Header\n"
        "builtin_interfaces/Time stamp\n"
    )
    assert schema_fields(spelt) == expected_fields(MOTOR_STATE)
    assert expected_fields("std_msgs/msg/Float64") is None  # not decoded here: not checked


def test_a_motor_state_of_another_definition_is_refused_naming_its_fields(tmp_path: Path) -> None:
    """Speed before current under the same name: decoded by the installed layout, current
    and speed swapped, exit 0 and a load RMSE of 24 % (found by a review session)."""
    motor = motor_samples(100, faults=False)
    sec, nanosec = seconds_to_stamps(motor.stamp_s)
    columns = {"sec": sec, "nanosec": nanosec, "current_a": motor.current_a}
    columns |= {"speed_rad_s": motor.speed_rad_s, "position_rad": motor.position_rad}
    payloads = encode_motor_states(columns, frame_id="m")
    definition, _ = typestore().generate_msgdef(MOTOR_STATE, ros_version=2)
    swapped = definition.replace(
        "float64 current_a\nfloat64 speed_rad_s", "float64 speed_rad_s\nfloat64 current_a"
    )
    path = tmp_path / "other.mcap"
    with path.open("wb") as stream:
        writer = McapWriter(stream)
        writer.start(profile="ros2", library="test")
        schema = writer.register_schema(MOTOR_STATE, "ros2msg", swapped.encode())
        channel = writer.register_channel("/motor_state", "cdr", schema)
        for i, payload in enumerate(payloads):
            writer.add_message(channel, 1000 + i, bytes(payload), 1000 + i)
        writer.finish()
    with pytest.raises(
        BagError,
        match=r"topic /motor_state: its schema prsm_health_msgs/msg/MotorState defines "
        r"\[std_msgs/Header header, float64 speed_rad_s, float64 current_a, ",
    ):
        read_motor_samples(path)
