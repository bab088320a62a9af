"""The rosbags type store for ROS 2 Jazzy with the ``prsm_health_msgs`` messages registered.

The ``.msg`` files are read from the installed interface package, found without importing
rclpy: first ``<prefix>/share/prsm_health_msgs/msg`` for every prefix of ``AMENT_PREFIX_PATH``,
then the parents of the installed Python package ``prsm_health_msgs`` (the venv of
``make venv``, a colcon install space, a Debian ROS install all put ``share/`` beside ``lib/``).
The message type names used in bags are constants here.
"""

from __future__ import annotations

import importlib.util
import os
from functools import cache
from pathlib import Path

from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from prsm_health.bags.errors import InterfaceNotFoundError

INTERFACE_PACKAGE = "prsm_health_msgs"

MOTOR_STATE = "prsm_health_msgs/msg/MotorState"
HEALTH_ESTIMATE = "prsm_health_msgs/msg/HealthEstimate"
GROUND_TRUTH = "prsm_health_msgs/msg/GroundTruth"
JOINT_STATE = "sensor_msgs/msg/JointState"
DIAGNOSTIC_ARRAY = "diagnostic_msgs/msg/DiagnosticArray"

#: Our message types, in registration order (a type before the types that use it).
OWN_TYPES = (MOTOR_STATE, HEALTH_ESTIMATE, GROUND_TRUTH)


def _candidates() -> list[Path]:
    """Folders that may hold the installed ``.msg`` files, in search order."""
    tail = Path("share", INTERFACE_PACKAGE, "msg")
    found = [
        Path(prefix) / tail
        for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)
        if prefix
    ]
    try:
        spec = importlib.util.find_spec(INTERFACE_PACKAGE)
    except (ImportError, ValueError):
        spec = None
    if spec is not None:
        origins = [spec.origin] if spec.origin else []
        origins += list(spec.submodule_search_locations or [])
        for origin in origins:  # as installed, and with symlinks resolved (symlink installs)
            for path in dict.fromkeys((Path(origin), Path(origin).resolve())):
                found += [parent / tail for parent in path.parents]
    return found


def find_msg_dir() -> Path:
    """The installed ``share/prsm_health_msgs/msg`` folder with all our ``.msg`` files.

    Raises:
        InterfaceNotFoundError: no candidate folder holds them; the text lists where it looked.
    """
    names = [f"{t.rsplit('/', 1)[1]}.msg" for t in OWN_TYPES]
    candidates = _candidates()
    for folder in candidates:
        if all((folder / name).is_file() for name in names):
            return folder
    looked = ", ".join(str(c) for c in candidates) or "nowhere (no AMENT_PREFIX_PATH, no package)"
    raise InterfaceNotFoundError(
        f"the interface package {INTERFACE_PACKAGE} is not installed (run `make venv`, or source "
        f"a workspace that built it): no {', '.join(names)} in {looked}"
    )


@cache
def typestore() -> Typestore:
    """The Jazzy type store with MotorState, HealthEstimate and GroundTruth registered.

    Built once per process and shared: treat it as read-only (do not register more types in
    it; build your own store with :func:`rosbags.typesys.get_typestore` for that).
    """
    folder = find_msg_dir()
    store = get_typestore(Stores.ROS2_JAZZY)
    for typename in OWN_TYPES:
        text = (folder / f"{typename.rsplit('/', 1)[1]}.msg").read_text(encoding="utf-8")
        store.register(get_types_from_msg(text, typename))
    return store
