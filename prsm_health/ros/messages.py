"""ROS messages in and out: input rows from MotorState / JointState, HealthEstimate and
DiagnosticArray from the plain content of :mod:`prsm_health.outputs`.

Header stamps: ``sec + nanosec / 1e9``. A ``nanosec`` of 1e9 or more is not a time (the bags
of :mod:`prsm_health.bags` use 0xFFFFFFFF as the marker of a non-finite stamp) and becomes
NaN, which the estimator rejects as non-finite, as an offline replay of the same bag does.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from prsm_health_msgs.msg import HealthEstimate, MotorState

from prsm_health.outputs import DiagnosticStatusData

NS_PER_S = 1_000_000_000
#: Why a JointState gives no sample (counted as rejected by the node, by these names).
JOINT_PROBLEMS = ("joint_missing", "joint_incomplete", "joint_repeated")


def stamp_seconds(stamp: Any) -> float:
    """``builtin_interfaces/Time`` -> float seconds (NaN for an invalid ``nanosec``)."""
    if stamp.nanosec >= NS_PER_S:
        return math.nan
    return float(stamp.sec + stamp.nanosec / NS_PER_S)


def time_msg(seconds: float) -> Time:
    """Float seconds -> ``builtin_interfaces/Time`` (0 for a negative or non-finite time: the
    message could carry a negative ``sec``, but rclpy's ``Time.from_msg`` and rclcpp's
    ``Time`` refuse one, and a subscriber would fail on it)."""
    if not math.isfinite(seconds) or seconds < 0.0:
        return Time()
    ns = round(seconds * NS_PER_S)
    return Time(sec=min(ns // NS_PER_S, 2**31 - 1), nanosec=ns % NS_PER_S)


@dataclass(frozen=True)
class InputSample:
    """One motor sample taken from an input message, or why it could not be (``problem``)."""

    stamp_s: float = math.nan
    current_a: float = math.nan
    speed_rad_s: float = math.nan
    position_rad: float = math.nan
    problem: str = ""


def input_sample(msg: Any, joint: str, torque_constant_nm_per_a: float | None) -> InputSample:
    """A ``MotorState``, or the named joint of a ``JointState``, as a motor sample.

    The values are taken as they are (the estimator judges them). For a JointState:
    effort, velocity and position of ``joint``; ``torque_constant_nm_per_a`` None if the
    effort is the current, else k_t (the effort is the motor torque). Problems:
    ``joint_missing`` (no such name), ``joint_incomplete`` (the effort, velocity or position
    array is too short for the joint's index), ``joint_repeated`` (the name appears more than
    once: which entry is the motor cannot be told).
    """
    stamp = stamp_seconds(msg.header.stamp)
    if isinstance(msg, MotorState):
        return InputSample(stamp, msg.current_a, msg.speed_rad_s, msg.position_rad)
    names = list(msg.name)
    occurrences = names.count(joint)
    if occurrences != 1:
        return InputSample(problem=JOINT_PROBLEMS[0] if occurrences == 0 else JOINT_PROBLEMS[2])
    index = names.index(joint)
    arrays = (msg.effort, msg.velocity, msg.position)
    if any(len(values) <= index for values in arrays):
        return InputSample(problem=JOINT_PROBLEMS[1])
    effort = float(msg.effort[index])
    current = effort if torque_constant_nm_per_a is None else effort / torque_constant_nm_per_a
    return InputSample(stamp, current, float(msg.velocity[index]), float(msg.position[index]))


def health_estimate(fields: dict[str, Any], stamp_s: float, frame_id: str) -> Any:
    """A ``HealthEstimate`` from :func:`prsm_health.outputs.health_estimate_fields`."""
    msg = HealthEstimate(**fields)
    msg.header.stamp = time_msg(stamp_s)
    msg.header.frame_id = frame_id
    return msg


def diagnostic_array(statuses: Sequence[DiagnosticStatusData], now_s: float) -> Any:
    """A ``DiagnosticArray`` stamped ``now_s`` (the node's clock)."""
    msg = DiagnosticArray()
    msg.header.stamp = time_msg(now_s)
    msg.status = [
        DiagnosticStatus(
            level=bytes([int(status.level)]),
            name=status.name,
            message=status.message,
            hardware_id=status.hardware_id,
            values=[KeyValue(key=key, value=value) for key, value in status.values],
        )
        for status in statuses
    ]
    return msg
