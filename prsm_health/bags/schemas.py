"""The fields a ``ros2msg`` schema defines, to tell a message of the definition this package
reads from another one of the same name.

The replay decodes MotorState, GroundTruth and JointState with its own fixed layouts
(:mod:`prsm_health.bags.codecs`), by the schema's name. A bag whose MotorState schema lists
its fields in another order (or of other types) decoded as the installed one: current and
speed swapped, exit 0, a load RMSE of 24 % (found by a review session). The fields of the
message itself (the text before the first ``====`` line, comments, constants and default
values left out) are compared with the installed definition's.
"""

from __future__ import annotations

from functools import cache

from prsm_health.bags.typestore import GROUND_TRUTH, JOINT_STATE, MOTOR_STATE, typestore

#: The types whose schemas are checked: those decoded with this package's own layouts.
CHECKED_TYPES = (MOTOR_STATE, GROUND_TRUTH, JOINT_STATE)


def schema_fields(definition: str) -> tuple[str, ...]:
    """``"type name"`` of each field of a ros2msg definition's message (not its
    dependencies), types without ``/msg/`` (``std_msgs/msg/Header`` and ``std_msgs/Header``
    alike, and a bare ``Header``), constants and default values left out."""
    fields = []
    for line in definition.splitlines():
        if line.startswith("=="):
            break
        words = line.split("#", 1)[0].replace("=", " = ").split()
        if len(words) < 2 or (len(words) > 2 and words[2] == "="):  # empty, or a constant
            continue
        kind = "std_msgs/Header" if words[0] == "Header" else words[0].replace("/msg/", "/")
        fields.append(f"{kind} {words[1]}")
    return tuple(fields)


@cache
def expected_fields(msgtype: str) -> tuple[str, ...] | None:
    """The fields of the installed definition of ``msgtype``, for the CHECKED_TYPES (None for
    any other type: not checked)."""
    if msgtype not in CHECKED_TYPES:
        return None
    definition, _ = typestore().generate_msgdef(msgtype, ros_version=2)
    return schema_fields(definition)
